"""The encoder's hint from frame to frame (:class:`HintTracker`): key hints every
``key_interval`` frames or where the scene's range moves, deltas between, repeats where
nothing changed."""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import replace

import numpy as np
import zstandard

from lfstream.codec.hint.grids import HintMap
from lfstream.codec.hint.options import _ZSTD_LEVEL, KIND_DELTA, KIND_REPEAT, HintOptions
from lfstream.codec.hint.payload import QuantisedHint, _pack, key_payload, quantise
from lfstream.codec.hint.sweep import estimate_hint_map
from lfstream.errors import LFValueError


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
        from lfstream.codec.workers import completed, in_background, on_worker_thread

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
