"""The streaming pipeline: Producer -> Encoder -> Transport -> Decoder -> Refocus -> Sink.

Each stage runs in its own thread (the heavy work — OpenCV, numba kernels, torch — releases
the GIL) and stages are joined by bounded queues, so a slow sink throttles the producer
and memory stays bounded. A ``Metrics`` stage beside the sink compares each decoded frame
with the input frame the producer read (MPSNR every frame; MSSIM every ``mssim_every``
frames from frame 0: 0.2 s per 7x7x375x540 frame). Before the clock starts, the compiled
kernels are loaded on a tiny light field (:mod:`lfstream.stream.warmup`).

Skips (each switchable, each reported in the summary with what it saved and cost):
  (a) ``skip_static``: a frame whose decoded centre view differs from the previous one by
      less than ``static_threshold`` (mean absolute 8-bit levels) reuses the previous
      frame's disparity (no hint decoding / Depth-Net);
  (b) JPEG-Hance runs only where it was measured to help (the decoder's ``hance="auto"``:
      at JPEG qualities up to a preset's threshold, the fast preset on a CUDA device only;
      on any device, a stream with the encoder's strength maps, ``hance_map``, blended by
      them; elsewhere the classical post-filter :func:`lfstream.codec.centre.jpeg.deblock_jpeg`);
  (c) rendering the focal stack straight from centre view + disparity is not offered: each
      plane would need one scattered (gathered) sample of the centre per view and pixel,
      13 x 49 per pixel for the default planes of a 7x7 grid (~130 M scalar gathers, over a
      second on the development CPU), where the fused warp gathers once per view and pixel
      and the separable shift-and-sum then streams the views
      with vectorised rows.

The stages live in :mod:`lfstream.stream.stages`, each owning its statistics; this module
wires them: channels, queues, threads, and the summary. An error in any stage stops the
pipeline and raises :class:`PipelineError` naming the stage and frame;
:meth:`Pipeline.stop` (Ctrl-C in the CLI) stops every stage within a fraction of a second
and the sink finalises every file it opened.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from lfstream.errors import LFValueError
from lfstream.lightfield import axes_as_list
from lfstream.stream.config import StreamConfig
from lfstream.stream.report import QualityStats, RateStats, StageStats, StaticSkipStats, build_summary
from lfstream.stream.sinks import Sink
from lfstream.stream.stages import (
    DecoderStage,
    EncoderStage,
    MetricsStage,
    OriginalFrames,
    PipelineError,
    ProducerStage,
    RefocusStage,
    RunControl,
    SinkStage,
)
from lfstream.stream.transport import FileChannel, InprocChannel, LazyTcpSender, Receiver, Sender, TcpReceiver

#: The status line while the kernels load (:mod:`lfstream.stream.warmup`), before the first frame.
WARMUP_STATUS = "warming up: loading the compiled kernels (the first run after an install compiles them, about a minute)"
#: The same with a source to prepare (:attr:`lfstream.stream.Source.prepare`).
PREPARE_STATUS = (WARMUP_STATUS + "; preparing the source (the built-in clip: rendered into the cache on a first run, "
                                  "about 0.4 s a frame)")
STAGE_NAMES = ("producer", "encoder", "decoder", "refocus", "sink", "metrics")
#: After a stop (Ctrl-C), how long the pipeline waits for its stages to finish their item.
STOP_GRACE_S = 10.0


def _run_then_set(run: Callable[[], object], done: threading.Event, quiet: bool = False) -> None:
    """Runs ``run`` and then sets ``done``, whatever happens. ``quiet``: a failure is left to the
    stream (the source's preparation, the kernels' warm-up: the source then does the work as it
    goes, or it fails again in its stage, which names it with the stage and frame)."""
    try:
        run()
    except Exception:
        if not quiet:
            raise
    finally:
        done.set()


class Pipeline:
    """Runs the stages of one stream; see the module docstring.

    Args:
        source: iterator of ``(U, V, H, W, 3)`` uint8 frames (``None`` with ``receiver``).
        config: what to do.
        out: output folder of the sink (``None``: nothing written).
        sender: for ``lfstream stream --to``: a connected :class:`~lfstream.stream.transport.TcpSender`;
            the pipeline then ends at the transport.
        receiver: for ``lfstream serve``: a :class:`~lfstream.stream.transport.TcpReceiver`; the
            pipeline then starts at the transport.
        progress: a callable given a status line about twice a second.
        stream_file: the ``.lfs`` file of ``transport="file"``.
        total_frames: how many frames the source holds, when known (the status line's ETA).
        present: ``(U, V)`` mask of the source's views that exist (``None``: all); the
            encoder needs the centre view only, the metrics count present views only.
        prepare: the source's work before the stream is timed
            (:attr:`lfstream.stream.Source.prepare`: rendering the built-in clip into its
            cache), run on a thread beside the kernels' warm-up and waited for (its time is
            in the summary's ``warmup_s``); given an event set when the run is stopped.
        sink_delay_s: seconds the sink waits on each frame: a slow consumer, for tests and
            benchmarks of the bounded queues' backpressure (0: none).
        on_warm: called on the calling thread once the kernels are loaded (and the source
            prepared), just before the stream is timed: where a command settles its process
            (:func:`lfstream.cli._pipeline.frozen_garbage_collector`).

    Attributes:
        stats: per stage name, its :class:`~lfstream.stream.report.StageStats` (live while running).
    """

    def __init__(self, source: Iterator[np.ndarray] | None, config: StreamConfig, out: Path | None = None,
                 sender: Sender | None = None, receiver: Receiver | None = None,
                 progress: Callable[[str], None] | None = None, stream_file: Path | None = None,
                 total_frames: int | None = None, present: np.ndarray | None = None,
                 prepare: Callable[[threading.Event], object] | None = None, sink_delay_s: float = 0.0,
                 on_warm: Callable[[], None] | None = None) -> None:
        config.validate()
        if sink_delay_s < 0:
            raise LFValueError(f"sink_delay_s: >= 0, got {sink_delay_s!r}")
        self.config = config
        self.sink_delay_s = sink_delay_s
        self.source = source
        self.out = out
        self.sender = sender
        self.receiver = receiver
        self.progress = progress
        self.stream_file = stream_file
        self.total_frames = total_frames
        self.present = present
        self.prepare = prepare
        self.on_warm = on_warm
        self._prepare_stop = threading.Event()
        # set when the preparation ends: waited on instead of Thread.join, which a Ctrl-C
        # interrupting it can leave reporting a live thread as stopped
        self._prepared = threading.Event()
        self.control = RunControl()
        self.stats = {name: StageStats(name) for name in STAGE_NAMES}
        self.interrupted = False
        self.queues: dict[str, queue.Queue] = {}

    def _warm_kernels(self) -> None:
        """Loads the stages' compiled kernels (:func:`lfstream.stream.warmup.warm_kernels`)."""
        from lfstream.stream.warmup import warm_kernels

        warm_kernels(self.config, decode=self.sender is None)

    def stop(self) -> None:
        """Stops every stage (Ctrl-C); the run then reports ``interrupted``."""
        self.interrupted = True
        self.control.stop_event.set()

    def _channels(self) -> tuple[Sender | None, Receiver | None]:
        cfg = self.config
        if self.receiver is not None:
            return None, self.receiver
        if self.sender is not None:
            return self.sender, None
        if cfg.transport == "file":
            channel = FileChannel(self.stream_file)
            return channel, channel
        if cfg.transport == "tcp":
            # loopback TCP: the sender connects when the encoder sends the stream header
            receiver = TcpReceiver("127.0.0.1", 0)
            return LazyTcpSender(*receiver.address), receiver
        channel = InprocChannel(cfg.queue_size)
        return channel, channel

    def run(self) -> dict:
        """Runs the stream to its end (or a stop) and returns the summary. An input damaged
        after its first frames (a video or ``.lfs`` cut short) ends the stream there: the
        frames before it go through every stage, and the summary names the damage
        (``input_error``).

        Raises:
            PipelineError: a stage failed (after every stage has stopped and the outputs
                written so far are finalised).
        """
        cfg, ctl = self.config, self.control
        t_warm = time.perf_counter()
        if self.progress is not None:  # silent otherwise: a fresh install compiles here for most of a minute
            self.progress(WARMUP_STATUS if self.prepare is None else PREPARE_STATUS)
        preparing = None
        # the warm-up imports and loads modules on a thread of its own, so that this thread
        # only waits: a Ctrl-C (or a SIGTERM relayed as one) that lands inside an import
        # leaves that module's import lock held, and the source's thread importing the same
        # module then waited for it forever
        warmed = threading.Event()
        try:
            if self.prepare is not None:
                preparing = threading.Thread(target=_run_then_set, args=(lambda: self.prepare(self._prepare_stop),
                                                                         self._prepared, True),
                                             name="lfstream-prepare", daemon=True)
                preparing.start()
            threading.Thread(target=_run_then_set, args=(self._warm_kernels, warmed, True), name="lfstream-warmup",
                             daemon=True).start()
            while not warmed.wait(0.2):  # in slices: Ctrl-C reaches this thread meanwhile
                pass
            if preparing is not None:
                while not self._prepared.wait(0.2):
                    pass
        finally:
            # Ctrl-C: the source stops and cleans up (a thread the interrupt kept from
            # starting has nothing to clean)
            if preparing is not None and preparing.ident is not None and not self._prepared.is_set():
                self._prepare_stop.set()
                self._prepared.wait()
        if self.on_warm is not None:
            self.on_warm()
        t_start, cpu_start = time.perf_counter(), time.process_time()
        send_channel, recv_channel = self._channels()
        qs = cfg.queue_size
        self.queues = {name: queue.Queue(qs) for name in ("encode", "refocus", "sink", "metrics")}
        want_metrics = cfg.metrics and self.source is not None and self.sender is None
        originals = OriginalFrames() if want_metrics else None
        stages = []
        encoder = decoder = refocus = sink = metrics = None
        if self.source is not None:
            stages.append(ProducerStage(ctl, self.stats["producer"], self.source, self.queues["encode"], originals))
            encoder = EncoderStage(ctl, self.stats["encoder"], self.queues["encode"], send_channel, cfg,
                                   expect_frames=self.sender is None, present=self.present)
            stages.append(encoder)
        if self.sender is None:
            decoder = DecoderStage(ctl, self.stats["decoder"], recv_channel, self.queues["refocus"], cfg)
            refocus = RefocusStage(ctl, self.stats["refocus"], self.queues["refocus"], self.queues["sink"], cfg)
            sink = SinkStage(ctl, self.stats["sink"], self.queues["sink"], self.queues["metrics"] if want_metrics else None,
                             Sink(self.out, cfg) if self.out is not None else None, self.sink_delay_s)
            stages += [decoder, refocus, sink]
            if want_metrics:
                metrics = MetricsStage(ctl, self.stats["metrics"], self.queues["metrics"], originals, cfg, self.present)
                stages.append(metrics)
        # each stage sets its event when it ends: waited on instead of Thread.join, which a
        # Ctrl-C interrupting it can leave reporting a live thread as stopped
        done = [threading.Event() for _ in stages]
        threads = [threading.Thread(target=_run_then_set, args=(s.run, d), name=s.name, daemon=True)
                   for s, d in zip(stages, done)]
        for t in threads:
            t.start()
        last = 0.0
        try:
            while not all(d.is_set() for d in done):
                for d in done:
                    d.wait(timeout=0.05)
                if self.progress is not None and time.perf_counter() - last > 0.5:
                    last = time.perf_counter()
                    self.progress(self.status_line(last - t_start))
        except KeyboardInterrupt:
            self.stop()
            # every stage sees the stop at its next item; wait for them (the longest item, an
            # MSSIM of a large frame, takes ~2 s): a thread still inside native code when the
            # interpreter exits aborts the process ("terminate called without an active
            # exception") and leaves files unfinished
            deadline = time.perf_counter() + STOP_GRACE_S
            for d in done:
                d.wait(timeout=max(0.0, deadline - time.perf_counter()))
        wall = time.perf_counter() - t_start
        if ctl.error is not None:
            raise ctl.error
        refocuser = refocus.refocuser if refocus is not None else None
        receive = recv_channel.stats.as_dict() if recv_channel is not None else None
        if receive is not None and decoder is not None and decoder.decoder is not None:
            # delta hints / gain maps whose reference frame was lost: the previous ones stood in
            receive["hint_fallbacks"] = decoder.decoder.hint_fallbacks
            receive["gain_fallbacks"] = decoder.decoder.gain_fallbacks
        summary = build_summary(
            wall_s=wall,
            process_cpu_s=time.process_time() - cpu_start,
            warmup_s=t_start - t_warm,
            frames=self.stats["sink"].frames if self.sender is None else self.stats["encoder"].frames,
            stages=self.stats,
            rate=encoder.rate if encoder is not None else RateStats(),
            coding=encoder.coding() if encoder is not None else None,
            quality=metrics.quality if metrics is not None else QualityStats(),
            static=decoder.static if decoder is not None else StaticSkipStats(enabled=cfg.skip_static),
            receive=receive,
            transport="tcp" if self.sender is not None or self.receiver is not None else cfg.transport,
            refocus={"method": refocuser.method, "why": refocuser.reason, "view_axes": axes_as_list(refocus.view_axes)}
            if refocuser is not None else None,
            focal_planes=refocuser.planes() if refocuser is not None else [],
            plane_updates=refocuser.updates if refocuser is not None else [],
            hance={"mode": cfg.hance, "networks": cfg.networks,
                   "ran": bool(decoder is not None and decoder.decoder is not None and decoder.decoder.uses_hance),
                   # the precision the decoder's networks (JPEG-Hance, Depth-Net) ran in, or None
                   "precision": decoder.decoder.network_precision
                   if decoder is not None and decoder.decoder is not None else None},
            interrupted=self.interrupted,
            outputs=sink.sink.files if sink is not None and sink.sink is not None else [],
        )
        if ctl.input_error is not None:
            summary["input_error"] = str(ctl.input_error)
        return summary

    def status_line(self, elapsed: float) -> str:
        """One line: frames done (of the total, with an ETA, when known), frames/s, elapsed
        time, frames per stage and queue fill."""
        done = self.stats["sink" if self.sender is None else "encoder"].frames
        rate = done / elapsed if elapsed > 0 else 0.0
        head = f"frame {done}" + (f"/{self.total_frames}" if self.total_frames else "") + f" | {rate:.1f} frames/s"
        if self.total_frames and rate > 0:
            head += f" | ETA {max(self.total_frames - done, 0) / rate:.0f} s"
        parts = [head, f"{elapsed:.1f} s"]
        for name in ("producer", "encoder", "decoder", "refocus", "sink"):
            s = self.stats[name]
            if s.frames:
                parts.append(f"{name[:3]} {s.frames}")
        parts.append("queues " + " ".join(f"{k[:3]} {q.qsize()}/{q.maxsize}" for k, q in self.queues.items()))
        return " | ".join(parts)


__all__ = ["Pipeline", "PipelineError", "STAGE_NAMES", "WARMUP_STATUS", "PREPARE_STATUS"]
