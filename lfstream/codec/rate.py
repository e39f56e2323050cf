"""Rate control: the configuration that gives the best measured quality at a target size.

The encoder's knobs are the centre view's JPEG quality and whether the depth hint is sent.
The hint and the gain maps do not depend on the JPEG quality, so they are computed once
per frame; the size at every quality then costs one JPEG encode per frame, and a bisection
finds, with the hint and without it, the quality whose stream is closest to the target.
The two candidates are decoded on the first frame and the one with the higher MPSNR (over
the views that exist) wins: the encoder has the whole light field, so it can measure
instead of guess.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, pack_header
from lfstream.codec.jpeg import QUALITY_RANGE, encode_jpeg
from lfstream.errors import LFValueError
from lfstream.lightfield import centre_view, to_uint8

#: How far from the target a chosen configuration may land (relative), when it can.
RATE_TOLERANCE = 0.15


@dataclass(frozen=True)
class RateChoice:
    """The configuration rate control picked, and what it measured."""

    quality: int
    depth_hint: bool
    bpp: float
    mpsnr_first_frame: float
    candidates: tuple[dict, ...]


def _stream_bytes(header: StreamHeader, quality: int, packets: list[Packet], jpeg_sizes: list[int]) -> int:
    # the header at this quality (it records it), every packet less its JPEG plus the JPEG at it
    at_q = replace(header, quality=quality, meta={**header.meta, "quality": quality})
    return len(pack_header(at_q)) + sum(p.nbytes - len(p.image) + n for p, n in zip(packets, jpeg_sizes))


def _best_quality(frames: np.ndarray, packets: list[Packet], header: StreamHeader, target_bytes: float) -> tuple[int, int]:
    """The JPEG quality whose stream is closest to ``target_bytes`` (bisection; sizes grow
    with quality), and that stream's size."""
    centres = [centre_view(to_uint8(f)) for f in frames]
    cache: dict[int, int] = {}

    def size(q: int) -> int:
        if q not in cache:
            cache[q] = _stream_bytes(header, q, packets, [len(encode_jpeg(c, q)) for c in centres])
        return cache[q]

    lo, hi = QUALITY_RANGE
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if size(mid) <= target_bytes:
            lo = mid
        else:
            hi = mid
    q = min((lo, hi), key=lambda k: abs(size(k) - target_bytes))
    return q, size(q)


def choose_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None = None,
                         hint_options=None, gain_grid: int = 4) -> RateChoice:
    """The (JPEG quality, depth hint) whose stream lands nearest ``target_bpp`` with the best
    first-frame MPSNR (see the module docstring).

    Shape:
        - frames: ``(T, U, V, H, W, 3)``
    """
    from lfstream.codec.decoder import decode
    from lfstream.codec.encoder import Encoder, encode
    from lfstream.codec.hint import HintOptions
    from lfstream.metrics import bpp, mpsnr

    if not (np.isfinite(target_bpp) and target_bpp > 0):
        raise LFValueError(f"bpp: a positive target in bits per pixel, got {target_bpp!r}")
    pixels = int(np.prod(frames.shape[:5]))
    target_bytes = target_bpp * pixels / 8.0
    candidates = []
    for hint in (True, False):
        enc = Encoder(quality=50, depth_hint=hint, hint_options=hint_options or HintOptions(), gain_grid=gain_grid)
        header = enc.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
        packets = [enc.encode_frame(f, t, int(round(t * 1e6 / fps)), present) for t, f in enumerate(frames)]
        q, n = _best_quality(frames, packets, header, target_bytes)
        first = encode(frames[:1], quality=q, depth_hint=hint, fps=fps, hint_options=hint_options, gain_grid=gain_grid,
                       present=present)
        score = float(np.minimum(mpsnr(frames[0], decode(first)[0], present=present), 100.0))
        candidates.append({"quality": q, "depth_hint": hint, "bpp": bpp(n, frames.shape), "mpsnr_first_frame": score})
    # within the tolerance where possible, then the better measured quality
    def rank(c: dict) -> tuple:
        off = abs(c["bpp"] - target_bpp) / target_bpp
        return (off > RATE_TOLERANCE, -c["mpsnr_first_frame"] if off <= RATE_TOLERANCE else off)

    best = min(candidates, key=rank)
    return RateChoice(best["quality"], best["depth_hint"], best["bpp"], best["mpsnr_first_frame"], tuple(candidates))


__all__ = ["RATE_TOLERANCE", "RateChoice", "choose_configuration"]
