"""The encoder's depth hint: estimation, compact coding, decoding, and accuracy metrics.

Estimation (the encoder has every view, at encode time): a plane sweep at half resolution
(``1 / work_scale``), averaged down to the grid the hint is sent on (``1 / hint_scale``),
over a sparse set of views — the corners and
edge mid-points of the grid, the largest baselines — fused into one parallel numba kernel
(:func:`lfstream.codec.hint_kernels.sweep_cost`) on high-passed luma (vignetting and colour
shading differ between views and would bias the cost); cost aggregation by a box filter
(O(1) per pixel); the cheapest candidate per pixel with a parabolic sub-step. The search
range is the scene's own: a coarse pass at ``1 / coarse_scale`` over ``+-search_limit``
px per view step finds it, or the previous frame's range does in a video
(:class:`HintTracker`).

View axes: a capture whose view grid is not aligned with the image axes (a camera array
with flipped rows, unequal row and column baselines, a rotated rig; see
:func:`lfstream.lightfield.view_offsets`) is detected on a stream's first frame by dense
optical flow from the centre view to the edge mid-point views and a rank-1 fit of the flows
(:func:`estimate_view_axes`); the sweep and the decoder's warp then move points along those
axes. Light fields that follow the convention keep ``A = I`` (the fit must explain the flows
far better than the convention, and change a warped pixel by a quarter of a pixel or more).

Payload (version 2, little-endian)::

    version u8 = 2 | kind u8 (0 full, 1 delta, 2 repeat) | scale u8 | coder u8
    lo f32 | hi f32 | hs u16 | ws u16 | ref u32 | body

Version 4 (5 with the axes below) is the same layout with coder 1 (a full map, context
coded); versions 2 and 3 carry coder 0 (zstd; the byte was reserved before).

Version 3 is version 2 followed by the view axes, ``A`` as 4 f32 (row-major), before the
body; it is written only when ``A`` is not the identity, so a stream that follows the
convention is byte for byte what it was.

``full``: the ``hs x ws`` map quantised to 8 bits over ``[lo, hi]``; with coder 1 (what
the encoder writes) the body is the map's level step ``k`` (u8: the values are multiples
of ``k`` and 255) and its levels, range coded with context-adaptive probabilities
(:mod:`lfstream.codec._entropy`: median-edge prediction, five activity contexts; 12-37 %
fewer bytes than zstd on the shared samples' hints, e.g. lytro_bikes 3195 -> 2072 B, and
faster); with coder 0 (streams written before it) zstd of its planar prediction residual
(``q - left - up + upleft``, mod 256). ``delta``: zstd of the difference (mod 256) to the
quantised map of frame ``ref``, on the same grid and range; ``repeat``: frame ``ref``'s map
unchanged (no body). Version 1 payloads (full maps only, the first release) still decode.

Decoding: the quantised map, upsampled to full resolution by joint bilateral upsampling
guided by the decoded centre view (edges of the depth follow edges of the picture).
"""

from __future__ import annotations

import struct
import threading
from concurrent.futures import Future, wait
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
import zstandard

from lfstream.codec.bitstream import decompress_bounded
from lfstream.errors import BitstreamError, LFShapeError, LFValueError
from lfstream.lightfield import check_lf, to_uint8, view_offsets


class HintReferenceError(BitstreamError):
    """A delta hint refers to a frame this decoder never received (lost in transport)."""


_HEADER_V1 = struct.Struct("<BffHH")
_HEADER_V2 = struct.Struct("<BBBBffHHI")
_AXES = struct.Struct("<4f")
HINT_VERSION = 2
HINT_VERSION_AXES = 3
# versions 2 and 3 whose fourth header byte names the body's coder (:data:`CODER_CONTEXT`):
# readers from before the context coder refuse them by version instead of as corrupt zstd
HINT_VERSION_CODED = 4
HINT_VERSION_CODED_AXES = 5
GEOMETRY_MODES = ("auto", "standard")
#: Largest entry of a view-axes matrix a payload may carry (|A| <= 8: a view step moving a
#: point eight times its disparity is not a light field this codec models).
MAX_AXIS_ENTRY = 8.0
KIND_FULL, KIND_DELTA, KIND_REPEAT = 0, 1, 2
#: How a body is coded (the header's fourth byte, zero before coders existed): zstd, or
#: context-adaptive range coding of the map's levels (full maps; :mod:`lfstream.codec._entropy`)
CODER_ZSTD, CODER_CONTEXT = 0, 1
_ZSTD_LEVEL = 9  # delta maps: level 19 costs ~3 ms for a few hundred bytes less


@dataclass(frozen=True)
class HintOptions:
    """Sweep and coding parameters of the depth hint.

    Attributes:
        max_disparity: search ``[-max_disparity, max_disparity]`` px per view step; ``None``
            (default) derives the range from the scene (coarse pass or previous frame).
        hint_scale: the map is sent at ``1 / hint_scale`` resolution (block means of the
            sweep's map).
        work_scale: the sweep runs at ``1 / work_scale`` (a divisor of ``hint_scale``):
            measured on the real samples, sweeping at the sent resolution (1/4) loses 0.3 to
            2.5 dB of decoded MPSNR against 1/2, which costs about four times the time.
        step: candidate spacing, as the change of the outermost view's shift in pixels of
            the working resolution (smaller: finer, slower); the parabolic fit refines it.
        min_spacing: the candidates' spacing is at least this many pixels of the full view
            per view step (0: ``step`` alone). On a 7x7 grid ``step`` alone spaces them 1/6
            px apart; a quarter pixel (a third fewer candidates) encodes faster, decoded
            MPSNR within 0.02 dB of the finer sweep on the real captures (synthetic clip +0.04 dB), MSSIM within
            0.0001, and on the ground truth of 14 synthetic 7x7x375x540 scenes MSEx100
            28.63 -> 28.19, BadPix(0.07) 0.406 -> 0.356. It does not bind on 5x5 or 3x3 grids
            (1/4 and 1/2 px already), where wider spacing lost: seahorse (5x5) -0.09 dB at
            3/8 px, -0.21 dB on a 128x160 crop.
        box_radius: cost aggregation window radius at the working resolution.
        coarse_scale: resolution divisor of the range-finding pass.
        search_limit: largest ``|disparity|`` (px per view step) the range pass considers.
        key_interval: in a video, a full (non-delta) map at least every this many frames,
            so a receiver that lost packets recovers.
        geometry: ``"auto"`` estimates the capture's view axes on a stream's first frame
            (:func:`estimate_view_axes`); ``"standard"`` assumes the convention (``A = I``).
        median: size (1, 3 or 5) of a median filter on the sent grid; 1: none. The sweep's
            outliers (textureless and occluded pixels) cost bits and help no view.
        precision: quantisation step, as the displacement it makes at the outermost view, in
            pixels (0: the 8-bit grid's finest step). The payload's format is the same; the
            encoder only uses every k-th level, which codes in fewer bytes. Measured
            (with ``median=3``, q50, one frame, against the 8-bit map without the median):
            9-25 % off the stream's bytes on the shared samples and the synthetic clip
            (most of it hint bytes) at MPSNR within 0.05 dB and MSSIM within 0.0005.
    """

    max_disparity: float | None = None
    hint_scale: int = 4
    work_scale: int = 2
    step: float = 0.25
    min_spacing: float = 0.25
    box_radius: int = 2
    coarse_scale: int = 8
    search_limit: float = 16.0
    key_interval: int = 30
    geometry: str = "auto"
    median: int = 3
    precision: float = 0.2

    def validate(self) -> None:
        if self.max_disparity is not None and not (np.isfinite(self.max_disparity) and 0 < self.max_disparity <= 64):
            raise LFValueError(f"max_disparity: in (0, 64] or None, got {self.max_disparity}")
        if not (1 <= self.hint_scale <= 64 and 1 <= self.coarse_scale <= 256 and 0 <= self.box_radius <= 32):
            raise LFValueError("hint options: hint_scale in 1..64, coarse_scale in 1..256, box_radius in 0..32")
        if not (1 <= self.work_scale <= self.hint_scale):
            raise LFValueError("hint options: work_scale in 1..hint_scale")
        if not (0.01 <= self.step <= 2 and 0 < self.search_limit <= 64 and self.key_interval >= 1):
            raise LFValueError("hint options: step in [0.01, 2], search_limit in (0, 64], key_interval >= 1")
        if self.median not in (1, 3, 5):
            raise LFValueError(f"hint options: median 1, 3 or 5, got {self.median!r}")
        if not (np.isfinite(self.min_spacing) and 0 <= self.min_spacing <= 4):
            raise LFValueError(f"hint options: min_spacing in [0, 4] px, got {self.min_spacing!r}")
        if not (np.isfinite(self.precision) and 0 <= self.precision <= 4):
            raise LFValueError(f"hint options: precision in [0, 4] px, got {self.precision!r}")
        if self.geometry not in GEOMETRY_MODES:
            raise LFValueError(f"hint options: geometry one of {', '.join(GEOMETRY_MODES)}, got {self.geometry!r}")

    def as_meta(self) -> dict:
        """What the stream header records about the hint."""
        return {"max_disparity": self.max_disparity, "hint_scale": self.hint_scale, "work_scale": self.work_scale,
                "step": self.step, "box_radius": self.box_radius, "median": self.median, "precision": self.precision}


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


def is_standard(axes: np.ndarray | None) -> bool:
    """Whether view axes are the convention's (``None`` or exactly the identity)."""
    return axes is None or bool(np.array_equal(np.asarray(axes), np.eye(2)))


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
    8-bit grey conversion, then block means (:func:`lfstream.codec.hint_kernels.block_means`;
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
    from lfstream.codec.hint_kernels import block_means

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


def sweeps_on_device(device: str | None) -> bool:
    """Whether a sweep on ``device`` runs as tensor operations
    (:func:`lfstream.codec.sweep_batched.sweep_batched`: a CUDA device) rather than the CPU
    kernels (``None`` or ``"cpu"``)."""
    return device is not None and str(device).startswith("cuda")


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


def _sweep(images: np.ndarray, offsets: np.ndarray, lo: float, hi: float, scale: int, options: HintOptions,
           max_candidates: int = 128, device: str | None = None) -> np.ndarray:
    """Disparity (px of the full view per view step) at the resolution of ``images``; on a
    CUDA ``device`` the same sweep as tensor operations (:func:`sweeps_on_device`)."""
    from lfstream.codec.hint_kernels import sweep_cost, winner_subpixel

    reach = float(np.abs(offsets).max()) or 1.0
    step = max(options.step * scale / reach, options.min_spacing)  # candidate spacing in full-view px per view step
    n = int(np.ceil((hi - lo) / step)) + 1
    if n > max_candidates:
        n, step = max_candidates, (hi - lo) / (max_candidates - 1)
    n = max(n, 3)
    cands = (lo + step * np.arange(n)).astype(np.float32)
    if sweeps_on_device(device):
        from lfstream.codec.sweep_batched import sweep_batched

        return sweep_batched(images, offsets, cands, scale, options.box_radius, device)
    cost = _kept_array("cost", (len(cands), *images.shape[1:]))
    sweep_cost(images, offsets, cands / np.float32(scale), cost)
    r = options.box_radius
    if r:
        for k in range(len(cands)):
            cv2.blur(cost[k], (2 * r + 1, 2 * r + 1), dst=cost[k], borderType=cv2.BORDER_REPLICATE)
    out = np.empty(images.shape[1:], np.float32)
    winner_subpixel(cost, cands, out)
    return out


# view-axes detection (see the module docstring)
_AXES_SCALE = 4  # the detection's resolution divisor; an accepted fit is refined at the sweep's working one
_AXES_MAX_GAIN = 0.5  # the fit's mean flow residual must be below this share of the convention's
_AXES_MIN_SHIFT = 0.25  # px of the full view a warped pixel must move for the axes to matter
_AXES_SAMPLES = 2048  # textured pixels the fit keeps at most (every k-th: a few thousand fix 4 numbers)
# The detection's flows see luma divided by its local mean over this box (pixels at
# 1 / _AXES_SCALE): vignetting darkens outer views unevenly and pulled the flows of the
# synthetic clip (noise, vignetting 0.3) so far that its flipped or transposed grid went
# undetected (28.3 / 29.2 dB against 31.6 in its own order). The refinement keeps plain
# luma: on toys_array it fits 1.08 there, 1.49 on divided luma (the fast preset's decode:
# 19.31 against 16.98 dB).
_AXES_SHADING_BOX = 15


def _flows(images: np.ndarray, scale: int, preset: int, shading_free: bool = False) -> np.ndarray:
    """Dense optical flow (OpenCV's DIS) from ``images[0]`` to each other image, in pixels
    of the full view: ``images[0](x) ~ images[j](x + flow[j - 1](x))``. ``shading_free``:
    each image divided by its local mean first (15 x 15 box), so that vignetting, which
    darkens the outer views unevenly, does not pull the flow (:data:`_AXES_SHADING_BOX`).

    Shape:
        - images: ``(1 + J, h, w)`` float32 in [0, 1]
        - output: ``(J, h, w, 2)`` float32, ``(dx, dy)``
    """
    dis = cv2.DISOpticalFlow_create(preset)
    if shading_free:
        box = (_AXES_SHADING_BOX, _AXES_SHADING_BOX)
        images = [img / (cv2.blur(img, box, borderType=cv2.BORDER_REFLECT) + np.float32(1e-3)) * np.float32(0.5)
                  for img in images]
    as8 = [np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8) for img in images]
    return np.stack([dis.calc(as8[0], img, None) for img in as8[1:]]) * np.float32(scale)


def _fit_axes(images: np.ndarray, steps: np.ndarray, scale: int, preset: int,
              shading_free: bool = False) -> tuple[np.ndarray, bool]:
    """The view axes that best explain the flows from the centre image to the others, and
    whether they explain them clearly better than the convention (and matter).

    Every view j moves a centre pixel by ``-d(x) * A @ steps[j]``: over the views the flows
    of a pixel are one vector ``g = (A @ steps[j])_j`` times a per-pixel scalar, so ``g``
    is the leading eigenvector of the flows' second moments (textured pixels, outliers
    dropped twice), and ``A`` its least-squares fit. Normalised so that a step along ``v``
    moves a point by ``-d`` along the image axis it mostly moves along: ``x`` as in the
    convention (``A[1, 1] = 1``), or ``y`` for a grid stored with its view axes swapped or
    turned a quarter (``A[0, 1] = 1``, e.g. ``(V, U)`` order: ``A`` close to ``[[0, 1], [1,
    0]]``); the same with column 0 where the grid has one column.

    Args:
        images: ``(1 + J, h, w)`` luma at ``1 / scale``; images[0] the centre view.
        steps: ``(J, 2)`` view steps ``(u - u0, v - v0)`` of the other images.
        preset: OpenCV's DIS preset.
        shading_free: the flows on luma divided by its local mean (:func:`_flows`).
    """
    from lfstream.codec.hint_kernels import axes_moments, axes_moved, axes_prune, axes_residuals

    identity = np.eye(2, dtype=np.float32)
    _, h, w = images.shape
    # textured pixels away from the border (where points leave the view) carry the fit
    by, bx = max(2, h // 10), max(2, w // 10)
    if (h - 2 * by) * (w - 2 * bx) < 64:
        return identity, False
    gy, gx = np.gradient(images[0][by - 1:h - by + 1, bx - 1:w - bx + 1])
    texture = np.hypot(gx, gy)[1:-1, 1:-1].ravel()
    sel = np.flatnonzero(texture > np.median(texture))
    if sel.size < 32:
        return identity, False
    sel = sel[::-(-sel.size // _AXES_SAMPLES)]
    flows = _flows(images, scale, preset, shading_free)[:, by:h - by, bx:w - bx].reshape(len(steps), -1, 2)[:, sel]
    f = np.empty((sel.size, 2 * len(steps)), np.float64)  # one row per pixel: dy_j, dx_j
    f[:, 0::2] = flows[..., 1].T
    f[:, 1::2] = flows[..., 0].T
    weight = np.sqrt(texture[sel]).astype(np.float64)
    if not np.all(np.isfinite(f)):
        return identity, False
    k = np.zeros((2 * len(steps), 4))
    k[0::2, 0:2] = steps
    k[1::2, 2:4] = steps
    n = sel.size
    moments = np.empty((f.shape[1], f.shape[1]))
    r = np.empty(n)
    for _ in range(3):
        axes_moments(f, weight, n, moments)
        g = np.ascontiguousarray(np.linalg.eigh(moments)[1][:, -1])
        kept = axes_prune(g, f, weight, n, r, 3.0, 32)
        if not kept:
            break
        n = kept

    def mean_residual(line: np.ndarray) -> float:
        axes_residuals(line, f, n, r)
        return float(np.mean(r[:n]))

    a = np.linalg.lstsq(k, g, rcond=None)[0].reshape(2, 2)
    has_u, has_v = bool(np.any(steps[:, 0])), bool(np.any(steps[:, 1]))
    col = 1 if has_v else 0
    ref = a[int(np.argmax(np.abs(a[:, col]))), col]  # [1, 1] unless the grid is transposed or turned
    if abs(ref) < 0.1 * (np.abs(a).max() + 1e-12):  # a v step barely moves points: not a light field
        return identity, False
    a = a / ref
    if not has_u:
        a[:, 0] = (1.0, 0.0)
    if not has_v:
        a[:, 1] = (0.0, 1.0)
    if not np.all(np.isfinite(a)) or np.abs(a).max() > MAX_AXIS_ENTRY:
        return identity, False
    better = mean_residual(k @ a.ravel()) < _AXES_MAX_GAIN * mean_residual(k @ identity.ravel())
    # how far the axes move a warped pixel against the convention, at the outermost view
    moved = np.linalg.norm(steps @ a.T, axis=1)
    change = np.linalg.norm(steps @ (a - identity).T, axis=1) / np.maximum(moved, 1e-9)
    axes_moved(f, n, np.ascontiguousarray(change, np.float64), r)
    shift = float(np.percentile(r[:n], 98))
    return a.astype(np.float32), bool(better and shift >= _AXES_MIN_SHIFT)


def warm_axes_fit() -> None:
    """Loads the kernels of the view axes' fit (:func:`_fit_axes`) with the argument types it
    calls them with: a stream's warm-up frame is too small for the detection to reach its
    fit, which would otherwise load them (or compile them, on a fresh install) in the first
    timed frame."""
    from lfstream.codec.hint_kernels import axes_moments, axes_moved, axes_prune, axes_residuals

    n, views = 32, 2
    flows = np.zeros((n, 2 * views))
    weight, r = np.ones(n), np.empty(n)
    axes_moments(flows, weight, n, np.empty((2 * views, 2 * views)))
    line = np.ones(2 * views)
    axes_prune(line, flows, weight, n, r, 3.0, n)
    axes_residuals(line, flows, n, r)
    axes_moved(flows, n, np.ones(views), r)


def _axes_views(keys: list[tuple[int, int]], u: int, v: int, present: np.ndarray | None) -> list[int]:
    """Which sweep views (:func:`sweep_views`) the axes detection uses: of the outer ring
    (the longest flows, and the fit it was tuned on), those on the centre's row and column
    (pure steps along one axis) where each axis of the grid has one, else the whole ring."""
    centre = (u // 2, v // 2)
    keys = keys[: len(_ring_views(u, v, present))]  # sweep_views puts the ring first
    on_axis = [j for j, (a, b) in enumerate(keys) if (a == centre[0]) != (b == centre[1])]
    u_ok = any(keys[j][0] != centre[0] for j in on_axis) or all(a == centre[0] for a, _ in keys)
    v_ok = any(keys[j][1] != centre[1] for j in on_axis) or all(b == centre[1] for _, b in keys)
    return on_axis if on_axis and u_ok and v_ok else list(range(len(keys)))


def _detect_axes(grids: np.ndarray, steps: np.ndarray, use: list[int], work: int) -> np.ndarray:
    """The view axes of a frame from its sweep grids (centre first, then the views of
    ``steps``), by optical flow on the views ``use``: detected at ``1 / _AXES_SCALE`` on
    OpenCV's fast preset and luma freed of shading (every stream pays this, a few
    milliseconds), refined at the working resolution on the medium preset for captures off
    the convention only (where the refinement's fit is not accepted, the detection's axes)."""
    factor = max(1, _AXES_SCALE // work)
    grids = grids[[0, *(1 + j for j in use)]]
    steps = steps[use]
    coarse = _coarser(grids, factor) if factor > 1 else grids
    if min(coarse.shape[1:]) < 16:
        return np.eye(2, dtype=np.float32)
    axes, found = _fit_axes(coarse, steps, work * factor, cv2.DISOPTICAL_FLOW_PRESET_FAST, shading_free=True)
    if not found:
        return np.eye(2, dtype=np.float32)
    fine, found = _fit_axes(grids, steps, work, cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return fine if found else axes


def estimate_view_axes(lf: np.ndarray, present: np.ndarray | None = None,
                       work_scale: int = HintOptions.work_scale) -> np.ndarray:
    """The view axes of a light field (:func:`lfstream.lightfield.view_offsets`): the
    identity where it follows the convention, else the 2x2 matrix its views move along.

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output: ``(2, 2)`` float32
    """
    u, v, h, w, _ = check_lf(lf, allow_video=False)
    frame = np.ascontiguousarray(to_uint8(np.asarray(lf)))
    keys = sweep_views(u, v, present)
    centre = (u // 2, v // 2)
    if not keys:
        return np.eye(2, dtype=np.float32)
    steps = np.asarray([(a - centre[0], b - centre[1]) for a, b in keys], np.float64)
    return _detect_axes(_grids(frame, [centre, *keys], work_scale), steps, _axes_views(keys, u, v, present),
                        work_scale)


def scene_range(disparity: np.ndarray, margin: float) -> tuple[float, float]:
    """Robust range of a disparity map (1st..99th percentile), widened by ``margin``."""
    lo, hi = np.percentile(disparity, [1, 99]) if disparity.size else (0.0, 0.0)
    return float(lo - margin), float(hi + margin)


def estimate_hint_map(lf: np.ndarray, options: HintOptions = HintOptions(), present: np.ndarray | None = None,
                      search: tuple[float, float] | None = None, axes: np.ndarray | None = None,
                      keep_ring_luma: bool = False, keep_coarse: bool = False, device: str | None = None) -> HintMap:
    """The centre view's disparity at the hint's resolution.

    Args:
        lf: one frame, uint8 or float in [0, 1].
        options: sweep parameters.
        present: ``(U, V)`` mask of views that exist (e.g. an HCI "star").
        search: ``(lo, hi)`` range to sweep (a video's previous frame); ``None``: the options'
            ``max_disparity``, else a coarse pass finds the scene's range.
        axes: the capture's view axes (a video's first frame); ``None``: detected
            (``options.geometry == "auto"``) or the convention.
        keep_ring_luma: fill :attr:`HintMap.ring_luma`.
        keep_coarse: fill :attr:`HintMap.coarse` (block means of the same working map and
            the same median: well under a millisecond).
        device: ``None`` or ``"cpu"``: the sweep on the CPU kernels; ``"cuda"``: the sweep as
            tensor operations there (:func:`sweeps_on_device`; the views' luma, the axes and
            the range pass's texture test stay on the CPU).

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output disparity: ``(H // hint_scale, W // hint_scale)``
    """
    options.validate()
    u, v, h, w, _ = check_lf(lf, allow_video=False)
    frame = np.ascontiguousarray(to_uint8(np.asarray(lf)))
    keys = sweep_views(u, v, present)
    s = min(options.hint_scale, h, w)
    work = max(1, min(options.work_scale, s))
    s -= s % work  # the sent grid is made of whole working-resolution blocks
    hs, ws = max(1, h // s), max(1, w // s)
    identity = np.eye(2, dtype=np.float32)
    if not keys:
        return HintMap(np.zeros((hs, ws), np.float32), s, (0.0, 0.0), identity if axes is None else axes)
    centre = (u // 2, v // 2)
    steps = np.asarray([(a - centre[0], b - centre[1]) for a, b in keys], np.float64)
    grids = _grids(frame, [centre, *keys], work, kept=True)
    f = s // work
    ring_luma = None
    if keep_ring_luma:
        n_ring = 1 + len(_ring_views(u, v, present))  # sweep_views puts the ring first
        # block means of block means are the map's block means (taken before the in-place
        # high-pass; OpenCV's area resize: numpy's mean over a reshape took 4 ms, this 0.2)
        ring_luma = np.stack([cv2.resize(g[: hs * f, : ws * f], (ws, hs), interpolation=cv2.INTER_AREA)
                              for g in grids[:n_ring]]) if f > 1 else grids[:n_ring].copy()
    detection = None
    if axes is None and options.geometry == "auto":
        # the detection (optical flow, a few ms) runs beside the sweeps, which assume the
        # convention meanwhile: it is what almost every capture turns out to follow, and
        # where the detection finds other axes the sweeps run again with them (same result
        # as detecting first, either way)
        from lfstream.codec.watchdog import beside

        use = _axes_views(keys, u, v, present)
        detection = beside(lambda: _detect_axes(grids, steps, use, work))
    guess = identity if axes is None else np.asarray(axes, np.float32)
    try:
        high_passed = None
        if detection is not None:  # the detection reads the plain grids meanwhile
            high_passed = _kept_array("high_passed", grids.shape)
            np.copyto(high_passed, grids)
            _high_pass(high_passed)
        lo, hi, work_map, grid_offsets = _sweeps(grids, high_passed, keys, (u, v), guess, work, options, search,
                                                  device)
    except BaseException:
        if detection is not None:  # done with this thread's kept grids before they are reused
            wait([detection])
        raise
    if detection is not None:
        axes = np.asarray(detection.result(), np.float32)
        if not np.array_equal(axes, guess):
            lo, hi, work_map, grid_offsets = _sweeps(grids, high_passed, keys, (u, v), axes, work, options, search,
                                                      device)
    else:
        axes = guess
    disp = _sent_grid(work_map, (h, w), s, work, options.median)
    coarse = _sent_grid(work_map, (h, w), 2 * s, work, options.median) if keep_coarse else None
    return HintMap(disp, s, (float(lo), float(hi)), axes, float(np.abs(grid_offsets).max()) or 1.0, ring_luma,
                   coarse)


def _sweeps(grids: np.ndarray, high_passed: np.ndarray | None, keys: list[tuple[int, int]], views: tuple[int, int],
            axes: np.ndarray, work: int, options: HintOptions, search: tuple[float, float] | None,
            device: str | None) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The range pass (where ``search`` is ``None`` and the options fix no range) and the
    working-resolution sweep of :func:`estimate_hint_map` for view ``axes``: the range swept,
    the working map and the whole grid's view offsets. ``high_passed``: ``grids`` through
    :func:`_high_pass` where the caller has it, else ``grids`` is high-passed in place."""
    rows, cols = np.asarray(keys).T
    grid_offsets = view_offsets(views, axes)
    offsets = np.ascontiguousarray(grid_offsets[rows, cols])
    if search is None:
        if options.max_disparity is not None:
            search = (-options.max_disparity, options.max_disparity)
        else:
            factor = max(1, options.coarse_scale // work)
            cs = work * factor
            images = _high_pass(_coarser(grids, factor))
            coarse = _sweep(images, offsets, -options.search_limit, options.search_limit, cs,
                            HintOptions(step=0.5, box_radius=1), device=device)
            # textureless pixels match anywhere: the range comes from the textured ones
            texture = cv2.blur(np.abs(images[0]), (3, 3))
            textured = texture > 0.01
            reach = float(np.abs(offsets).max()) or 1.0
            lo, hi = scene_range(coarse[textured] if textured.mean() > 0.05 else coarse, margin=0.5 * cs / reach)
            search = (max(lo, -options.search_limit), min(hi, options.search_limit))
    lo, hi = search
    if not hi > lo:  # an empty range (or one the search limit cut off entirely): around it
        lo, hi = min(lo, hi) - 0.5, max(lo, hi) + 0.5
    images = high_passed if high_passed is not None else _high_pass(grids)
    return lo, hi, _sweep(images, offsets, lo, hi, work, options, device=device), grid_offsets


def _sent_grid(work_map: np.ndarray, size: tuple[int, int], scale: int, work: int, median: int) -> np.ndarray:
    """The map sent at ``scale``: block means of the working-resolution map (``work`` px
    a cell), median-filtered where it is large enough."""
    h, w = size
    hs, ws = max(1, h // scale), max(1, w // scale)
    f = scale // work
    disp = work_map
    if f > 1:
        disp = cv2.resize(work_map[: hs * f, : ws * f], (ws, hs), interpolation=cv2.INTER_AREA)
    if median > 1 and min(disp.shape) >= median:
        disp = cv2.medianBlur(np.ascontiguousarray(disp, np.float32), median)
    return disp


def estimate_disparity(lf: np.ndarray, options: HintOptions = HintOptions(),
                       present: np.ndarray | None = None) -> np.ndarray:
    """The hint's disparity upsampled (bilinearly) to the views' resolution, for evaluation.

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output: ``(H, W)`` float32, pixels per view step
    """
    hm = estimate_hint_map(lf, options, present)
    h, w = np.asarray(lf).shape[2:4]
    return _upsample(hm.disparity, hm.scale, (h, w))


def _upsample(small: np.ndarray, scale: int, size: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling that maps map pixel k to the centre of its ``scale`` block."""
    h, w = size
    hs, ws = small.shape
    ys = np.clip((np.arange(h, dtype=np.float32) + 0.5) / scale - 0.5, 0, hs - 1)
    xs = np.clip((np.arange(w, dtype=np.float32) + 0.5) / scale - 0.5, 0, ws - 1)
    mx, my = np.meshgrid(xs, ys)
    return cv2.remap(np.ascontiguousarray(small, np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


# ----------------------------------------------------------------------------------------
# coding


@dataclass
class QuantisedHint:
    """A hint map on its 8-bit grid: what the encoder sent and the decoder rebuilt."""

    q: np.ndarray  # (hs, ws) uint8
    lo: float
    hi: float
    scale: int
    axes: np.ndarray | None = None  # (2, 2) float32 view axes; None: the convention

    def values(self) -> np.ndarray:
        span = self.hi - self.lo if self.hi > self.lo else 1.0
        return (self.lo + self.q.astype(np.float32) / np.float32(255.0) * np.float32(span)).astype(np.float32)


def level_step(span: float, reach: float, precision: float) -> int:
    """How many 8-bit levels apart the quantised values are: the largest step whose
    displacement at the outermost view (``reach`` px per unit disparity) stays within
    ``precision`` px (at least 1, at most 64)."""
    if precision <= 0 or span <= 0:
        return 1
    return int(min(max(precision * 255.0 / (span * max(reach, 1e-6)), 1.0), 64.0))


def quantise(hm: HintMap, search: tuple[float, float] | None = None, precision: float = 0.0) -> QuantisedHint:
    """8-bit levels over ``search`` (default: the map's own range), every
    :func:`level_step`-th level used."""
    d = hm.disparity
    lo, hi = search if search is not None else (float(d.min()), float(d.max()))
    span = hi - lo if hi > lo else 1.0
    k = level_step(float(np.float32(hi) - np.float32(lo)), hm.reach, precision)
    # multiples of k, and 255 for what rounds past the last one (still within k / 2 levels)
    q = np.clip(np.round((d - lo) / span * (255.0 / k)) * k, 0, 255).astype(np.uint8)
    # the range as the payload will carry it (float32), so encoder and decoder agree exactly
    axes = None if is_standard(hm.axes) else np.asarray(hm.axes, np.float32)
    return QuantisedHint(q, float(np.float32(lo)), float(np.float32(hi)), hm.scale, axes)


def _pack(kind: int, qh: QuantisedHint, ref: int, body: bytes, coder: int = CODER_ZSTD) -> bytes:
    hs, ws = qh.q.shape
    coded = coder != CODER_ZSTD
    if qh.axes is None:  # the convention: version 2 (4 with a coder), as before view axes existed
        version = HINT_VERSION_CODED if coded else HINT_VERSION
        return _HEADER_V2.pack(version, kind, qh.scale, coder, qh.lo, qh.hi, hs, ws, ref) + body
    version = HINT_VERSION_CODED_AXES if coded else HINT_VERSION_AXES
    return (_HEADER_V2.pack(version, kind, qh.scale, coder, qh.lo, qh.hi, hs, ws, ref)
            + _AXES.pack(*np.asarray(qh.axes, np.float32).ravel().tolist()) + body)


def _diff2d(q: np.ndarray) -> np.ndarray:
    """The planar prediction residual ``q - (left + up - upleft)`` mod 256: disparity is
    piecewise smooth, so the residual is mostly near zero (measured: zstd then needs 31 to
    44 % fewer bytes on the real samples)."""
    d = np.diff(q.astype(np.int16), axis=1, prepend=0)
    return np.diff(d, axis=0, prepend=0).astype(np.uint8)


def _undiff2d(r: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_diff2d`: the 2-D running sum mod 256 (exact)."""
    return (np.cumsum(np.cumsum(r.astype(np.int64), axis=0), axis=1) % 256).astype(np.uint8)


def _level_step_of(q: np.ndarray) -> int:
    """The spacing ``k`` of a quantised map's values (:func:`quantise` uses multiples of
    ``k`` and 255): the largest that describes every value, 1 where none does better."""
    v = q.astype(np.int64)
    inner = v[v != 255]
    # values below 255 have a gcd below 255; none but 0 (gcd 0): the two levels 0 and 255
    k = (int(np.gcd.reduce(inner)) if inner.size else 0) or 255
    return k if np.all((v % k == 0) | (v == 255)) else 1


def _level_count(k: int) -> int:
    """Levels on a grid of step ``k``: 0, k, 2k, ... and 255 where it is not a multiple."""
    return 255 // k + 1 + (1 if 255 % k else 0)


def _coded_body(q: np.ndarray) -> bytes:
    """A full map's body for :data:`CODER_CONTEXT`: its level step, then its levels
    (:func:`lfstream.codec._entropy.encode_levels`; the coder's first byte, always 0, left out)."""
    from lfstream.codec._entropy import code_levels

    k = _level_step_of(q)
    return bytes([k]) + code_levels(np.where(q == 255, _level_count(k) - 1, q.astype(np.int32) // k))


def _decoded_body(body: bytes, shape: tuple[int, int], frame: int | None) -> np.ndarray:
    """Inverse of :func:`_coded_body`: the ``(hs, ws)`` uint8 map."""
    from lfstream.codec._entropy import OK, OVERRUN, decode_coded_levels

    if len(body) < 1 or body[0] == 0:
        raise BitstreamError("depth hint: coded map without a level step", frame)
    k = body[0]
    count = _level_count(k)
    levels, status = decode_coded_levels(body[1:], shape, count)
    if status != OK:
        why = "truncated" if status == OVERRUN else "corrupt"
        raise BitstreamError(f"depth hint: {why} coded map", frame)
    values = np.minimum(np.arange(count, dtype=np.int32) * k, 255).astype(np.uint8)
    return values[levels]


def key_payload(qh: QuantisedHint) -> bytes:
    """The payload that sends ``qh`` whole (a key hint: no reference to another frame)."""
    return _pack(KIND_FULL, qh, 0, _coded_body(qh.q), CODER_CONTEXT)


def encode_hint(disparity: np.ndarray | HintMap, options: HintOptions = HintOptions()) -> bytes:
    """A self-contained (``full``) hint payload. A full-resolution ``(H, W)`` map is first
    reduced to the hint grid (area average by ``options.hint_scale``)."""
    if isinstance(disparity, HintMap):
        hm = disparity
    else:
        d = np.asarray(disparity, np.float32)
        if d.ndim != 2:
            raise LFShapeError(f"disparity: expected (H, W), got {d.shape}")
        s = min(options.hint_scale, *d.shape)
        hs, ws = max(1, d.shape[0] // s), max(1, d.shape[1] // s)
        small = cv2.resize(d[: hs * s, : ws * s], (ws, hs), interpolation=cv2.INTER_AREA)
        hm = HintMap(small, s, (float(d.min()), float(d.max())))
    return key_payload(quantise(hm, precision=options.precision))


class HintTracker:
    """The encoder's hint state across the frames of a video.

    A key hint (the first frame, then every ``key_interval`` frames, and whenever the scene's
    range changes) runs the range pass and is sent whole; the frames after it sweep the key
    hint's range (no range pass) and are sent as deltas on the key hint's 8-bit grid, or as
    "repeat" when nothing changed: a static scene's hint costs a few bytes per frame.
    """

    def __init__(self, options: HintOptions = HintOptions(), device: str | None = None) -> None:
        options.validate()
        self.options = options
        self.device = device  # where the sweep runs (estimate_hint_map)
        self._prev: QuantisedHint | None = None
        self._prev_seq = -1
        self._since_key = 0
        self._search: tuple[float, float] = (0.0, 0.0)  # the key hint's sweep range
        self._axes: np.ndarray | None = None  # the capture's view axes, from the first frame
        self.last_ring_luma: np.ndarray | None = None  # the last frame's HintMap.ring_luma (key hints only)
        self._key_map: HintMap | None = None  # the last key hint's map (with its coarser twin)

    @property
    def last(self) -> QuantisedHint | None:
        """The last frame's hint as the decoder rebuilds it (``None`` before the first)."""
        return self._prev

    def encode(self, lf: np.ndarray, seq: int, present: np.ndarray | None = None) -> bytes:
        """The hint payload of frame ``seq`` (frames must come in order for deltas)."""
        return self.start_encode(lf, seq, present).result()

    def start_encode(self, lf: np.ndarray, seq: int, present: np.ndarray | None = None) -> Future:
        """:meth:`encode`, returning as soon as the hint is known (:attr:`last` is set): the
        future of its payload, whose entropy coding runs on a worker thread meanwhile, so the caller can measure what depends on
        the hint (the shading gains) beside it. On a worker thread, coded before returning."""
        from lfstream.codec.watchdog import completed, in_background, on_worker_thread

        opts = self.options
        prev = self._prev
        key = prev is None or self._since_key + 1 >= opts.key_interval or seq != self._prev_seq + 1
        hm = estimate_hint_map(lf, opts, present, None if key else self._search, self._axes, keep_ring_luma=key,
                               keep_coarse=key, device=self.device)
        self._axes = hm.axes  # a rig's geometry does not change within a video
        if not key:
            lo, hi = self._search
            edge = 0.02 * (hi - lo)
            pressed = float(np.mean((hm.disparity <= lo + edge) | (hm.disparity >= hi - edge)))
            if pressed > 0.02 and opts.max_disparity is None:  # the scene's range changed: search again
                hm, key = estimate_hint_map(lf, opts, present, axes=self._axes, keep_ring_luma=True,
                                            device=self.device), True
        payload = None
        if not key and prev.q.shape == hm.disparity.shape and prev.scale == hm.scale \
                and prev.lo <= float(hm.disparity.min()) and float(hm.disparity.max()) <= prev.hi:
            # on the previous frame's 8-bit grid: a delta, or nothing if nothing changed
            qh = quantise(hm, (prev.lo, prev.hi), opts.precision)
            if np.array_equal(qh.q, prev.q):
                payload = _pack(KIND_REPEAT, qh, self._prev_seq, b"")
            else:
                delta = (qh.q.astype(np.int16) - prev.q).astype(np.uint8)  # mod 256
                payload = _pack(KIND_DELTA, qh, self._prev_seq,
                                zstandard.ZstdCompressor(level=_ZSTD_LEVEL).compress(delta.tobytes()))
                whole = key_payload(qh)
                if len(whole) < len(payload):  # a moving scene: the map itself is smaller
                    payload = whole
        if payload is None:
            qh = self._key_hint(hm)
            job = completed(key_payload(qh)) if on_worker_thread() else in_background(lambda: key_payload(qh))
            self._since_key = 0
            self._search = hm.search
            self._key_map = hm
        else:
            job = completed(payload)
            self._since_key += 1
        self._prev, self._prev_seq = qh, seq
        self.last_ring_luma = hm.ring_luma
        return job

    def _key_hint(self, hm: HintMap) -> QuantisedHint:
        """A key hint's 8-bit grid, with headroom so that the next frames' deltas fit it."""
        d = hm.disparity
        lo, hi = float(d.min()), float(d.max())
        pad = 0.1 * (hi - lo) + 0.05
        # the headroom stays within the range swept, but the grid always covers the map: the
        # sweep's last candidate and its sub-pixel step can lie past the range's end, and a
        # map entirely past it (a tiny, noisy frame) gave an inverted range the decoder refused
        return quantise(hm, (min(max(lo - pad, hm.search[0]), lo), max(min(hi + pad, hm.search[1]), hi)),
                        self.options.precision)

    def coarser_key_hint(self) -> QuantisedHint | None:
        """The last frame's key hint as it would be sent at twice the scale, from the same
        sweep (:attr:`HintMap.coarse`): exactly the hint a tracker with that ``hint_scale``
        sends for the frame. ``None`` where the last frame was not a key hint."""
        hm = self._key_map
        if self._prev is None or self._since_key != 0 or hm is None or hm.coarse is None:
            return None
        return self._key_hint(HintMap(hm.coarse, 2 * hm.scale, hm.search, hm.axes, hm.reach))

    def coarsen(self, payload: bytes | None = None) -> bytes:
        """Sends the last frame's key hint at twice the scale (:meth:`coarser_key_hint`)
        instead, and the frames after it at that scale: the payload that replaces the
        frame's (``payload``: its :func:`key_payload` where the caller coded it already)."""
        qh = self.coarser_key_hint()
        if qh is None:
            raise LFValueError("coarsen: the last frame's hint is not a key hint")
        self.options = replace(self.options, hint_scale=qh.scale)
        self._prev = qh
        self._key_map = None
        return key_payload(qh) if payload is None else payload


class HintDecoder:
    """The decoder's hint state: the last frames' quantised maps, for delta payloads."""

    def __init__(self, keep: int = 4) -> None:
        self._maps: dict[int, QuantisedHint] = {}
        self._keep = keep

    def parse(self, data: bytes, size: tuple[int, int], frame: int | None = None) -> QuantisedHint:
        """The quantised map of a payload, remembered for the deltas that follow."""
        qh = _parse(data, size, frame, self._maps)
        if frame is not None:
            self._maps[frame] = qh
            for k in sorted(self._maps)[: -self._keep]:
                del self._maps[k]
        return qh

    def decode(self, data: bytes, size: tuple[int, int], guide: np.ndarray | None = None,
               frame: int | None = None) -> np.ndarray:
        """The ``(H, W)`` float32 disparity of a hint payload (see :func:`decode_hint`)."""
        return self.decode_with_axes(data, size, guide, frame)[0]

    def decode_with_axes(self, data: bytes, size: tuple[int, int], guide: np.ndarray | None = None,
                         frame: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """The disparity and the view axes it is measured along (``None``: the convention)."""
        qh = self.parse(data, size, frame)
        return _expand(qh, size, guide), qh.axes


def _parse(data: bytes, size: tuple[int, int], frame: int | None, refs: dict[int, QuantisedHint]) -> QuantisedHint:
    h, w = size
    if len(data) < 1:
        raise BitstreamError("depth hint: truncated", frame)
    version = data[0]
    axes = None
    if version == 1:
        if len(data) < _HEADER_V1.size:
            raise BitstreamError("depth hint: truncated", frame)
        _, lo, hi, hs, ws = _HEADER_V1.unpack_from(data)
        kind, scale, ref, body, coder = KIND_FULL, None, 0, data[_HEADER_V1.size:], CODER_ZSTD
    elif version in (HINT_VERSION, HINT_VERSION_AXES, HINT_VERSION_CODED, HINT_VERSION_CODED_AXES):
        with_axes = version in (HINT_VERSION_AXES, HINT_VERSION_CODED_AXES)
        head = _HEADER_V2.size + (_AXES.size if with_axes else 0)
        if len(data) < head:
            raise BitstreamError("depth hint: truncated", frame)
        _, kind, scale, coder, lo, hi, hs, ws, ref = _HEADER_V2.unpack_from(data)
        body = data[head:]
        if kind not in (KIND_FULL, KIND_DELTA, KIND_REPEAT) or scale < 1:
            raise BitstreamError(f"depth hint: unknown kind {kind} or scale {scale}", frame)
        if version in (HINT_VERSION, HINT_VERSION_AXES):
            coder = CODER_ZSTD  # the byte was reserved (written as 0) before coders existed
        elif coder != CODER_CONTEXT or kind != KIND_FULL:
            raise BitstreamError(f"depth hint: unknown coder {coder} for a kind {kind} map", frame)
        if with_axes:
            axes = np.asarray(_AXES.unpack_from(data, _HEADER_V2.size), np.float32).reshape(2, 2)
            if not (np.all(np.isfinite(axes)) and np.abs(axes).max() <= MAX_AXIS_ENTRY):
                raise BitstreamError(f"depth hint: bad view axes {axes.ravel().tolist()}", frame)
    else:
        raise BitstreamError(f"depth hint: unknown version {version}", frame)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi and abs(lo) < 1e4 and abs(hi) < 1e4):
        raise BitstreamError(f"depth hint: bad range {lo}..{hi}", frame)
    if not (1 <= hs <= h and 1 <= ws <= w):
        raise BitstreamError(f"depth hint: map size {hs}x{ws} does not fit the view size {h}x{w}", frame)
    if scale is None:  # version 1: the map spans the view
        scale = max(1, int(round(h / hs)))
    base = None
    if kind != KIND_FULL:
        base = refs.get(ref)
        if base is None or base.q.shape != (hs, ws) or not (np.isclose(base.lo, lo) and np.isclose(base.hi, hi)):
            raise HintReferenceError(f"depth hint: refers to frame {ref}, which this decoder does not have", frame)
        if kind == KIND_REPEAT:
            return QuantisedHint(base.q, base.lo, base.hi, scale, axes)
    if coder == CODER_CONTEXT:
        return QuantisedHint(_decoded_body(body, (hs, ws), frame), float(lo), float(hi), int(scale), axes)
    try:
        raw = decompress_bounded(body, hs * ws)
    except zstandard.ZstdError as exc:
        raise BitstreamError(f"depth hint: corrupt ({exc})", frame) from exc
    if len(raw) != hs * ws:
        raise BitstreamError(f"depth hint: {len(raw)} values where {hs * ws} were expected", frame)
    q = np.frombuffer(raw, np.uint8).reshape(hs, ws)
    if base is not None:
        q = (base.q.astype(np.int16) + q).astype(np.uint8)
    elif version != 1:  # a full map of version 2 or 3: the planar prediction residual
        q = _undiff2d(q)
    return QuantisedHint(q.copy(), float(lo), float(hi), int(scale), axes)


# range weights of the joint bilateral upsampling, by absolute 8-bit grey difference
_RANGE_SIGMA = 50.0
_RANGE_LUT = np.exp(-(np.arange(256, dtype=np.float32) ** 2) / (2 * _RANGE_SIGMA**2)).astype(np.float32)


def _expand(qh: QuantisedHint, size: tuple[int, int], guide: np.ndarray | None) -> np.ndarray:
    small = qh.values()
    if guide is None:
        full = _upsample(small, qh.scale, size)
    else:
        from lfstream.codec.hint_kernels import joint_upsample

        g8 = to_uint8(np.asarray(guide))
        gray = cv2.cvtColor(np.ascontiguousarray(g8), cv2.COLOR_RGB2GRAY) if g8.ndim == 3 else g8
        hs, ws = small.shape
        # the guide on the map's grid: block means, as the encoder's sweep saw it
        crop = gray[: hs * qh.scale, : ws * qh.scale]
        gsmall = cv2.resize(crop if crop.shape == (hs * qh.scale, ws * qh.scale) else gray, (ws, hs),
                            interpolation=cv2.INTER_AREA)
        full = np.empty(size, np.float32)
        joint_upsample(small, gsmall, np.ascontiguousarray(gray), np.float32(qh.scale), _RANGE_LUT, full)
    full = np.asarray(full, np.float32)
    return np.clip(full, np.float32(qh.lo), np.float32(max(qh.hi, qh.lo)), out=full)  # in place: a fresh map


def decode_hint(data: bytes, size: tuple[int, int], guide: np.ndarray | None = None, frame: int | None = None) -> np.ndarray:
    """A self-contained hint payload to the ``(H, W)`` float32 disparity, upsampled edge-aware
    (joint bilateral, guided by the decoded centre view ``guide``) or bilinearly without a
    guide. Delta payloads need the frames they refer to: use a :class:`HintDecoder`."""
    return _expand(_parse(data, size, frame, {}), size, guide)


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


__all__ = ["HintReferenceError", "HintOptions", "HintMap", "HintTracker", "HintDecoder", "QuantisedHint", "sweep_views",
           "estimate_hint_map", "estimate_disparity",
           "estimate_view_axes", "is_standard", "GEOMETRY_MODES", "encode_hint", "decode_hint", "disparity_errors", "scene_range",
           "quantise", "level_step", "sweeps_on_device", "key_payload"]
