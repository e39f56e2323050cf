"""Disparity estimation for the encoder's depth hint, its compact coding, and accuracy metrics.

The encoder has every view, so it can afford a plane sweep: for each candidate disparity
the views of the centre row and column (and both diagonals, when the grid has them) are
shifted onto the centre view, their absolute differences are summed into a cost slice,
each slice is smoothed by a guided filter with the centre view as guide (edge-aware cost
aggregation), and each pixel takes the cheapest disparity with a parabolic sub-step.

The hint payload is self-contained: a small header (format version, disparity range,
size of the quantised map) and the zstd-compressed 8-bit map at a reduced resolution.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import cv2
import numpy as np
import zstandard

from lfstream.errors import BitstreamError, LFShapeError, LFValueError
from lfstream.lightfield import as_float, check_lf

_HINT_HEADER = struct.Struct("<BffHH")
HINT_VERSION = 1


@dataclass(frozen=True)
class HintOptions:
    """Plane-sweep and coding parameters of the depth hint.

    Attributes:
        max_disparity: the sweep covers ``[-max_disparity, max_disparity]`` px per view step.
        steps: number of candidate disparities.
        work_scale: the sweep runs on views downscaled by this factor (speed).
        hint_scale: the sent map is the full-resolution map downscaled by this factor.
        guide_radius: guided-filter radius at the working resolution.
    """

    max_disparity: float = 2.5
    steps: int = 41
    work_scale: int = 2
    hint_scale: int = 4
    guide_radius: int = 5

    def validate(self) -> None:
        if not (np.isfinite(self.max_disparity) and 0 < self.max_disparity <= 64):
            raise LFValueError(f"max_disparity: in (0, 64], got {self.max_disparity}")
        if not 3 <= self.steps <= 1024 or self.work_scale < 1 or self.hint_scale < 1 or self.guide_radius < 1:
            raise LFValueError("hint options: steps >= 3 and scales / radius >= 1")


def _sweep_views(u: int, v: int) -> list[tuple[int, int]]:
    u0, v0 = u // 2, v // 2
    views = {(u0, k) for k in range(v)} | {(k, v0) for k in range(u)}
    if u == v:
        views |= {(k, k) for k in range(u)} | {(k, u - 1 - k) for k in range(u)}
    views.discard((u0, v0))
    return sorted(views)


def estimate_disparity(lf: np.ndarray, options: HintOptions = HintOptions(),
                       present: np.ndarray | None = None) -> np.ndarray:
    """Centre-view disparity of one LF frame by plane sweep with edge-aware aggregation.

    Args:
        lf: the frame.
        options: sweep parameters.
        present: ``(U, V)`` mask of views that exist (e.g. an HCI "star"); others are ignored.

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output: ``(H, W)`` float32, pixels per view step
    """
    options.validate()
    u, v, h, w, _ = check_lf(lf, allow_video=False)
    views = [k for k in _sweep_views(u, v) if present is None or present[k]]
    if not views:
        return np.zeros((h, w), np.float32)
    s = options.work_scale
    hs, ws = max(1, h // s), max(1, w // s)
    gray = as_float(np.asarray(lf)).mean(-1)
    small = {key: cv2.resize(gray[key], (ws, hs), interpolation=cv2.INTER_AREA) for key in
             views + [(u // 2, v // 2)]}
    centre = small[(u // 2, v // 2)]
    cands = np.linspace(-options.max_disparity, options.max_disparity, options.steps).astype(np.float32)
    cost = np.empty((len(cands), hs, ws), np.float32)
    guide = centre.astype(np.float32)
    eps = 1e-3
    use_ximgproc = hasattr(cv2, "ximgproc")
    for k, d in enumerate(cands):
        acc = np.zeros((hs, ws), np.float32)
        ds = d / s  # disparity at the working resolution
        for uu, vv in views:
            # view(p) = centre(p + d*delta): sample the view at p - d*delta to align it
            m = np.float32([[1, 0, -ds * (vv - v // 2)], [0, 1, -ds * (uu - u // 2)]])
            shifted = cv2.warpAffine(small[(uu, vv)], m, (ws, hs), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_REPLICATE)
            acc += np.abs(shifted - centre)
        acc /= len(views)
        if use_ximgproc:
            cost[k] = cv2.ximgproc.guidedFilter(guide, acc, options.guide_radius, eps)
        else:  # pragma: no cover - opencv-contrib is a dependency; plain box filter otherwise
            cost[k] = cv2.blur(acc, (2 * options.guide_radius + 1,) * 2)
    best = np.argmin(cost, axis=0)
    # parabolic refinement between neighbouring candidates
    k0 = np.clip(best, 1, len(cands) - 2)
    yy, xx = np.indices(best.shape)
    c_m, c_0, c_p = cost[k0 - 1, yy, xx], cost[k0, yy, xx], cost[k0 + 1, yy, xx]
    denom = c_m - 2 * c_0 + c_p
    offset = np.where(denom > 1e-9, 0.5 * (c_m - c_p) / np.maximum(denom, 1e-9), 0.0)
    offset = np.where((best == k0), np.clip(offset, -0.5, 0.5), 0.0)
    step = float(cands[1] - cands[0])
    disp = cands[best] + offset * step
    full = cv2.resize(disp.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
    return full.astype(np.float32)


def encode_hint(disparity: np.ndarray, options: HintOptions = HintOptions()) -> bytes:
    """Downscales, quantises to 8 bits over the map's range and zstd-compresses a disparity map."""
    d = np.asarray(disparity, np.float32)
    if d.ndim != 2:
        raise LFShapeError(f"disparity: expected (H, W), got {d.shape}")
    h, w = d.shape
    hs, ws = max(1, h // options.hint_scale), max(1, w // options.hint_scale)
    small = cv2.resize(d, (ws, hs), interpolation=cv2.INTER_AREA)
    lo, hi = float(small.min()), float(small.max())
    span = hi - lo if hi > lo else 1.0
    q = np.clip(np.round((small - lo) / span * 255.0), 0, 255).astype(np.uint8)
    body = zstandard.ZstdCompressor(level=19).compress(q.tobytes())
    return _HINT_HEADER.pack(HINT_VERSION, lo, hi, hs, ws) + body


def decode_hint(data: bytes, size: tuple[int, int], guide: np.ndarray | None = None, frame: int | None = None) -> np.ndarray:
    """Inverse of :func:`encode_hint`: the ``(H, W)`` float32 map, upsampled (edge-aware with
    a joint bilateral filter when the decoded centre view is given as ``guide``)."""
    if len(data) < _HINT_HEADER.size:
        raise BitstreamError("depth hint: truncated", frame)
    version, lo, hi, hs, ws = _HINT_HEADER.unpack_from(data)
    h, w = size
    if version != HINT_VERSION:
        raise BitstreamError(f"depth hint: unknown version {version}", frame)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi and abs(lo) < 1e4 and abs(hi) < 1e4):
        raise BitstreamError(f"depth hint: bad range {lo}..{hi}", frame)
    if not (1 <= hs <= h and 1 <= ws <= w):
        raise BitstreamError(f"depth hint: map size {hs}x{ws} does not fit the view size {h}x{w}", frame)
    try:
        raw = zstandard.ZstdDecompressor().decompress(data[_HINT_HEADER.size :], max_output_size=hs * ws)
    except zstandard.ZstdError as exc:
        raise BitstreamError(f"depth hint: corrupt ({exc})", frame) from exc
    if len(raw) != hs * ws:
        raise BitstreamError(f"depth hint: {len(raw)} values where {hs * ws} were expected", frame)
    q = np.frombuffer(raw, np.uint8).reshape(hs, ws).astype(np.float32)
    span = hi - lo if hi > lo else 1.0
    small = lo + q / 255.0 * span
    full = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    if guide is not None and hasattr(cv2, "ximgproc"):
        g = as_float(np.asarray(guide))
        full = cv2.ximgproc.jointBilateralFilter(g, full, d=-1, sigmaColor=0.1, sigmaSpace=3.0)
    return np.clip(full, lo, hi).astype(np.float32)


def disparity_errors(estimate: np.ndarray, truth: np.ndarray, border: int = 15) -> dict:
    """The HCI benchmark's metrics: ``mse_x100`` (MSE times 100) and ``badpix_007`` (share of
    pixels off by more than 0.07), excluding a border as the benchmark does."""
    e = np.asarray(estimate, np.float64)
    t = np.asarray(truth, np.float64)
    if e.shape != t.shape:
        raise LFShapeError(f"disparity shapes differ: {e.shape} vs {t.shape}")
    if border and min(e.shape) > 2 * border:
        e, t = e[border:-border, border:-border], t[border:-border, border:-border]
    diff = e - t
    return {"mse_x100": float(100 * np.mean(diff**2)), "badpix_007": float(np.mean(np.abs(diff) > 0.07))}


__all__ = ["HintOptions", "estimate_disparity", "encode_hint", "decode_hint", "disparity_errors"]
