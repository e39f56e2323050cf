"""Focal stacks: shift-and-sum (SaS), Fourier slice (FLR) and RefNet.

The definition of a focal plane (the seed's Eq. 2.3 without magnification), the border
rule and the relation between SaS and FLR are stated in :mod:`~lfstream.refocus.shift_sum`
and :mod:`~lfstream.refocus.fourier`. Modules: :mod:`~lfstream.refocus.planes` (alphas,
slopes, aperture weights), :mod:`~lfstream.refocus.shift_sum` (fused numba kernel on CPU,
separable torch on GPU), :mod:`~lfstream.refocus.fourier`, :mod:`~lfstream.refocus.stack`
(:func:`focal_stack`, :func:`all_in_focus`) and :mod:`~lfstream.refocus.module` (the
:class:`FocalStack` module). Importing the package does not import torch: numpy light fields
refocus by shift-and-sum without it; ``fourier_slice`` and ``FocalStack`` load on first use.
"""

from lfstream.optics import alpha_from_slope
from lfstream.refocus.planes import plane_records, plane_spacing, resolve_slopes, scene_slopes, slope_range
from lfstream.refocus.shift_sum import shift_and_sum
from lfstream.refocus.stack import METHODS, all_in_focus, focal_stack, refnet_stack


def __getattr__(name: str):
    # torch-based names load their modules (and torch) on first use
    if name == "fourier_slice":
        from lfstream.refocus.fourier import fourier_slice

        return fourier_slice
    if name == "FocalStack":
        from lfstream.refocus.module import FocalStack

        return FocalStack
    raise AttributeError(f"module 'lfstream.refocus' has no attribute {name!r}")


__all__ = [
    "METHODS",
    "resolve_slopes",
    "slope_range",
    "plane_spacing",
    "plane_records",
    "scene_slopes",
    "shift_and_sum",
    "fourier_slice",
    "focal_stack",
    "refnet_stack",
    "all_in_focus",
    "FocalStack",
    "alpha_from_slope",
]
