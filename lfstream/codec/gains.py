"""Per-view brightness: vignetting and colour shading sent as tiny gain maps.

Real plenoptic captures darken towards the corner views (the main lens's mechanical
vignetting) and shade colours differently per view; a warp of the centre view copies the
centre's brightness into every view and misses that entirely. The encoder, which has
every view, measures each view's low-frequency gain against the centre view on a coarse
grid (``grid x grid`` cells per view, per colour channel), and sends it as 8-bit
log2-gains, range coded (key maps) or zstd-compressed (deltas); the decoder multiplies
each warped view by the upsampled gain. With the depth hint, each view is sampled where
the centre's samples appear in it (the hint's disparity), so a cell compares the same
surfaces and the gain captures shading, not the content parallax moves between views (on
a camera array's large disparities coarse cells alone did not suffice).

Payload, a full map: ``u8 kind = 4, u8 grid_h, u8 grid_w, u8 channels, u8 U, u8 V`` + the
int8 values ``round(64 * log2(gain))``, shape ``(U, V, grid_h, grid_w, channels)``, plus
127 as one level image (rows ``(u, grid_y)``, columns ``(v, grid_x, channel)``) range coded
with context-adaptive probabilities (:mod:`lfstream.codec._entropy`; 19-27 % fewer bytes
than zstd on the synthetic scenes). In a video (:class:`GainTracker`), the frames between
key maps (every ``key_interval`` frames) send a delta (``kind = 5``): the same header plus
``u32 reference``, the frame whose map it changes, + zstd(uint8 ``(q - q_reference)
mod 256``). Shading is a property of the camera, but the measured cells also move with the
content (on the built-in clip 40 % of the values change by a step from frame to frame, 3-8 %
by more), so the encoder keeps a cell's sent value until the measurement leaves it by more than
:data:`GAIN_DEADBAND` steps: deltas of ~0.35 KB instead of ~1.85 KB maps a frame.
"""

from __future__ import annotations

import struct

import cv2
import numpy as np
import zstandard

from lfstream.codec.bitstream import decompress_bounded
from lfstream.errors import BitstreamError, LFShapeError, LFValueError

_HEADER = struct.Struct("<BBBBBB")
_REFERENCE = struct.Struct("<I")
#: The payload's first byte: a full map, range coded with context-adaptive probabilities
#: (:mod:`lfstream.codec._entropy`), or a delta to an earlier frame's map. 1 to 3 were
#: written by development builds and are refused with a line that says so.
KIND_FULL = 4
KIND_DELTA = 5
OLDER_KINDS = (1, 2, 3)
#: Steps (1.1 % each) a cell's measurement may move before the encoder sends the new value.
GAIN_DEADBAND = 1
_STEP = 64.0  # int8 units per octave: gains within 2**(+-127/64) ~ [0.25, 3.96], 1.1 % steps


def measure_gains(lf: np.ndarray, grid: int = 4, channels: int = 3, present: np.ndarray | None = None,
                  disparity: np.ndarray | None = None, axes: np.ndarray | None = None) -> np.ndarray:
    """Gains ``(U, V, gh, gw, channels)`` of each view against the centre view, cell by cell;
    views marked absent in ``present`` get gain 1.

    With ``disparity`` (the centre view's, at any resolution: the decoded hint map) each
    view is sampled where the centre's samples appear in it (``x - d * (u - u0)``, view
    ``axes`` as :func:`lfstream.lightfield.view_offsets`), so a cell compares the same
    surfaces, not whatever parallax moved into it: on a camera array (toys_array, ~7.5 px
    of disparity per view step) uncompensated cells measured content, and the "gains"
    cost 0.49 dB MPSNR against sending none.

    Shape:
        - lf: ``(U, V, H, W, C)``; disparity: ``(h, w)`` px per view step
    """
    if grid < 1 or channels not in (1, 3):
        raise LFValueError(f"gain grid >= 1 and channels 1 or 3, got {grid}, {channels}")
    x = np.asarray(lf)
    u, v, h, w, c = x.shape
    # cells this coarse need no full-resolution pass: about 8 x 8 samples per cell are
    # plenty (shading is smooth) and keep the encoder's cost near a millisecond
    step = max(1, min(h, w) // (8 * grid))
    ys, xs = np.arange(0, h, step), np.arange(0, w, step)
    gh = max(1, min(grid, len(ys)))
    gw = max(1, min(int(round(grid * w / max(h, 1))), len(xs)))
    scale = np.float32(1 / 255.0) if x.dtype == np.uint8 else np.float32(1.0)
    from lfstream.codec.gains_kernels import gain_samples
    from lfstream.lightfield import read_only, view_offsets

    if disparity is None:
        d_samples = np.zeros((len(ys), len(xs)), np.float32)
    else:
        d = np.asarray(disparity, np.float32)
        # the map's value at each sample: nearest cell of the (coarser) map
        dy = np.minimum((ys * d.shape[0]) // h, d.shape[0] - 1)
        dx = np.minimum((xs * d.shape[1]) // w, d.shape[1] - 1)
        d_samples = np.ascontiguousarray(d[dy[:, None], dx[None, :]])
    # each view is read where the centre's samples appear in it (``x - d * (u - u0)``), all
    # views' samples in one parallel pass, their grids stacked along the rows, and averaged
    # into cells by one area resize: the same cells as a resize per view (whole cells per
    # view, the same weights) in under a millisecond a 7x7x375x540 frame, where numpy's
    # gather and a resize per view took about 4
    src = x if x.dtype in (np.uint8, np.float32, np.float64) else x.astype(np.float32)  # no float copy of a float LF
    n = u * v
    samples = np.empty((n * len(ys), len(xs), c), np.float32)
    gain_samples(read_only(np.ascontiguousarray(src)), ys.astype(np.float32), xs.astype(np.float32), d_samples,
                 view_offsets((u, v), axes), scale, samples)
    if c <= 4:  # OpenCV 5 resizes up to four channels at once
        cells = cv2.resize(samples, (gw, n * gh), interpolation=cv2.INTER_AREA).reshape(n * gh, gw, c)
    else:
        cells = np.stack([cv2.resize(np.ascontiguousarray(samples[..., k]), (gw, n * gh), interpolation=cv2.INTER_AREA)
                          for k in range(c)], axis=-1)
    cells = cells.reshape(u, v, gh, gw, c)
    if channels == 1:
        cells = cells.mean(-1, keepdims=True)
    ref = cells[u // 2, v // 2]
    # the offset keeps dark cells (noise, black backgrounds) from producing wild ratios
    gains = ((cells + 0.02) / (ref + 0.02)).astype(np.float32)
    if present is not None:
        gains[~np.asarray(present, bool)] = 1.0
    return gains


def shading_present(gains: np.ndarray, threshold: float = 0.02) -> bool:
    """Whether the views differ in brightness enough to be worth sending: some view's median
    gain (robust to cells where parallax, not shading, changed the content) is off by more
    than ``threshold`` (relative)."""
    u, v = gains.shape[:2]
    medians = np.median(gains.reshape(u, v, -1), axis=2)
    return bool(np.max(np.abs(np.log2(medians))) > np.log2(1 + threshold))


def quantise_gains(gains: np.ndarray) -> np.ndarray:
    """The int8 values a payload carries: ``round(64 * log2(gain))``, clipped to +-127."""
    return np.clip(np.round(_STEP * np.log2(np.clip(gains, 1e-6, None))), -127, 127).astype(np.int8)


def dequantise_gains(q: np.ndarray) -> np.ndarray:
    return np.exp2(q.astype(np.float32) / _STEP)


#: zstd level of the delta maps (7x7x4x6x3 values a frame, mostly zeros). Measured on the
#: built-in clip (12 frames) and the golden synthetic case: level 19 2.4 ms a frame, 15 0.9
#: ms for the same bytes (the golden case 4 bytes more of 8,336), 9 0.1-0.2 ms but 1.7 % more
#: bytes on the golden case, whose small views make the maps a larger share of a frame.
_ZSTD_LEVEL = 15


def _compress(raw: bytes) -> bytes:
    return zstandard.ZstdCompressor(level=_ZSTD_LEVEL).compress(raw)


def encode_gains(gains: np.ndarray) -> bytes:
    """A full gain-map payload."""
    return _full_payload(quantise_gains(gains))


def _as_image(q: np.ndarray) -> np.ndarray:
    """The int8 values ``(U, V, gh, gw, C)`` as one 2-D level image for the context coder:
    rows ``(u, gy)``, columns ``(v, gx, c)``, so a value's causal neighbours are the next
    cell, channel and view (what predicts it best: 1422 bytes against 1706 with the
    channels as separate planes and 1941 for zstd, on the synthetic scene's 7x7x4x6x3 map)."""
    u, v, gh, gw, ch = q.shape
    return (q.astype(np.int32) + 127).transpose(0, 2, 1, 3, 4).reshape(u * gh, v * gw * ch)


def _full_payload(q: np.ndarray) -> bytes:
    from lfstream.codec._entropy import code_levels

    u, v, gh, gw, ch = q.shape
    return _HEADER.pack(KIND_FULL, gh, gw, ch, u, v) + code_levels(_as_image(q))


class GainReferenceError(BitstreamError):
    """A delta gain map refers to a frame this decoder never received (lost in transport)."""


def _parse(data: bytes, views: tuple[int, int], frame: int | None, refs: dict[int, np.ndarray]) -> np.ndarray:
    """The int8 values ``(U, V, gh, gw, C)`` of a payload (a delta resolved against ``refs``)."""
    if len(data) < _HEADER.size:
        raise BitstreamError("gain maps: truncated", frame)
    kind, gh, gw, ch, u, v = _HEADER.unpack_from(data)
    if kind in OLDER_KINDS:
        raise BitstreamError(f"gain maps: payload kind {kind}, made by an older lfstream; re-encode the stream", frame)
    if kind not in (KIND_FULL, KIND_DELTA) or ch not in (1, 3) or gh < 1 or gw < 1 or (u, v) != tuple(views):
        raise BitstreamError(f"gain maps: bad header (kind {kind}, grid {gh}x{gw}, {ch} channels, views {u}x{v})",
                             frame)
    start = _HEADER.size
    ref = None
    if kind == KIND_DELTA:
        if len(data) < start + _REFERENCE.size:
            raise BitstreamError("gain maps: truncated", frame)
        (ref,) = _REFERENCE.unpack_from(data, start)
        start += _REFERENCE.size
    shape = (u, v, gh, gw, ch)
    n = u * v * gh * gw * ch
    if kind == KIND_FULL:
        from lfstream.codec._entropy import OK, decode_coded_levels

        levels, status = decode_coded_levels(data[start:], (u * gh, v * gw * ch), 255)
        if status != OK:
            raise BitstreamError("gain maps: corrupt or truncated coded map", frame)
        return (levels - 127).astype(np.int8).reshape(u, gh, v, gw, ch).transpose(0, 2, 1, 3, 4).copy()
    try:
        raw = decompress_bounded(data[start:], n)
    except zstandard.ZstdError as exc:
        raise BitstreamError(f"gain maps: corrupt ({exc})", frame) from exc
    if len(raw) != n:
        raise BitstreamError(f"gain maps: {len(raw)} values where {n} were expected", frame)
    base = refs.get(ref)
    if base is None:
        raise GainReferenceError(f"gain maps: delta to frame {ref}, which this decoder has not decoded", frame)
    if base.shape != shape:
        raise BitstreamError(f"gain maps: delta of shape {shape} to a map of shape {base.shape}", frame)
    delta = np.frombuffer(raw, np.uint8).reshape(shape)
    return (base.view(np.uint8) + delta).view(np.int8)  # mod 256, as encoded


def decode_gains(data: bytes, views: tuple[int, int], frame: int | None = None) -> np.ndarray:
    """The gains ``(U, V, gh, gw, C)`` of a full payload (a delta needs a :class:`GainDecoder`)."""
    return dequantise_gains(_parse(data, views, frame, {}))


class GainTracker:
    """The encoder's gain maps of one stream: a full map on the first frame, every
    ``key_interval`` frames, after a gap in the frame numbers, when shading reappears and
    whenever it is smaller than the delta; in between a delta with :data:`GAIN_DEADBAND`
    (see the module docstring)."""

    def __init__(self, key_interval: int = 30, deadband: int = GAIN_DEADBAND) -> None:
        if key_interval < 1 or deadband < 0:
            raise LFValueError(f"gain tracker: key_interval >= 1 and deadband >= 0, got {key_interval}, {deadband}")
        self.key_interval, self.deadband = key_interval, deadband
        self._sent: np.ndarray | None = None
        self._seq = -1
        self._since_key = 0

    def encode(self, gains: np.ndarray | None, seq: int) -> bytes:
        """The payload of frame ``seq`` (``None``: no shading to send, an empty payload)."""
        if gains is None:
            self._sent = None
            return b""
        q = quantise_gains(gains)
        prev = self._sent
        key = (prev is None or prev.shape != q.shape or seq != self._seq + 1
               or self._since_key + 1 >= self.key_interval)
        self._seq = seq
        if key:
            self._sent, self._since_key = q, 0
            return _full_payload(q)
        sent = np.where(np.abs(q.astype(np.int16) - prev) > self.deadband, q, prev)
        u, v, gh, gw, ch = q.shape
        delta = sent.view(np.uint8) - prev.view(np.uint8)  # mod 256
        payload = _HEADER.pack(KIND_DELTA, gh, gw, ch, u, v) + _REFERENCE.pack(seq - 1) + _compress(delta.tobytes())
        full = _full_payload(q)
        if len(full) <= len(payload):
            # content moving through the cells can make the delta the larger (measured on a
            # pan over seahorse: 975 vs 839 B); the full map is then the better key
            self._sent, self._since_key = q, 0
            return full
        self._sent = sent
        self._since_key += 1
        return payload


class GainDecoder:
    """The decoder's gain state: the last frames' maps, for delta payloads (re-decoding a
    frame, as the stream's static-skip audit does, resolves against the same reference)."""

    def __init__(self, keep: int = 4) -> None:
        self._maps: dict[int, np.ndarray] = {}
        self._keep = keep

    def decode(self, data: bytes, views: tuple[int, int], frame: int | None = None) -> np.ndarray:
        """The gains ``(U, V, gh, gw, C)`` of a payload, remembered for the deltas that follow.

        Raises:
            GainReferenceError: a delta to a frame this decoder has not decoded.
        """
        q = _parse(data, views, frame, self._maps)
        if frame is not None:
            self._maps[frame] = q
            for k in sorted(self._maps)[: -self._keep]:
                del self._maps[k]
        return dequantise_gains(q)


def upsample_gain(gain: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """One view's gain map at full resolution, as the decoder applies it (OpenCV's
    INTER_LINEAR resize; the warp kernel's taps are the same).

    Shape:
        - gain: ``(gh, gw, Cg)``; output: ``(H, W, Cg)`` float32
    """
    h, w = size
    return cv2.resize(np.asarray(gain, np.float32), (w, h), interpolation=cv2.INTER_LINEAR).reshape(h, w, -1)


def check_gain_maps(gains: np.ndarray, views: tuple[int, int], channels: int) -> np.ndarray:
    """Per-view gain maps ``(U, V, gh, gw, 1 or C)`` for ``views`` ``(U, V)`` of ``channels``
    channels, as C-contiguous float32 (the warp's and :func:`apply_gains`'s one check).

    Raises:
        LFShapeError: maps that do not match the views, or without a cell.
    """
    u, v = views
    gains = np.ascontiguousarray(gains, np.float32)
    if gains.ndim != 5 or gains.shape[:2] != (u, v) or gains.shape[4] not in (1, channels) \
            or min(gains.shape[2:4]) < 1:
        raise LFShapeError(f"gains: expected ({u}, {v}, gh, gw, 1 or {channels}), got {gains.shape}")
    return gains


def resize_taps(n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's INTER_LINEAR taps for resizing ``n_in`` float samples to ``n_out``, computed
    as OpenCV computes them (the source position in float32 from a double expression, the
    weights ``1 - f`` and ``f`` in float32, clamped at the ends): per output sample the two
    input indices ``(n_out, 2)`` int64 and their weights ``(n_out, 2)`` float32. The warp
    kernel's gains use :func:`lfstream.codec.warp.cpu._linear_taps` instead, the same taps with
    the weights computed in float64: they differ from these in the last bit for most sizes
    (375 of 4 cells: 181 of 375), and the hint path's decoded bytes follow those."""
    scale = 1.0 / (n_out / n_in)  # OpenCV's scale_x = 1 / inv_scale_x
    f = ((np.arange(n_out, dtype=np.float64) + 0.5) * scale - 0.5).astype(np.float32)
    i0 = np.floor(f).astype(np.int64)
    frac = (f - i0.astype(np.float32)).astype(np.float32)
    low, high = i0 < 0, i0 >= n_in - 1
    frac[low | high] = 0.0
    i0[low] = 0
    i0[high] = n_in - 1
    taps = np.stack([i0, np.minimum(i0 + 1, n_in - 1)], axis=1)
    weights = np.stack([np.float32(1.0) - frac, frac], axis=1).astype(np.float32)
    return taps, weights


def apply_gains(lf: np.ndarray, gains: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Multiplies each uint8 view ``(U, V, H, W, C)`` by its gain map ``(U, V, gh, gw, 1 or
    C)`` bilinearly up-sampled, into ``out`` (a new array where ``None``): OpenCV's arithmetic
    for ``cv2.multiply(view, upsample_gain(gain), dtype=CV_8U)`` (INTER_LINEAR's taps and
    float32 passes, the product rounded half to even), done in one parallel kernel
    and so the same on every CPU, where OpenCV's own resize runs IPP's
    CPU-specific code (within one level of it, on 0.01-0.03 % of samples here). ``lf`` may
    be a broadcast of one view (the flat decode), which is then read as one.

    Raises:
        LFShapeError: gains that do not match the views.
    """
    from lfstream.codec.gains_kernels import apply_view_gains

    u, v, h, w, c = lf.shape
    gains = check_gain_maps(gains, (u, v), c)
    out = np.empty((u, v, h, w, c), np.uint8) if out is None else out
    if lf.strides[0] == 0 and lf.strides[1] == 0:  # one view for all
        views = np.ascontiguousarray(lf[0, 0]).reshape(1, h, w * c)
        which = np.zeros(u * v, np.int64)
    else:
        views = np.ascontiguousarray(lf).reshape(u * v, h, w * c)
        which = np.arange(u * v, dtype=np.int64)
    active = ~np.all(np.abs(gains - 1.0) < 1e-6, axis=(2, 3, 4)).reshape(-1)
    rows, row_w = resize_taps(h, gains.shape[2])
    cols, col_w = resize_taps(w, gains.shape[3])
    target = out if out.flags.c_contiguous else np.empty((u, v, h, w, c), np.uint8)  # the kernel writes rows
    apply_view_gains(views, which, gains, active, rows, row_w, cols, col_w, target.reshape(u, v, h, w * c))
    if target is not out:
        out[...] = target
    return out


__all__ = ["GAIN_DEADBAND", "GainDecoder", "GainReferenceError", "GainTracker", "shading_present", "measure_gains",
           "quantise_gains", "dequantise_gains", "encode_gains", "decode_gains", "upsample_gain", "check_gain_maps",
           "resize_taps", "apply_gains"]
