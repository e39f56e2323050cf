"""The hint's payload: quantisation to levels (:func:`quantise`), the coded body (context-coded
levels or zstd), the key payload and its parsing, and the decoder's up-sampling of a
decoded map to the view (:class:`HintDecoder`, :func:`decode_hint`)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import zstandard

from lfstream.codec.bitstream import decompress_bounded
from lfstream.codec.hint.grids import HintMap, _upsample
from lfstream.codec.hint.options import (
    _AXES,
    _HEADER,
    CODER_CONTEXT,
    CODER_ZSTD,
    HINT_FORMAT,
    KIND_AXES,
    KIND_DELTA,
    KIND_FULL,
    KIND_REPEAT,
    MAX_AXIS_ENTRY,
    OLDER_HINT_FORMATS,
    HintOptions,
    HintReferenceError,
    is_standard,
)
from lfstream.errors import BitstreamError, LFShapeError
from lfstream.lightfield import to_uint8


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
    if qh.axes is None:  # the convention: no axes in the payload
        return _HEADER.pack(HINT_FORMAT, kind, qh.scale, coder, qh.lo, qh.hi, hs, ws, ref) + body
    return (_HEADER.pack(HINT_FORMAT, kind | KIND_AXES, qh.scale, coder, qh.lo, qh.hi, hs, ws, ref)
            + _AXES.pack(*np.asarray(qh.axes, np.float32).ravel().tolist()) + body)


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
    if version in OLDER_HINT_FORMATS:
        raise BitstreamError(f"depth hint: payload format {version}, made by an older lfstream; re-encode the "
                             "stream", frame)
    if version != HINT_FORMAT:
        raise BitstreamError(f"depth hint: unknown payload format {version}", frame)
    if len(data) < _HEADER.size:
        raise BitstreamError("depth hint: truncated", frame)
    _, kind, scale, coder, lo, hi, hs, ws, ref = _HEADER.unpack_from(data)
    with_axes = bool(kind & KIND_AXES)
    kind &= ~KIND_AXES
    head = _HEADER.size + (_AXES.size if with_axes else 0)
    if len(data) < head:
        raise BitstreamError("depth hint: truncated", frame)
    body = data[head:]
    if kind not in (KIND_FULL, KIND_DELTA, KIND_REPEAT) or scale < 1:
        raise BitstreamError(f"depth hint: unknown kind {kind} or scale {scale}", frame)
    # a full map is context coded; a delta (and a repeat, which has no body) is zstd
    if coder != (CODER_CONTEXT if kind == KIND_FULL else CODER_ZSTD):
        raise BitstreamError(f"depth hint: unknown coder {coder} for a kind {kind} map", frame)
    if with_axes:
        axes = np.asarray(_AXES.unpack_from(data, _HEADER.size), np.float32).reshape(2, 2)
        if not (np.all(np.isfinite(axes)) and np.abs(axes).max() <= MAX_AXIS_ENTRY):
            raise BitstreamError(f"depth hint: bad view axes {axes.ravel().tolist()}", frame)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi and abs(lo) < 1e4 and abs(hi) < 1e4):
        raise BitstreamError(f"depth hint: bad range {lo}..{hi}", frame)
    if not (1 <= hs <= h and 1 <= ws <= w):
        raise BitstreamError(f"depth hint: map size {hs}x{ws} does not fit the view size {h}x{w}", frame)
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
    q = (base.q.astype(np.int16) + q).astype(np.uint8)
    return QuantisedHint(q.copy(), float(lo), float(hi), int(scale), axes)


# range weights of the joint bilateral upsampling, by absolute 8-bit grey difference
_RANGE_SIGMA = 50.0


_RANGE_LUT = np.exp(-(np.arange(256, dtype=np.float32) ** 2) / (2 * _RANGE_SIGMA**2)).astype(np.float32)


def _expand(qh: QuantisedHint, size: tuple[int, int], guide: np.ndarray | None) -> np.ndarray:
    small = qh.values()
    if guide is None:
        full = _upsample(small, qh.scale, size)
    else:
        from lfstream.codec.hint.kernels import joint_upsample

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
