"""Plenoptic-camera optics (seed chapter 2): refocus parameters, SPC <-> camera array,
depth of field, vignetting.

Refocus parameters, all equivalent:

* ``alpha`` (Ng 2005, seed Eq. 2.3): the synthetic film plane at ``F' = alpha * F``. View
  ``(u, v)`` is shifted by ``(1 - 1/alpha) * (u - u0, v - v0)`` pixels before averaging.
  ``alpha = 1`` keeps the captured focus, ``alpha < 1`` focuses farther, ``alpha > 1`` nearer.
* ``slope`` (HCI, plenpy): the shift in pixels per view step, ``slope = 1 - 1/alpha``.
  Refocusing at ``slope = d`` brings points of disparity ``d`` into focus (lfstream's
  disparity convention, :mod:`lfstream.lightfield`). ``alpha = 1 / (1 - slope)``, so slopes
  ``>= 1`` have no positive alpha; lfstream accepts them as slopes.
* Hahne's shift ``a``: the same pixel shift between adjacent views used by the seed's
  Table 2.1 (there called "alpha"); ``a = slope``.
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from lfstream.errors import LFValueError

#: The seed's sixteen refocus parameters, alpha = 0.125, 0.25, ..., 2.0.
SEED_ALPHAS: tuple[float, ...] = tuple(0.125 * k for k in range(1, 17))


def check_alpha(alpha: float) -> float:
    """Returns ``alpha`` as float; rejects non-finite or non-positive values."""
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise LFValueError(f"alpha: expected a number, got {alpha!r}") from None
    if not math.isfinite(a) or a <= 0:
        raise LFValueError(f"alpha: must be finite and > 0 (1 - 1/alpha diverges at 0), got {alpha!r}")
    return a


def slope_from_alpha(alpha: float) -> float:
    """``slope = 1 - 1/alpha`` (pixels of shift per view step)."""
    return 1.0 - 1.0 / check_alpha(alpha)


def alpha_from_slope(slope: float) -> float:
    """``alpha = 1 / (1 - slope)``; raises for slopes ``>= 1`` (no finite positive alpha)."""
    s = float(slope)
    if not math.isfinite(s):
        raise LFValueError(f"slope: must be finite, got {slope!r}")
    if s >= 1.0:
        raise LFValueError(f"slope {s} >= 1 has no finite positive alpha; refocus by slope instead")
    return 1.0 / (1.0 - s)


def slopes_from_alphas(alphas: Iterable[float]) -> np.ndarray:
    """Vectorised :func:`slope_from_alpha`; returns float64 ``(K,)``."""
    return np.array([slope_from_alpha(a) for a in alphas], dtype=np.float64)


def radial_falloff(d, r: float, a: float):
    """Two-parameter radial light falloff ``F(d; r, a) = (1 + (d/r)^2)^(-a)``.

    ``d`` is the distance from the optical axis, ``r`` a length scale and ``a`` the
    exponent; ``a = 2`` with ``r`` the focal distance is the cos^4 law exactly
    (``cos(theta) = (1 + (d/r)^2)^(-1/2)``). Returns values in ``(0, 1]``.
    """
    if not (np.isfinite(r) and r > 0 and np.isfinite(a) and a >= 0):
        raise LFValueError(f"radial_falloff: need r > 0 and a >= 0, got r={r!r}, a={a!r}")
    d = np.asarray(d, dtype=np.float64)
    return (1.0 + (d / r) ** 2) ** (-a)


__all__ = ["radial_falloff", "SEED_ALPHAS", "check_alpha", "slope_from_alpha", "alpha_from_slope", "slopes_from_alphas"]
