"""One stream's encoder, frame by frame: the one object behind ``lfstream.encode``,
``lfstream encode``, the stream's encoder stage and the cluster's jobs.

It owns what a stream carries from frame to frame: the configuration chosen on the first
frame (rate control for a ``bpp`` target, :func:`lfstream.codec.rate.choose_rate`; the
default's choice, :func:`lfstream.codec.rate.choose_default`; or the preset named), the
:class:`~lfstream.codec.encoder.Encoder` with its hint and gain trackers and key frames, and,
under a target, the budget the later frames follow (:class:`lfstream.codec.rate.RateFollower`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, StreamWriter, with_present
from lfstream.codec.encoder import DEFAULT_PRESET, Encoder, EncodeStats
from lfstream.codec.hint import HintOptions
from lfstream.codec.rate import (
    RateChoice,
    RateFollower,
    choose_default,
    choose_rate,
    family_of,
    uses_default_choice,
)
from lfstream.errors import LFValueError
from lfstream.io._fs import atomic_open
from lfstream.lightfield import check_lf


@dataclass(frozen=True)
class CodingOptions:
    """What a stream is asked to be (every front end's one set of coding options).

    Attributes:
        quality: the centre view's quality, 1..100 (ignored with ``bpp``).
        bpp: a target size in bits per pixel: rate control chooses the rest on the first frame.
        preset: the centre view's coding (:data:`lfstream.codec.encoder.PRESETS`); ``None``:
            the default's choice (or, with ``bpp``, rate control's).
        depth_hint: send the depth hint.
        residual, residual_mode: the residual layer (:mod:`lfstream.codec.residual`).
        post_filter: name the decoder's JPEG post-filter the encoder measured best.
        hance_map: send JPEG-Hance strength maps with JPEG centre views.
        device: where the hint's plane sweep runs.
        hint_options: the hint's sweep and coding (``None``: the defaults).
        gain_grid: cells per axis of the per-view gain maps.
        search: rate control's search (:data:`lfstream.codec.rate.SEARCHES`; ``None``: its default).
        views_hint: send the hint even where the views are coded themselves (a stream's
            focal planes are fitted to the decoded disparity).
    """

    quality: int = 50
    bpp: float | None = None
    preset: str | None = None
    depth_hint: bool = True
    residual: int | None = None
    residual_mode: str = "prediction"
    post_filter: bool = True
    hance_map: bool = False
    device: str = "cpu"
    hint_options: HintOptions | None = None
    gain_grid: int = 4
    search: str | None = None
    views_hint: bool = False


def with_default_hance_map(encoder: Encoder, first: Packet | None, frame: np.ndarray,
                           present: np.ndarray | None = None) -> Packet | None:
    """The default encode (:func:`lfstream.codec.rate.choose_default`) with JPEG-Hance strength
    maps: where its ``encoder`` codes a JPEG centre view, it sends them from frame 0 on
    (``first``, the packet the choice coded, is marked; it is final: any coarser hint is in
    it); where the choice codes the views themselves (AV1), nothing changes."""
    if not encoder.takes_hance_map:
        return first
    encoder.hance_map = True
    return first if first is None else encoder.mark_hance(first, frame, present)


class StreamEncoder:
    """Encodes one stream frame by frame (see the module docstring).

    Args:
        options: the coding asked for.
        fps: the stream's frame rate (timestamps are ``t / fps``).
        present: ``(U, V)`` mask of the views the source has (recorded in the header).
        start: the index of the first frame given (its packet's ``seq`` and timestamp): a
            group of a longer video coded apart, from a key frame.

    Attributes:
        encoder: the :class:`~lfstream.codec.encoder.Encoder` (set by the first frame).
        header: the stream's header (set by the first frame).
        rate: rate control's choice on the first frame (:class:`lfstream.codec.rate.RateChoice`), or ``None``.
        prediction_db: the default's check of its own prediction, or ``None``.
        frames: frames encoded so far.
    """

    def __init__(self, options: CodingOptions = CodingOptions(), fps: float = 30.0,
                 present: np.ndarray | None = None, start: int = 0) -> None:
        self.options = options
        self.fps = float(fps)
        self.present = present
        self.encoder: Encoder | None = None
        self.header: StreamHeader | None = None
        self.rate: RateChoice | None = None
        self.prediction_db: float | None = None
        self.frames = 0
        self.start = int(start)
        self._follower: RateFollower | None = None

    def encode_frame(self, frame: np.ndarray) -> Packet:
        """The next frame's packet.

        Shape:
            - frame: ``(U, V, H, W, 3)``
        """
        t = self.start + self.frames
        ts = int(round(t * 1e6 / self.fps))
        if self.frames == 0:
            packet = self._first(frame, t, ts)
        elif self._follower is not None:
            packet = self._follower.encode_frame(frame, t, ts, self.present)
        else:
            packet = self.encoder.encode_frame(frame, t, ts, self.present)
        self.frames += 1
        return packet

    def _first(self, frame: np.ndarray, t: int, ts: int) -> Packet:
        o = self.options
        views, size = tuple(frame.shape[:2]), tuple(frame.shape[2:4])
        if o.bpp is not None:
            if t:
                raise LFValueError("bpp: rate control starts a stream at its first frame (start=0)")
            self.rate = choose_rate(frame[None], o.bpp, self.fps, self.present, o.hint_options, o.gain_grid,
                                    preset=o.preset, views_hint=o.views_hint, search=o.search)
            self._follower = self.rate.follower or self._primed_follower(frame, ts)
            self.encoder = self._follower.encoder
            self.header = with_present(self.rate.header, self.present)
            return self.rate.packets[0]
        if uses_default_choice(o.preset, o.depth_hint, o.residual, o.residual_mode):
            if t:
                raise LFValueError("the default's choice is made on a stream's first frame: fix it first "
                                   "(StreamEncoder.fixed_options) for a group that starts later")
            check_lf(frame, allow_video=False)
            choice = choose_default(frame, o.quality, self.present, o.hint_options, o.gain_grid,
                                    views_hint=o.views_hint, post_filter=o.post_filter, device=o.device)
            self.encoder, first = choice.encoder, choice.first
            self.prediction_db = choice.prediction_db
            if o.hance_map:
                first = with_default_hance_map(self.encoder, first, frame, self.present)
        else:
            self.encoder, first = self.named_encoder(), None
        self.header = with_present(self.encoder.header(views, size, self.fps), self.present)
        return first if first is not None else self.encoder.encode_frame(frame, t, ts, self.present)

    def fixed_options(self, frame: np.ndarray) -> CodingOptions:
        """The options with the first frame's choice made (preset, hint, residual layer,
        strength maps), so that groups of a video coded apart (:attr:`start`) code as this
        stream would: the default's choice on ``frame``; the options as they are where they
        name the coding."""
        from dataclasses import replace

        o = self.options
        if o.bpp is not None:
            raise LFValueError("bpp: rate control follows a budget over the whole stream; it is not fixed per group")
        if o.preset is not None:
            return o
        if not uses_default_choice(None, o.depth_hint, o.residual, o.residual_mode):
            return replace(o, preset=DEFAULT_PRESET)
        enc = choose_default(frame, o.quality, self.present, o.hint_options, o.gain_grid, views_hint=o.views_hint,
                             post_filter=o.post_filter, device=o.device).encoder
        return replace(o, preset=enc.preset, depth_hint=enc.depth_hint, residual=enc.residual,
                       residual_mode=enc.residual_mode, hint_options=enc.hint_options,
                       hance_map=o.hance_map and enc.takes_hance_map)

    def named_encoder(self) -> Encoder:
        """An :class:`~lfstream.codec.encoder.Encoder` with the options as given (no choice)."""
        o = self.options
        return Encoder(quality=o.quality, depth_hint=o.depth_hint, hint_options=o.hint_options or HintOptions(),
                       gain_grid=o.gain_grid, preset=o.preset or DEFAULT_PRESET, residual=o.residual,
                       residual_mode=o.residual_mode, post_filter=o.post_filter, device=o.device,
                       hance_map=o.hance_map)

    def _primed_follower(self, frame: np.ndarray, ts: int) -> RateFollower:
        """The follower of a search's choice, which keeps no encoder: a fresh one in the
        chosen configuration codes frame 0 once, unsent, so that its hint and gain trackers
        continue from the frame the decoder has (the same hint and gains: both are
        deterministic)."""
        r = self.rate
        enc = Encoder(quality=r.quality, depth_hint=r.depth_hint, hint_options=r.hint_options,
                      gain_grid=self.options.gain_grid, preset=r.preset, residual=r.residual,
                      residual_mode=r.residual_mode)
        enc.encode_frame(frame, 0, ts, self.present)
        return RateFollower.after(enc, family_of(r.residual, r.residual_mode), r.header, r.packets[0],
                                  self.options.bpp, int(np.prod(frame.shape[:4])))

    def coding(self) -> dict:
        """What the stream's encoder codes (before the first frame: what the options name):
        preset, quality, hint (and its resolution divisor, ``hint_scale``), residual layer,
        strength maps, and the default's check of its prediction (``prediction_db``, dB)."""
        enc = self.encoder if self.encoder is not None else self.named_encoder()
        db = self.prediction_db
        return {"preset": enc.preset, "quality": int(enc.quality), "depth_hint": bool(enc.depth_hint),
                "hint_scale": int(enc.hint_options.hint_scale) if enc.depth_hint else None,
                "residual": enc.residual, "residual_mode": enc.residual_mode if enc.residual is not None else None,
                "hance_map": bool(enc.hance_map), "prediction_db": None if db is None else round(float(db), 3)}


def encode_file(frames: Iterable[np.ndarray], path: str | os.PathLike, stream: StreamEncoder) -> EncodeStats:
    """Encodes frames into an ``.lfs`` file through ``stream``, written atomically; returns byte
    counts and the encoding time. Where no frame comes (a run stopped before its first),
    nothing is written and the counts are zero."""
    stats = EncodeStats()
    it = iter(frames)
    first = next(it, None)
    if first is None:
        return stats
    t0 = time.perf_counter()
    packet = stream.encode_frame(first)
    stats.encode_s += time.perf_counter() - t0
    with atomic_open(Path(path)) as fh:
        writer = StreamWriter(fh, stream.header)
        writer.write(packet)
        stats.add(packet, 0.0)
        for frame in it:
            t0 = time.perf_counter()
            packet = stream.encode_frame(frame)
            stats.encode_s += time.perf_counter() - t0
            writer.write(packet)
            stats.add(packet, 0.0)
        stats.bytes = writer.bytes_written
    return stats


__all__ = ["CodingOptions", "StreamEncoder", "encode_file", "with_default_hance_map"]
