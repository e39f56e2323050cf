"""Rate control: the configuration that gives the best measured quality at a target size.

The encoder's knobs are the preset (the centre view's codec: JPEG or AV1), its quality and
whether the depth hint is sent. The hint and the gain maps do not depend on the centre
view's coding, so they are computed once per frame; the size at every quality then costs
one centre-view encode per frame, and a bisection finds, for every preset with the hint and
without it, the quality whose stream is closest to the target. The candidates are decoded
on the first frame and the one with the higher MPSNR (over the views that exist) wins: the
encoder has the whole light field, so it can measure instead of guess.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, pack_header, pack_packet
from lfstream.codec.hint import HintOptions
from lfstream.codec.intra import CentreCoding, encode_centre
from lfstream.codec.jpeg import QUALITY_RANGE
from lfstream.errors import LFValueError
from lfstream.lightfield import centre_view, to_uint8

#: How far from the target a chosen configuration may land (relative), when it can.
RATE_TOLERANCE = 0.15
#: The second hint precision rate control tries (the default sends 1/4 resolution): at low
#: rates a 1/8 map costs a third of the bytes for 0.1-0.3 dB (measured on the shared samples).
COARSE_HINT_SCALE = 8


@dataclass(frozen=True)
class RateChoice:
    """The configuration rate control picked, what it measured, and its stream (header and
    packets, the same bytes an encoder with this preset, quality and hint setting writes)."""

    quality: int
    depth_hint: bool
    bpp: float
    mpsnr_first_frame: float
    candidates: tuple[dict, ...]
    header: StreamHeader
    packets: tuple[Packet, ...]
    preset: str = "fast"
    hint_options: HintOptions = HintOptions()  # the chosen hint's options (the default without a hint)

    def stream(self) -> bytes:
        """The chosen ``.lfs`` stream."""
        return pack_header(self.header) + b"".join(pack_packet(p) for p in self.packets)


def _at_quality(header: StreamHeader, packets: list[Packet], quality: int, images: list[bytes],
                coding: CentreCoding) -> tuple[StreamHeader, list[Packet]]:
    """The stream at another quality: the header records it, each packet carries its centre
    view coded at it; hints and gains do not depend on it."""
    meta = {**header.meta, "quality": quality}
    if "centre" in meta:
        meta["centre"] = coding.as_meta(quality)
    at_q = replace(header, quality=quality, meta=meta)
    return at_q, [replace(p, image=img) for p, img in zip(packets, images)]


def _best_quality(frames: np.ndarray, packets: list[Packet], header: StreamHeader, target_bytes: float,
                  coding: CentreCoding) -> tuple[int, int, list[bytes]]:
    """The quality whose stream is closest to ``target_bytes`` (bisection; sizes grow with
    quality), that stream's size and its centre-view payloads."""
    centres = [centre_view(to_uint8(f)) for f in frames]
    cache: dict[int, tuple[int, list[bytes]]] = {}

    def size(q: int) -> int:
        if q not in cache:
            images = [encode_centre(c, q, coding) for c in centres]
            at_q, moved = _at_quality(header, packets, q, images, coding)
            cache[q] = (len(pack_header(at_q)) + sum(p.nbytes for p in moved), images)
        return cache[q][0]

    lo, hi = QUALITY_RANGE
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if size(mid) <= target_bytes:
            lo = mid
        else:
            hi = mid
    q = min((lo, hi), key=lambda k: abs(size(k) - target_bytes))
    return q, size(q), cache[q][1]


def choose_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None = None,
                         hint_options: HintOptions | None = None, gain_grid: int = 4,
                         preset: str | None = None) -> RateChoice:
    """The (preset, quality, depth hint, hint precision) whose stream lands nearest
    ``target_bpp`` with the best first-frame MPSNR (see the module docstring). ``preset``:
    the only preset to consider; ``None`` considers every preset. ``hint_options``: the only
    hint options to consider; ``None`` tries the default and a 1/8-resolution hint.

    Shape:
        - frames: ``(T, U, V, H, W, 3)``
    """
    from lfstream.codec.decoder import decode
    from lfstream.codec.encoder import PRESETS, Encoder, preset_coding
    from lfstream.metrics import bpp, mpsnr

    if not (np.isfinite(target_bpp) and target_bpp > 0):
        raise LFValueError(f"bpp: a positive target in bits per pixel, got {target_bpp!r}")
    if preset is not None:
        preset_coding(preset)  # an unknown name fails before any encoding
    presets = tuple(PRESETS) if preset is None else (preset,)
    pixels = int(np.prod(frames.shape[:5]))
    target_bytes = target_bpp * pixels / 8.0
    candidates = []
    hints = [hint_options] if hint_options is not None else [HintOptions(), HintOptions(hint_scale=COARSE_HINT_SCALE)]
    for hint, opts in [(True, h) for h in hints] + [(False, HintOptions())]:
        # hints and gains do not depend on the preset: one encode per frame, the centre
        # view recoded per preset and quality
        enc = Encoder(quality=50, depth_hint=hint, hint_options=opts, gain_grid=gain_grid)
        packets = [enc.encode_frame(f, t, int(round(t * 1e6 / fps)), present) for t, f in enumerate(frames)]
        for name in presets:
            enc_p = Encoder(quality=50, depth_hint=hint, hint_options=opts, gain_grid=gain_grid, preset=name)
            header = enc_p.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
            q, n, images = _best_quality(frames, packets, header, target_bytes, enc_p.coding)
            at_q, moved = _at_quality(header, packets, q, images, enc_p.coding)
            first = pack_header(at_q) + pack_packet(moved[0])  # the first frame is a key frame: it decodes alone
            score = float(np.minimum(mpsnr(frames[0], decode(first)[0], present=present), 100.0))
            candidates.append({"preset": name, "quality": q, "depth_hint": hint,
                               "hint_scale": opts.hint_scale if hint else None, "bpp": bpp(n, frames.shape),
                               "mpsnr_first_frame": score, "_stream": (at_q, tuple(moved), opts)})
    # within the tolerance where possible, then the better measured quality
    def rank(c: dict) -> tuple:
        off = abs(c["bpp"] - target_bpp) / target_bpp
        return (off > RATE_TOLERANCE, -c["mpsnr_first_frame"] if off <= RATE_TOLERANCE else off)

    best = min(candidates, key=rank)
    header_q, packets_q, opts_q = best["_stream"]
    report = tuple({k: v for k, v in c.items() if k != "_stream"} for c in candidates)
    return RateChoice(best["quality"], best["depth_hint"], best["bpp"], best["mpsnr_first_frame"], report, header_q,
                      packets_q, best["preset"], opts_q)


__all__ = ["RATE_TOLERANCE", "COARSE_HINT_SCALE", "RateChoice", "choose_configuration"]
