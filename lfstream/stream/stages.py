"""The stages of a stream, one thread each, joined by bounded queues.

Each stage owns its state and its statistics (:mod:`lfstream.stream.report`); nothing is
written by two threads. Consuming stages share one loop (:class:`ConsumerStage`): take an
item until the end marker or a stop, time the work, forward the result, turn any
exception into a :class:`PipelineError` naming the stage and frame, and always close.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np

from lfstream.codec.bitstream import Packet
from lfstream.codec.decoder import DecodedFrame, Decoder
from lfstream.codec.stream_encoder import CodingOptions, StreamEncoder
from lfstream.errors import LFStreamError, LFValueError
from lfstream.lightfield import canonical_views
from lfstream.stream.config import StreamConfig
from lfstream.stream.frames import SourceFrame, StackFrame
from lfstream.stream.refocuser import Refocuser
from lfstream.stream.report import QualityStats, RateStats, StageStats, StaticSkipStats
from lfstream.stream.sinks import Sink
from lfstream.stream.transport import Receiver, Sender, StoppedError, get_until_stopped, put_until_stopped

_POLL_S = 0.1


class PipelineError(LFStreamError):
    """A stage failed; ``stage`` and ``frame`` say where."""

    def __init__(self, message: str, stage: str, frame: int | None) -> None:
        super().__init__(message)
        self.stage = stage
        self.frame = frame


class RunControl:
    """What the stages of one run share: the stop event and the first error."""

    def __init__(self) -> None:
        self.stop_event = threading.Event()
        self.error: PipelineError | None = None
        # the input's damage after its first frames: the stream ends there, the frames before
        # it go through every stage and the outputs are finalised, then the run reports it
        self.input_error: LFStreamError | None = None
        self._lock = threading.Lock()

    def fail(self, stage: str, frame: int | None, exc: BaseException) -> None:
        """Records the first failure (later ones are consequences) and stops every stage. A
        receiver whose wait ended because the run was stopped did not fail (a Ctrl-C
        before the stream header arrived was reported as "stage transport failed", exit 2,
        and no summary)."""
        if isinstance(exc, StoppedError) and self.stop_event.is_set():
            return
        with self._lock:
            if self.error is None:
                where = f" at frame {frame}" if frame is not None else ""
                self.error = PipelineError(f"stage {stage} failed{where}: {exc}", stage, frame)
                self.error.__cause__ = exc
        self.stop_event.set()

    def put(self, q: queue.Queue, item: Any) -> bool:
        return put_until_stopped(q, item, self.stop_event)

    def get(self, q: queue.Queue) -> Any:
        """The next item, or ``None`` at the end of the stream or on stop."""
        return get_until_stopped(q, self.stop_event)

    def put_end(self, q: queue.Queue) -> None:
        """The end marker (``None``) must get through even when the consumer is slow or gone."""
        while True:
            try:
                q.put(None, timeout=_POLL_S)
                return
            except queue.Full:
                if self.stop_event.is_set():
                    try:
                        q.get_nowait()
                    except queue.Empty:
                        pass


class OriginalFrames:
    """Input frames kept for the metrics stage (producer writes, metrics reads; locked)."""

    def __init__(self) -> None:
        self._frames: dict[int, np.ndarray] = {}
        self._lock = threading.Lock()

    def keep(self, seq: int, lf: np.ndarray) -> None:
        with self._lock:
            self._frames[seq] = lf

    def take(self, seq: int) -> np.ndarray | None:
        """The input of frame ``seq``; originals of earlier frames (lost in transport) are dropped."""
        with self._lock:
            ref = self._frames.pop(seq, None)
            for k in [k for k in self._frames if k < seq]:
                del self._frames[k]
        return ref


class Stage:
    """A thread's worth of work with its own :class:`StageStats`."""

    name = "stage"

    def __init__(self, control: RunControl, stats: StageStats) -> None:
        self.control = control
        self.stats = stats

    def run(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError


class ConsumerStage(Stage):
    """The loop every consuming stage shares (see the module docstring)."""

    def __init__(self, control: RunControl, stats: StageStats, q_in: queue.Queue,
                 q_out: queue.Queue | None = None) -> None:
        super().__init__(control, stats)
        self.q_in, self.q_out = q_in, q_out

    def work(self, item: Any) -> Any:
        """The stage's work on one item; ``None`` means: not a frame of this stage."""
        raise NotImplementedError

    def forward(self, result: Any) -> bool:
        return self.control.put(self.q_out, result) if self.q_out is not None else True

    def close(self, seq: int | None) -> None:
        if self.q_out is not None:
            self.control.put_end(self.q_out)

    def run(self) -> None:
        seq = None
        try:
            while (item := self.control.get(self.q_in)) is not None:
                seq = item.seq
                t0, c0 = time.perf_counter(), time.thread_time()
                result = self.work(item)
                if result is None:
                    continue
                self.stats.add(1, time.perf_counter() - t0, time.thread_time() - c0)
                if not self.forward(result):
                    break
        except Exception as exc:
            self.control.fail(self.name, seq, exc)
        finally:
            self.close(seq)


class ProducerStage(Stage):
    """Reads the source into the encoder's queue, keeping the inputs for the metrics."""

    name = "producer"

    def __init__(self, control: RunControl, stats: StageStats, source: Iterator[np.ndarray], q_out: queue.Queue,
                 originals: OriginalFrames | None) -> None:
        super().__init__(control, stats)
        self.source, self.q_out, self.originals = source, q_out, originals

    def run(self) -> None:
        seq = 0
        try:
            it = iter(self.source)
            while not self.control.stop_event.is_set():
                t0, c0 = time.perf_counter(), time.thread_time()
                try:
                    lf = next(it)
                except StopIteration:
                    break
                lf = np.ascontiguousarray(lf)
                self.stats.add(1, time.perf_counter() - t0, time.thread_time() - c0)
                if self.originals is not None:
                    self.originals.keep(seq, lf)
                if not self.control.put(self.q_out, SourceFrame(seq, lf)):
                    break
                seq += 1
        except LFStreamError as exc:
            if seq == 0:  # nothing read: the input itself is refused
                self.control.fail(self.name, seq, exc)
            else:  # damaged part way (a video or .lfs cut short): the stream ends here
                self.control.input_error = exc
        except Exception as exc:
            self.control.fail(self.name, seq, exc)
        finally:
            # a generator stopped early cleans up now (a cache file it was filling), not
            # whenever it happens to be collected
            close = getattr(it, "close", None) if "it" in locals() else None
            if close is not None:
                try:
                    close()
                except Exception:  # noqa: BLE001 - the stream's own outcome stands
                    pass
            self.control.put_end(self.q_out)


class EncoderStage(ConsumerStage):
    """Frames -> packets on the channel; counts the bytes (:class:`RateStats`)."""

    name = "encoder"

    def __init__(self, control: RunControl, stats: StageStats, q_in: queue.Queue, channel: Sender,
                 config: StreamConfig, expect_frames: bool, present: np.ndarray | None = None) -> None:
        super().__init__(control, stats, q_in)
        self.channel, self.config, self.expect_frames, self.present = channel, config, expect_frames, present
        cfg = config
        # views_hint: the hint is sent even where the views are coded themselves (the focal
        # planes are fitted to the decoded disparity)
        self.stream = StreamEncoder(CodingOptions(quality=cfg.quality, bpp=cfg.bpp, preset=cfg.preset,
                                                  depth_hint=cfg.depth_hint, residual=cfg.residual,
                                                  residual_mode=cfg.residual_mode, hance_map=cfg.hance_map,
                                                  views_hint=True), cfg.fps, present)
        self.rate = RateStats()

    def work(self, item: SourceFrame) -> Packet:
        lf = item.lf
        first = self.stream.frames == 0
        packet = self.stream.encode_frame(lf)
        if first:
            self.channel.send_header(self.stream.header)
        self.rate.add(item.seq, len(packet.image) + len(packet.hint) + len(packet.gain) + len(packet.residual),
                      int(np.prod(lf.shape[:4])), self.stream.encoder.quality)
        return packet

    def coding(self) -> dict:
        """What the stream's encoder codes (the summary's ``coding``,
        :meth:`lfstream.codec.stream_encoder.StreamEncoder.coding`)."""
        return self.stream.coding()

    def forward(self, packet: Packet) -> bool:
        return self.channel.send(packet, self.control.stop_event)

    def close(self, seq: int | None) -> None:
        try:
            if self.stream.frames == 0 and self.expect_frames and not self.control.stop_event.is_set():
                self.control.fail(self.name, None, LFValueError("the source gave no frames"))
            self.channel.close(self.control.stop_event)
        except Exception as exc:
            self.control.fail("transport", seq, exc)


class DecoderStage(Stage):
    """Packets -> decoded frames, batched for the networks, with skip (a): a frame whose
    centre view barely changed reuses the previous frame's disparity."""

    name = "decoder"

    def __init__(self, control: RunControl, stats: StageStats, channel: Receiver, q_out: queue.Queue,
                 config: StreamConfig) -> None:
        super().__init__(control, stats)
        self.channel, self.q_out, self.config = channel, q_out, config
        self.decoder: Decoder | None = None
        self.static = StaticSkipStats(enabled=config.skip_static)

    def run(self) -> None:
        cfg, seq = self.config, None
        try:
            header = self.channel.header(self.control.stop_event)
            dec = self.decoder = Decoder(header, depth=cfg.depth, hance=cfg.hance, device=cfg.device,
                                         preset=cfg.networks)
            prev: DecodedFrame | None = None
            pending: list[Packet] = []
            packets = self.channel.packets(self.control.stop_event)
            done = False
            while not done and not self.control.stop_event.is_set():
                try:
                    pending.append(next(packets))
                except StopIteration:
                    done = True
                if pending and (len(pending) >= cfg.batch or done):
                    seq = pending[0].seq
                    t0, c0 = time.perf_counter(), time.thread_time()
                    frames = self._decode(dec, pending, prev)
                    self.stats.add(len(frames), time.perf_counter() - t0, time.thread_time() - c0)
                    pending = []
                    for f in frames:
                        prev = f
                        if not self.control.put(self.q_out, f):
                            return
        except Exception as exc:
            self.control.fail(self.name if not isinstance(exc, OSError) else "transport", seq, exc)
        finally:
            self.control.put_end(self.q_out)

    def _decode(self, dec: Decoder, packets: list[Packet], prev: DecodedFrame | None) -> list[DecodedFrame]:
        sk = self.static
        if not (sk.enabled and dec.estimates_depth and prev is not None and len(packets) == 1):
            return dec.decode_batch(packets)
        t0 = time.perf_counter()
        centres = dec.decode_centres(packets)
        t_centres = time.perf_counter() - t0
        if float(cv2.absdiff(centres[0], prev.centre).mean()) >= self.config.static_threshold:
            return dec.decode_batch(packets, centres)
        skipped = dec.reconstruct(packets[0], centres[0], prev.disparity)
        t_skip = time.perf_counter() - t0
        sk.frames += 1
        if sk.error_db is None:
            # audit the first skip: decode fully, compare, and time what a skip saves
            from lfstream.metrics import mpsnr

            t0 = time.perf_counter()
            full = dec.decode_batch(packets, centres)[0]
            sk.full_decode_s = t_centres + time.perf_counter() - t0
            sk.error_db = float(np.minimum(mpsnr(full.lf, skipped.lf), 100.0))
        sk.saved_s += max(sk.full_decode_s - t_skip, 0.0)
        return [skipped]


class RefocusStage(ConsumerStage):
    """Decoded frames -> focal stacks (the method is chosen on the first frame)."""

    name = "refocus"

    def __init__(self, control: RunControl, stats: StageStats, q_in: queue.Queue, q_out: queue.Queue,
                 config: StreamConfig) -> None:
        super().__init__(control, stats, q_in, q_out)
        self.config = config
        self.refocuser: Refocuser | None = None
        self.view_axes: np.ndarray | None = None  # the first frame's, where its views were reordered

    def work(self, f: DecodedFrame) -> StackFrame:
        # the convention's grid (a capture with flipped or swapped view axes, which the hint
        # carries, reordered), so that the planes focus at the disparities they name
        lf = canonical_views(f.lf, f.axes)[0]
        if self.refocuser is None:
            self.view_axes = None if lf is f.lf else f.axes
            self.refocuser = Refocuser(self.config, tuple(lf.shape[:2]))
            self.refocuser.fit_planes(f)
            self.refocuser.choose(lf)
        else:
            self.refocuser.fit_planes(f)
        stack = self.refocuser.render(f, lf)
        return StackFrame(f.seq, f, stack, self.refocuser.slopes.copy())


class SinkStage(ConsumerStage):
    """Writes the outputs (when there is an output folder) and passes frames to the metrics."""

    name = "sink"

    def __init__(self, control: RunControl, stats: StageStats, q_in: queue.Queue, q_out: queue.Queue | None,
                 sink: Sink | None, delay_s: float = 0.0) -> None:
        super().__init__(control, stats, q_in, q_out)
        self.sink, self.delay_s = sink, delay_s

    def work(self, f: StackFrame) -> StackFrame:
        if self.sink is not None:
            self.sink.write(f)
        if self.delay_s:
            time.sleep(self.delay_s)
        return f

    def close(self, seq: int | None) -> None:
        if self.sink is not None:
            try:
                self.sink.close()
            except Exception as exc:
                self.control.fail(self.name, seq, exc)
        super().close(seq)


class MetricsStage(ConsumerStage):
    """Decoded frames against the inputs: MPSNR every frame, MSSIM and the focal stack's
    PSNR against shift-and-sum of the input every ``mssim_every`` frames."""

    name = "metrics"

    def __init__(self, control: RunControl, stats: StageStats, q_in: queue.Queue, originals: OriginalFrames,
                 config: StreamConfig, present: np.ndarray | None = None) -> None:
        super().__init__(control, stats, q_in)
        self.originals, self.config, self.present = originals, config, present
        self.quality = QualityStats()

    def work(self, f: StackFrame) -> StackFrame | None:
        from lfstream.metrics import mpsnr, mssim, psnr
        from lfstream.refocus import focal_stack

        ref = self.originals.take(f.seq)
        if ref is None:
            return None
        rec = f.decoded.lf
        q = self.quality
        # over the views that exist: a missing view is zero in the input, not a target
        q.mpsnr.append((f.seq, float(np.minimum(mpsnr(ref, rec, present=self.present), 100.0))))
        every = self.config.mssim_every
        if every and f.seq % every == 0 and min(ref.shape[2:4]) >= 11:
            q.mssim.append((f.seq, float(mssim(ref, rec, present=self.present))))
            if f.stack is not None:
                ref_views, present = canonical_views(ref, f.decoded.axes, self.present)  # as the refocus stage
                truth = focal_stack(ref_views, slopes=f.slopes, present=present)
                q.stack_psnr[f.seq] = float(np.mean(np.minimum(psnr(truth, f.stack), 100.0)))
        return f


__all__ = ["PipelineError", "RunControl", "OriginalFrames", "Stage", "ConsumerStage", "ProducerStage", "EncoderStage",
           "DecoderStage", "RefocusStage", "SinkStage", "MetricsStage"]
