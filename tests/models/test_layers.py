"""Shared network layers (lfstream.models.layers)."""

import torch
from torch import nn

from lfstream.models.layers import ELU


def test_the_elu_overwrites_its_input_only_where_no_gradient_is_recorded():
    """lfstream's ELU gives nn.ELU's values; in inference it works in place (the input is the
    output), while recording gradients it leaves the input alone and its gradient is nn.ELU's."""
    x = torch.randn(2, 3, 5, 7)
    want = nn.ELU()(x)
    with torch.no_grad():
        y = x.clone()
        out = ELU()(y)
        assert torch.equal(out, want) and out.data_ptr() == y.data_ptr()
    a = x.clone().requires_grad_(True)
    b = x.clone().requires_grad_(True)
    ELU()(a).square().sum().backward()
    nn.ELU()(b).square().sum().backward()
    assert torch.equal(a.grad, b.grad) and torch.equal(a.detach(), x)
