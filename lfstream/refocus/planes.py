"""Focal planes: the user's alphas or slopes, and per-view synthetic-aperture weights."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from lfstream.errors import LFShapeError, LFValueError
from lfstream.optics import SEED_ALPHAS, slopes_from_alphas


def resolve_slopes(
    alphas: Sequence[float] | None = None,
    slopes: Sequence[float] | None = None,
) -> np.ndarray:
    """Turns the user's alphas or slopes into slopes (float64 ``(K,)``).

    Neither given: the seed's sixteen alphas 0.125 ... 2.0.
    """
    if alphas is not None and slopes is not None:
        raise LFValueError("give alphas or slopes, not both")
    if slopes is not None:
        s = np.asarray(list(slopes), dtype=np.float64).reshape(-1)
        if s.size == 0 or not np.isfinite(s).all():
            raise LFValueError(f"slopes: need at least one finite value, got {list(slopes)!r}")
        return s
    s = slopes_from_alphas(SEED_ALPHAS if alphas is None else alphas)
    if s.size == 0:
        raise LFValueError("alphas: need at least one value")
    return s


def slope_range(lo: float, hi: float, count: int) -> np.ndarray:
    """``count`` evenly spaced slopes from ``lo`` to ``hi`` (a focus range in disparity units)."""
    if count < 1 or not (math.isfinite(lo) and math.isfinite(hi)):
        raise LFValueError(f"slope range needs finite ends and count >= 1, got {lo}, {hi}, {count}")
    return np.linspace(lo, hi, int(count))




def check_slopes(slopes: Sequence[float] | np.ndarray) -> np.ndarray:
    """Slopes as float64 ``(K,)``; at least one, all finite."""
    s = np.asarray(slopes, np.float64).reshape(-1)
    if s.size == 0 or not np.isfinite(s).all():
        raise LFValueError("slopes: need at least one finite value")
    return s


def view_weights(u: int, v: int, weights, present) -> np.ndarray:
    """``(U, V)`` float32 view weights: the given ones (all 1 by default) times the mask of
    present views; checked finite, non-negative and not all zero."""
    w = np.ones((u, v), np.float32) if weights is None else np.asarray(
        weights.cpu() if hasattr(weights, "cpu") else weights, np.float32
    )
    if w.shape != (u, v):
        raise LFShapeError(f"weights: expected shape ({u}, {v}), got {w.shape}")
    if not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
        raise LFValueError("weights: must be finite, non-negative and not all zero")
    if present is not None:
        w = w * np.asarray(present, bool)
        if w.sum() <= 0:
            raise LFValueError("weights: no present view has a non-zero weight")
    return w


__all__ = ["resolve_slopes", "slope_range", "check_slopes", "view_weights"]
