"""Shared network layers (lfstream.models.layers)."""

import pytest
import torch
from torch import nn

from lfstream.models.layers import ELU, Bottleneck, add_, elu_

# lfstream's float32 ELU kernel against the true value: within 4e-7 relative (PyTorch's
# own within about 1e-7), so 6e-7 against PyTorch's; bfloat16 rounds from it as PyTorch does
ELU_RTOL = {torch.float32: 6e-7, torch.bfloat16: 0.0, torch.float64: 0.0}


def _samples(dtype: torch.dtype) -> torch.Tensor:
    """Normal samples and the edges: zeros, tiny and huge negatives, the clamp at -20."""
    g = torch.Generator().manual_seed(0)
    x = torch.randn(3, 24, 37, 41, generator=g) * 3
    edges = torch.tensor([0.0, -0.0, 1e-30, -1e-30, -1e-8, -0.3125, -0.625, -1.0, -19.99, -20.0, -20.5, -88.0,
                          -1e30, 1e30, 7.5, -7.5], dtype=torch.float32)
    x.view(-1)[: edges.numel()] = edges
    return x.to(dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16, torch.float64])
def test_elu_kernel_agrees_with_pytorch_in_place(dtype):
    """elu_ gives nn.ELU's values (per-dtype tolerance above), in place, finite, on the
    kernels' dtypes and through PyTorch on the others."""
    x = _samples(dtype)
    want = nn.functional.elu(x.double()).to(dtype)
    y = x.clone()
    out = elu_(y)
    assert out.data_ptr() == y.data_ptr() and out.dtype == dtype
    assert torch.isfinite(out).all()
    torch.testing.assert_close(out.double(), want.double(), rtol=ELU_RTOL[dtype], atol=1e-38)
    # the positive side and zero pass through unchanged
    assert torch.equal(out[x >= 0], x[x >= 0])


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_elu_kernel_takes_channels_last_and_leaves_views_to_pytorch(dtype):
    """A channels-last tensor goes through the kernel over its storage (the same values as
    the contiguous one); a strided view, which the kernel cannot walk, through PyTorch."""
    x = _samples(dtype)
    want = elu_(x.clone())
    last = x.clone().contiguous(memory_format=torch.channels_last)
    assert torch.equal(elu_(last), want)
    base = x.clone()
    view = base[:, ::2]  # not contiguous in any layout
    elu_(view)
    torch.testing.assert_close(view.double(), nn.functional.elu(x[:, ::2].double()).to(dtype).double(),
                               rtol=ELU_RTOL[dtype] or 1e-2, atol=0)
    assert torch.equal(base[:, 1::2], x[:, 1::2])  # the rest of the storage untouched


def test_the_elu_overwrites_its_input_only_where_no_gradient_is_recorded():
    """lfstream's ELU gives nn.ELU's values (within the kernel's tolerance); in inference it
    works in place (the input is the output), while recording gradients it leaves the input
    alone and its values and gradient are nn.ELU's exactly."""
    x = torch.randn(2, 3, 5, 7)
    want = nn.ELU()(x)
    with torch.no_grad():
        y = x.clone()
        out = ELU()(y)
        torch.testing.assert_close(out, want, rtol=ELU_RTOL[torch.float32], atol=1e-38)
        assert out.data_ptr() == y.data_ptr()
    a = x.clone().requires_grad_(True)
    b = x.clone().requires_grad_(True)
    out_a, out_b = ELU()(a), nn.ELU()(b)
    assert torch.equal(out_a, out_b)
    out_a.square().sum().backward()
    out_b.square().sum().backward()
    assert torch.equal(a.grad, b.grad) and torch.equal(a.detach(), x)


def test_add_sums_in_place_only_where_it_can():
    """add_ writes into its first argument where the sum fits it and no gradient is recorded,
    else returns a new tensor; the values are those of ``+`` either way."""
    y, other = torch.randn(2, 4, 3, 3), torch.randn(2, 4, 3, 3)
    want = y + other
    out = add_(y, other)
    assert out.data_ptr() == y.data_ptr() and torch.equal(out, want)
    small = torch.randn(4, 1, 1)  # broadcast into y: in place
    want = y + small
    assert torch.equal(add_(y, small), want)
    y2 = torch.randn(4, 1, 1)  # the sum is larger than y: a new tensor
    big = torch.randn(2, 4, 3, 3)
    want = y2 + big
    out = add_(y2, big)
    assert out.shape == big.shape and torch.equal(out, want) and out.data_ptr() != y2.data_ptr()
    z = torch.randn(3, 3)  # the same storage: not overwritten under itself
    want = z + z
    out = add_(z, z)
    assert torch.equal(out, want)
    leaf = torch.randn(2, 4, 3, 3, requires_grad=True)  # while autograd records: never in place
    fresh = leaf * 2
    out = add_(fresh, other)
    assert out.data_ptr() != fresh.data_ptr() and torch.equal(out, fresh + other)
    out.sum().backward()
    assert torch.equal(leaf.grad, torch.full_like(leaf, 2.0))


def test_bottleneck_inference_matches_training_forward():
    """The bottleneck's in-place sum at inference gives the recorded forward's values."""
    torch.manual_seed(0)
    block = Bottleneck(8, 4, 8, "none", "elu").eval()
    x = torch.randn(1, 8, 16, 16)
    with torch.no_grad():
        fast = block(x.clone())
    recorded = block(x.clone().requires_grad_(True))
    torch.testing.assert_close(fast, recorded.detach(), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_elu_kernel_value_does_not_depend_on_its_position(dtype):
    """The same value gives the same bits wherever it sits in the tensor (the kernels'
    vectorised body and scalar tail agree), so a row strip of a network computes what the
    whole image does there."""
    x = _samples(dtype).reshape(-1)[:10_007]
    whole = elu_(x.clone())
    for shift in (1, 3, 7, 4095, 4097):
        shifted = torch.cat([torch.zeros(shift, dtype=dtype), x])
        assert torch.equal(elu_(shifted)[shift:], whole)
