"""Classical refocusing: shift-and-sum (SaS) and Fourier slice (FLR) focal stacks.

Definition (seed Eq. 2.3 without the 1/alpha magnification, so every plane keeps the
centre view's framing): the plane at ``slope = 1 - 1/alpha`` is

    E(y, x) = sum_uv w_uv * L_uv(y - slope*(u - u0), x - slope*(v - v0)) / coverage(y, x)

with bilinear interpolation. Points of disparity ``d = slope`` (lfstream's HCI sign) are in
focus. Border handling: a view contributes only where its shifted image exists (no
padding); ``coverage`` is the sum of the weights that do contribute, as in Dansereau's
LFFiltShiftSum. The centre view never moves, so with a non-zero centre weight every pixel
is covered; shifts larger than the image (tiny or huge alpha) leave only views that still
overlap, and the plane tends to the centre view. A pixel no view covers is 0.

Fourier slice refocusing (Ng 2005) takes one 4-D FFT per light field and then, per plane,
a 2-D slice of the spectrum interpolated in the angular frequencies and one inverse 2-D
FFT. It shifts with sinc rather than bilinear interpolation and wraps around (mitigated
by reflect padding), so it approximates SaS; its brightness matches SaS exactly (the DC
term is the weighted mean).

Modules: :mod:`~lfstream.refocus.planes` (alphas, slopes, aperture weights),
:mod:`~lfstream.refocus.shift_sum` (fused numba kernel on CPU, separable torch on GPU),
:mod:`~lfstream.refocus.fourier`, :mod:`~lfstream.refocus.stack` (:func:`focal_stack`,
:func:`all_in_focus`, the :class:`FocalStack` module).
"""

from lfstream.optics import alpha_from_slope
from lfstream.refocus.fourier import fourier_slice
from lfstream.refocus.planes import resolve_slopes, slope_range
from lfstream.refocus.shift_sum import shift_and_sum
from lfstream.refocus.stack import METHODS, FocalStack, all_in_focus, focal_stack, refnet_stack

__all__ = [
    "METHODS",
    "resolve_slopes",
    "slope_range",
    "shift_and_sum",
    "fourier_slice",
    "focal_stack",
    "refnet_stack",
    "all_in_focus",
    "FocalStack",
    "alpha_from_slope",
]
