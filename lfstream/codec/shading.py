"""Per-view brightness: vignetting and colour shading sent as tiny gain maps.

Real plenoptic captures darken towards the corner views (the main lens's mechanical
vignetting) and shade colours differently per view; a warp of the centre view copies the
centre's brightness into every view and misses that entirely. The encoder, which has
every view, measures each view's low-frequency gain against the centre view on a coarse
grid (``grid x grid`` cells per view, per colour channel), and sends it as 8-bit
log2-gains, zstd-compressed; the decoder multiplies each warped view by the upsampled gain.
Cells this coarse are insensitive to parallax, so the gain captures shading, not content.

Payload: ``u8 version, u8 grid_h, u8 grid_w, u8 channels, u8 U, u8 V`` + zstd(int8 values
``round(64 * log2(gain))``, shape ``(U, V, grid_h, grid_w, channels)``).
"""

from __future__ import annotations

import struct

import cv2
import numpy as np
import zstandard

from lfstream.codec.bitstream import decompress_bounded
from lfstream.errors import BitstreamError, LFValueError

_HEADER = struct.Struct("<BBBBBB")
VERSION = 1
_STEP = 64.0  # int8 units per octave: gains within 2**(+-127/64) ~ [0.25, 3.96], 1.1 % steps


def measure_gains(lf: np.ndarray, grid: int = 4, channels: int = 3, present: np.ndarray | None = None) -> np.ndarray:
    """Gains ``(U, V, gh, gw, channels)`` of each view against the centre view, cell by cell;
    views marked absent in ``present`` get gain 1."""
    if grid < 1 or channels not in (1, 3):
        raise LFValueError(f"gain grid >= 1 and channels 1 or 3, got {grid}, {channels}")
    x = np.asarray(lf)
    u, v, h, w, c = x.shape
    # cells this coarse need no full-resolution pass: about 8 x 8 samples per cell are
    # plenty (shading is smooth) and keep the encoder's cost near a millisecond
    step = max(1, min(h, w) // (8 * grid))
    sub = x[:, :, ::step, ::step]
    gh = max(1, min(grid, sub.shape[2]))
    gw = max(1, min(int(round(grid * w / max(h, 1))), sub.shape[3]))
    scale = np.float32(1 / 255.0) if x.dtype == np.uint8 else np.float32(1.0)
    cells = np.empty((u, v, gh, gw, c), np.float32)
    for a in range(u):
        for b in range(v):
            view = sub[a, b].astype(np.float32) * scale
            cells[a, b] = cv2.resize(view, (gw, gh), interpolation=cv2.INTER_AREA).reshape(gh, gw, c)
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


def encode_gains(gains: np.ndarray) -> bytes:
    u, v, gh, gw, ch = gains.shape
    q = np.clip(np.round(_STEP * np.log2(np.clip(gains, 1e-6, None))), -127, 127).astype(np.int8)
    return _HEADER.pack(VERSION, gh, gw, ch, u, v) + zstandard.ZstdCompressor(level=19).compress(q.tobytes())


def decode_gains(data: bytes, views: tuple[int, int], frame: int | None = None) -> np.ndarray:
    if len(data) < _HEADER.size:
        raise BitstreamError("gain maps: truncated", frame)
    version, gh, gw, ch, u, v = _HEADER.unpack_from(data)
    if version != VERSION or ch not in (1, 3) or gh < 1 or gw < 1 or (u, v) != tuple(views):
        raise BitstreamError(f"gain maps: bad header (version {version}, grid {gh}x{gw}, {ch} channels, views {u}x{v})",
                             frame)
    n = u * v * gh * gw * ch
    try:
        raw = decompress_bounded(data[_HEADER.size :], n)
    except zstandard.ZstdError as exc:
        raise BitstreamError(f"gain maps: corrupt ({exc})", frame) from exc
    if len(raw) != n:
        raise BitstreamError(f"gain maps: {len(raw)} values where {n} were expected", frame)
    q = np.frombuffer(raw, np.int8).reshape(u, v, gh, gw, ch).astype(np.float32)
    return np.exp2(q / _STEP)


def apply_gains(lf: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """Multiplies each uint8 view ``(U, V, H, W, 3)`` by its upsampled gain map (a new array)."""
    u, v, h, w, c = lf.shape
    out = np.empty_like(lf)
    for a in range(u):
        for b in range(v):
            g = gains[a, b]
            if np.all(np.abs(g - 1.0) < 1e-6):
                out[a, b] = lf[a, b]
                continue
            full = cv2.resize(g, (w, h), interpolation=cv2.INTER_LINEAR).reshape(h, w, -1)
            if full.shape[-1] != c:
                full = np.repeat(full, c, axis=-1)
            # one saturating SIMD pass: uint8 x float32 -> uint8
            cv2.multiply(lf[a, b], full, dst=out[a, b], dtype=cv2.CV_8U)
    return out


__all__ = ["shading_present", "measure_gains", "encode_gains", "decode_gains", "apply_gains"]
