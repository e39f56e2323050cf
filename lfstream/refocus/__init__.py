"""Focal stacks: shift-and-sum (SaS), Fourier slice (FLR) and RefNet.

The definition of a focal plane (the seed's Eq. 2.3 without magnification), the border
rule and the relation between SaS and FLR are stated in :mod:`~lfstream.refocus.shift_sum`
and :mod:`~lfstream.refocus.fourier`. Modules: :mod:`~lfstream.refocus.planes` (alphas,
slopes, aperture weights), :mod:`~lfstream.refocus.shift_sum` (fused numba kernel on CPU,
separable torch on GPU), :mod:`~lfstream.refocus.fourier`, :mod:`~lfstream.refocus.stack`
(:func:`focal_stack`, :func:`all_in_focus`, the :class:`FocalStack` module).
"""

from lfstream.optics import alpha_from_slope
from lfstream.refocus.fourier import fourier_slice
from lfstream.refocus.planes import plane_records, plane_spacing, resolve_slopes, scene_slopes, slope_range
from lfstream.refocus.shift_sum import shift_and_sum
from lfstream.refocus.stack import METHODS, FocalStack, all_in_focus, focal_stack, refnet_stack

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
