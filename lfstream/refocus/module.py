"""The ``nn.Module`` wrapper of :func:`~lfstream.refocus.focal_stack` (imports torch)."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from lfstream.refocus.planes import resolve_slopes
from lfstream.refocus.stack import focal_stack


class FocalStack(torch.nn.Module):
    """``nn.Module`` wrapper of :func:`focal_stack` with fixed planes and method.

    Shape:
        - input: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)`` tensor
        - output: ``(K, H, W, 3)`` or ``(T, K, H, W, 3)``
    """

    def __init__(self, alphas: Sequence[float] | None = None, method: str = "sas", slopes=None, **options):
        super().__init__()
        self.slopes = resolve_slopes(alphas, slopes)
        self.method = method
        self.options = options

    def forward(self, lf: torch.Tensor) -> torch.Tensor:
        return focal_stack(lf, method=self.method, slopes=self.slopes, **self.options)


__all__ = ["FocalStack"]
