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
        return check_slopes(s)
    s = slopes_from_alphas(SEED_ALPHAS if alphas is None else alphas)
    if s.size == 0:
        raise LFValueError("alphas: need at least one value")
    return check_slopes(s)


#: The most focal planes one stack may have (each is a full view in memory and a file).
MAX_PLANES = 256


def slope_range(lo: float, hi: float, count: int) -> np.ndarray:
    """``count`` evenly spaced slopes from ``lo`` to ``hi`` (a focus range in disparity units),
    at most :data:`MAX_PLANES`."""
    if count < 1 or not (math.isfinite(lo) and math.isfinite(hi)):
        raise LFValueError(f"slope range needs finite ends and count >= 1, got {lo}, {hi}, {count}")
    if count > MAX_PLANES:
        raise LFValueError(f"slope range: {count:g} planes; at most {MAX_PLANES}")
    return np.linspace(lo, hi, int(count))




def check_slopes(slopes: Sequence[float] | np.ndarray) -> np.ndarray:
    """Slopes as float64 ``(K,)``; at least one, all finite."""
    s = np.asarray(slopes, np.float64).reshape(-1)
    if s.size == 0 or not np.isfinite(s).all():
        raise LFValueError("slopes: need at least one finite value")
    if s.size > MAX_PLANES:
        raise LFValueError(f"slopes: {s.size} planes; at most {MAX_PLANES}")
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


def plane_spacing(views: tuple[int, int]) -> float:
    """The slope step at which neighbouring planes' depths of field touch: a point is sharp
    (blur under one pixel) while ``|d - slope| * (N - 1) <= 1``, ``N`` the views across the
    wider axis of the aperture, so planes ``1 / (N - 1)`` apart leave no depth unfocused."""
    n = max(int(views[0]), int(views[1]), 2)
    return 1.0 / (n - 1)


def scene_slopes(disparity: np.ndarray, views: tuple[int, int], max_planes: int = 16, min_planes: int = 4,
                 percentiles: tuple[float, float] = (2.0, 98.0)) -> np.ndarray:
    """Focal planes that fit the scene: from the near to the far end of its disparity
    (robust percentiles of the centre view's map), :func:`plane_spacing` apart, between
    ``min_planes`` and ``max_planes`` of them (a deep scene gets wider spacing, a shallow
    one is centred on its depth).

    Shape:
        - disparity: ``(H, W)`` px per view step
        - output: ``(K,)`` float64 slopes, far (smallest) to near
    """
    d = np.asarray(disparity, np.float64)
    finite = d[np.isfinite(d)]
    lo, hi = np.percentile(finite, percentiles) if finite.size else (0.0, 0.0)
    step = plane_spacing(views)
    k = int(np.clip(np.ceil((hi - lo) / step) + 1, min_planes, max_planes))
    centre, span = 0.5 * (lo + hi), max(hi - lo, step * (k - 1))
    return np.linspace(centre - span / 2, centre + span / 2, k)


def plane_records(slopes, camera=None) -> list[dict]:
    """``[{"index", "slope", "alpha"}]`` of focal planes, as reports record them (alpha
    ``None`` for slopes >= 1, which no positive alpha reaches); with a
    :class:`~lfstream.optics.PlenopticCamera` also ``distance_m``, ``dof_near_m`` and
    ``dof_far_m`` (metres from the microlens array; ``None`` at or beyond infinity)."""
    from lfstream.optics import alpha_from_slope, refocus_plane

    def metres(x: float) -> float | None:
        return round(float(x), 6) if np.isfinite(x) else None

    records = []
    for k, s in enumerate(np.asarray(slopes, np.float64)):
        rec = {"index": k, "slope": round(float(s), 6), "alpha": round(alpha_from_slope(float(s)), 6) if s < 1 else None}
        if camera is not None:
            p = refocus_plane(camera, float(s))
            rec.update(distance_m=metres(p.focus_m), dof_near_m=metres(p.dof_near_m), dof_far_m=metres(p.dof_far_m))
        records.append(rec)
    return records


__all__ = ["resolve_slopes", "slope_range", "check_slopes", "view_weights", "plane_spacing", "scene_slopes",
           "plane_records"]
