"""What the hint's estimation works on: the views it sweeps (:func:`sweep_views`), their luma
block means (:func:`_grids`), high-passed and coarsened, the per-thread arrays kept from
frame to frame, and the maps' up-sampling (:func:`_upsample`)."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import cv2
import numpy as np


@dataclass(frozen=True)
class HintMap:
    """A low-resolution centre-view disparity and the search range it came from.

    Attributes:
        disparity: ``(hs, ws)`` float32, pixels (of the full view) per view step.
        scale: full resolution / map resolution.
        search: ``(lo, hi)`` the sweep covered.
        axes: ``(2, 2)`` float32 view axes the disparity is measured along
            (:func:`lfstream.lightfield.view_offsets`); the identity for the convention.
        reach: the largest displacement of any view per unit disparity (3 for 7 x 7 views
            on the convention's axes): what a disparity error costs at the outermost view.
        ring_luma: ``(1 + J, hs, ws)`` float32 luma in [0, 1] of the centre view and the J
            outer-ring views (:func:`_ring_views`) as means of ``scale x scale`` blocks: what
            the sweep read, kept for the encoder's check of its own prediction
            (:func:`lfstream.codec.rate.prediction_psnr`), which then reads no view again;
            ``None`` unless asked for (``keep_ring_luma``) or where the map was not swept.
        coarse: ``(H // 2s, W // 2s)`` float32, the same sweep's map at twice the scale
            ``s``: exactly what a sweep with ``hint_scale = 2s`` sends where the view has
            ``2s`` pixels a side (the encoder's default may choose it,
            :func:`lfstream.codec.rate.choose_default`); ``None`` unless asked for
            (``keep_coarse``).
    """

    disparity: np.ndarray
    scale: int
    search: tuple[float, float]
    axes: np.ndarray = field(default_factory=lambda: np.eye(2, dtype=np.float32))
    reach: float = 1.0
    ring_luma: np.ndarray | None = None
    coarse: np.ndarray | None = None


def _ring_views(u: int, v: int, present: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Corners and edge mid-points (the largest baselines); where those are missing, the
    farthest present views."""
    u0, v0 = u // 2, v // 2
    ring = {(a, b) for a in (0, u0, u - 1) for b in (0, v0, v - 1)} - {(u0, v0)}
    ok = [k for k in sorted(ring) if present is None or present[k]]
    if len(ok) >= 2:
        return ok
    others = [(a, b) for a in range(u) for b in range(v) if (a, b) != (u0, v0) and (present is None or present[a, b])]
    others.sort(key=lambda k: -(abs(k[0] - u0) + abs(k[1] - v0)))
    return others[:8]


def sweep_views(u: int, v: int, present: np.ndarray | None = None) -> list[tuple[int, int]]:
    """The views the sweep compares with the centre: the outer ring (:func:`_ring_views`,
    first) for precision, then the four views next to the centre.

    The short baselines resolve periodic texture (multi-baseline stereo): a stripe or checker
    of period ``p`` matches every outer view (all ``k`` steps from the centre) at a false
    disparity ``p / k`` as well as it does at the true one, but not the views one step away.
    Measured on 12 synthetic scenes (7x7x375x540, seeds 0-11, noise and vignetting): the
    ring alone put the coarse pass on such false matches on half of them (hint error
    MSE x 100 441 on average, 377 median, against the ground truth); with the inner four,
    21 (7.7 median), MPSNR of the default decode +2.9 dB on average.
    """
    keys = _ring_views(u, v, present)
    u0, v0 = u // 2, v // 2
    for k in ((u0 - 1, v0), (u0, v0 - 1), (u0, v0 + 1), (u0 + 1, v0)):
        if 0 <= k[0] < u and 0 <= k[1] < v and k not in keys and (present is None or present[k]):
            keys.append(k)
    return keys


def _grids(lf: np.ndarray, keys: list[tuple[int, int]], scale: int, kept: bool = False) -> np.ndarray:
    """Luma of the views ``keys`` as means of ``scale x scale`` blocks, in [0, 1]: OpenCV's
    8-bit grey conversion, then block means (:func:`lfstream.codec.hint.kernels.block_means`;
    float, not uint8: block means keep the sub-level precision the sub-pixel fit needs).
    OpenCV converts with SIMD on its threads: the 13 views a 7x7 frame sweeps in 1.9 ms
    (lytro_bikes; translucent 2.4) against 2.2 (3.2) for a numba kernel that converted and
    averaged in one pass, the same values to the bit (minimum of 40 interleaved calls).

    Args:
        kept: into the calling thread's kept buffer (:func:`_kept_array`), for a caller done
            with them before its next call; else a new array.

    Shape:
        - lf: ``(U, V, H, W, 3)`` uint8, C-contiguous
        - output: ``(len(keys), max(1, H // scale), max(1, W // scale))`` float32
    """
    from lfstream.codec.hint.kernels import block_means

    h, w = lf.shape[2:4]
    grey = np.empty((len(keys), h, w), np.uint8)
    for n, (a, b) in enumerate(keys):
        cv2.cvtColor(lf[a, b], cv2.COLOR_RGB2GRAY, dst=grey[n])
    shape = (len(keys), max(1, h // scale), max(1, w // scale))
    out = _kept_array("grids", shape) if kept else np.empty(shape, np.float32)
    block_means(grey, scale, out)
    return out


def _high_pass(images: np.ndarray) -> np.ndarray:
    """Each image minus its local mean (7 x 7 box): vignetting and colour shading, which
    differ between views but vary slowly, then do not bias the matching cost."""
    for img in images:
        img -= cv2.blur(img, (7, 7), borderType=cv2.BORDER_REFLECT)
    return images


def _coarser(images: np.ndarray, factor: int) -> np.ndarray:
    """Block means of ``factor x factor`` of every image (the coarse pass's input)."""
    _, h, w = images.shape
    hs, ws = max(1, h // factor), max(1, w // factor)
    return np.stack([cv2.resize(img[: hs * factor, : ws * factor], (ws, hs), interpolation=cv2.INTER_AREA)
                     for img in images])


#: The hint's per-frame working arrays (the views' luma, its high-pass, a sweep's cost volume)
#: are kept by the thread that makes them for its next frame, each up to this size: glibc's
#: largest dynamic mmap threshold, above which it maps every chunk afresh anyway (larger ones
#: are made anew, so the memory held for good stays bounded: 11 MB for a 7x7x375x540 frame).
KEPT_ARRAY_MAX_BYTES = 32 << 20


_kept = threading.local()


def _kept_array(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """An uninitialised float32 array of ``shape`` that must not outlive the call making it:
    the calling thread's kept buffer ``name`` where it is at most
    :data:`KEPT_ARRAY_MAX_BYTES`. Made afresh each frame, these were the encode's largest
    temporaries (lytro_bikes: a 5.7 MB cost volume, 2.6 MB of luma twice), and glibc, whose
    trim threshold is twice the largest chunk a process has freed, returned them to the
    kernel after each frame in a process that had freed nothing larger: thousands of page
    faults an encode, none kept. Library code does not set the process's allocator; it keeps its own buffers."""
    size = int(np.prod(shape))
    if size * 4 > KEPT_ARRAY_MAX_BYTES:
        return np.empty(shape, np.float32)
    buf = getattr(_kept, name, None)
    if buf is None or buf.size < size:
        buf = np.empty(size, np.float32)
        setattr(_kept, name, buf)
    return buf[:size].reshape(shape)


def _upsample(small: np.ndarray, scale: int, size: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling that maps map pixel k to the centre of its ``scale`` block."""
    h, w = size
    hs, ws = small.shape
    ys = np.clip((np.arange(h, dtype=np.float32) + 0.5) / scale - 0.5, 0, hs - 1)
    xs = np.clip((np.arange(w, dtype=np.float32) + 0.5) / scale - 0.5, 0, ws - 1)
    mx, my = np.meshgrid(xs, ys)
    return cv2.remap(np.ascontiguousarray(small, np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
