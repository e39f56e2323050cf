"""The streaming pipeline: Producer -> Encoder -> Transport -> Decoder -> Refocus -> Sink.

Each stage runs in its own thread (the heavy work — OpenCV, numba kernels, torch — releases
the GIL) and stages are joined by bounded queues, so a slow sink throttles the producer
and memory stays bounded. A ``Metrics`` stage beside the sink compares each decoded frame
with the input frame the producer read (MPSNR every frame; MSSIM every ``mssim_every``
frames: it costs ~2 s per 7x7x375x540 frame).

Skips (each switchable, each reported in the summary with what it saved and cost):
  (a) ``skip_static``: a frame whose decoded centre view differs from the previous one by
      less than ``static_threshold`` (mean absolute 8-bit levels) reuses the previous
      frame's disparity (no hint decoding / Depth-Net);
  (b) ``skip_planes`` (off by default, see :class:`StreamConfig`): focal planes whose slope lies outside the scene's disparity range
      (1st..99th percentile of the decoded disparity, widened by ``plane_margin``) are
      rendered by a cheap path (shift-and-sum at half resolution, upsampled) and flagged;
  (c) JPEG-Hance runs only at JPEG qualities where it was measured to help (the decoder's
      ``hance="auto"``);
  (d) rendering the focal stack straight from centre view + disparity is not offered: it
      needs one remap per view and plane (16 x 49 for 7x7), against 49 remaps plus the
      fused shift-and-sum; from the measured parts (49 remaps ~60 ms, SaS 16 planes
      ~164 ms at 7x7x375x540) that is ~1 s against ~0.22 s. Not measured directly.

An error in any stage stops the pipeline and raises :class:`PipelineError` naming the
stage and frame; :meth:`Pipeline.stop` (Ctrl-C in the CLI) stops every stage within a
fraction of a second and the sink finalises every file it opened.
"""

from __future__ import annotations

import json
import os
import queue
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import cv2
import numpy as np

from lfstream.bitstream import Packet
from lfstream.codec import Decoder, DecodedFrame, Encoder, check_device
from lfstream.errors import LFFileError, LFStreamError, LFValueError
from lfstream.optics import SEED_ALPHAS, slopes_from_alphas
from lfstream.transport import get_until_stopped, put_until_stopped

REFOCUS_MODES = ("auto", "refnet", "sas", "fourier", "none")
TRANSPORTS = ("inproc", "file", "tcp")
SAVE_KINDS = ("mp4", "png", "sweep", "lf")
_POLL_S = 0.1
_SKIP = object()  # a stage's work result meaning "not counted as a frame"


class PipelineError(LFStreamError):
    """A stage failed; ``stage`` and ``frame`` say where."""

    def __init__(self, message: str, stage: str, frame: int | None) -> None:
        super().__init__(message)
        self.stage = stage
        self.frame = frame


@dataclass
class StreamConfig:
    """What the pipeline does (the CLI's flags map onto these fields)."""

    quality: int = 50
    depth_hint: bool = True
    depth: str = "auto"
    hance: str = "auto"
    refocus: str = "auto"
    alphas: tuple[float, ...] = SEED_ALPHAS
    batch: int = 1
    device: str = "cpu"
    queue_size: int = 4
    transport: str = "inproc"
    save: tuple[str, ...] = ("mp4",)
    skip_static: bool = True
    static_threshold: float = 0.5
    # off by default: measured on 7x7x375x540, the half-resolution path is no faster than the
    # numba SaS of the same planes (resizing 49 views costs what it saves); see the summary
    skip_planes: bool = False
    plane_margin: float = 0.5
    mssim_every: int = 10
    metrics: bool = True
    sink_delay_s: float = 0.0  # an artificially slow sink (backpressure benchmarks)
    fps: float = 30.0

    def validate(self) -> None:
        if self.refocus not in REFOCUS_MODES:
            raise LFValueError(f"refocus: one of {', '.join(REFOCUS_MODES)}, got {self.refocus!r}")
        if self.transport not in TRANSPORTS:
            raise LFValueError(f"transport: one of {', '.join(TRANSPORTS)}, got {self.transport!r}")
        bad = [s for s in self.save if s not in SAVE_KINDS]
        if bad:
            raise LFValueError(f"save: each of {', '.join(SAVE_KINDS)}, got {bad}")
        if not 1 <= self.batch <= 64:
            raise LFValueError(f"batch: in 1..64, got {self.batch}")
        if not 1 <= self.queue_size <= 256:
            raise LFValueError(f"queue size: in 1..256, got {self.queue_size}")
        if self.mssim_every < 0 or self.static_threshold < 0 or self.sink_delay_s < 0:
            raise LFValueError("mssim_every, static_threshold and sink_delay_s must be >= 0")
        check_device(self.device)


@dataclass
class StageStats:
    name: str
    frames: int = 0
    busy_s: float = 0.0

    def as_dict(self) -> dict:
        return {"frames": self.frames, "time_s": round(self.busy_s, 4),
                "ms_per_frame": round(1e3 * self.busy_s / self.frames, 2) if self.frames else None,
                "fps": round(self.frames / self.busy_s, 2) if self.busy_s > 0 else None}


@dataclass
class Frame:
    """What travels between the decoder, refocus, sink and metrics stages."""

    seq: int
    decoded: DecodedFrame
    stack: np.ndarray | None = None  # (K, H, W, 3) uint8
    cheap_planes: list[int] = field(default_factory=list)


# ----------------------------------------------------------------------------------------
# sources


def synthetic_source(frames: int = 24, views: int = 7, size: tuple[int, int] = (375, 540),
                     seed: int = 2024) -> Iterator[np.ndarray]:
    """The built-in clip: a layered synthetic scene with motion, a pan, sensor noise and
    vignetting, rendered frame by frame (deterministic)."""
    from lfstream.synth import SynthConfig, iter_clip

    cfg = SynthConfig(frames=frames, views=views, size=size, layers=4, motion=1.0, camera_pan=0.4,
                      noise=1.5, vignetting=0.2, seed=seed)
    for lf, _ in iter_clip(cfg):
        yield lf


def file_source(path: str | os.PathLike, max_frames: int | None = None, **read_options) -> tuple[Iterator[np.ndarray], float | None]:
    """Frames of an LF file; mosaic videos are read lazily (one frame in memory)."""
    from lfstream.io import VIDEO_EXTS, iter_video_frames, load_lf, video_grid_and_fps
    from lfstream.lightfield import from_mosaic

    path = Path(path)
    if path.is_file() and path.suffix.lower() in VIDEO_EXTS and not read_options.get("crop"):
        grid, fps = video_grid_and_fps(path)
        grid = read_options.get("grid") or grid
        if grid is not None:
            return (from_mosaic(f, grid) for f in iter_video_frames(path, max_frames)), fps
    loaded = load_lf(path, max_frames=max_frames, **read_options)
    if loaded.present is not None and not loaded.present.all():
        raise LFValueError(f"{path}: streaming needs every view (this source has {int((~loaded.present).sum())} missing)")
    lf = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    return iter(lf), loaded.fps


# ----------------------------------------------------------------------------------------
# refocus stage


class Refocuser:
    """Renders the focal stack of decoded frames with the chosen method and skip (b)."""

    def __init__(self, config: StreamConfig, views: tuple[int, int]) -> None:
        self.config = config
        self.views = views
        self.slopes = slopes_from_alphas(config.alphas)
        self.method = config.refocus
        self.reason = "requested"
        self.cheap_planes = 0
        self.cheap_saved_s = 0.0
        self.cheap_error_db: float | None = None
        self._cheap_ratio: float | None = None

    def _refnet_applicable(self) -> bool:
        from lfstream.weights import manifest_entry

        entry = manifest_entry("refnet", "fast")
        return (entry is not None and tuple(entry["config"]["views"]) == tuple(self.views)
                and np.allclose(self.config.alphas, SEED_ALPHAS))

    def choose(self, lf: np.ndarray) -> None:
        """``auto``: RefNet when it is applicable, faster than SaS on this device and within
        30 dB PSNR of SaS on this frame; otherwise SaS (measured on the first frame)."""
        from lfstream.metrics import psnr
        from lfstream.refocus import focal_stack

        if self.method != "auto":
            if self.method == "refnet" and not self._refnet_applicable():
                raise LFValueError("refocus=refnet: the shipped RefNet takes 7x7 views and the seed's 16 alphas")
            return
        if not self._refnet_applicable():
            self.method, self.reason = "sas", "RefNet not applicable (grid or alphas differ from its training)"
            return
        t0 = time.perf_counter()
        ref = focal_stack(lf, self.config.alphas)
        t_sas = time.perf_counter() - t0
        focal_stack(lf, method="refnet", device=self.config.device)  # warm-up
        t0 = time.perf_counter()
        net = focal_stack(lf, method="refnet", device=self.config.device)
        t_net = time.perf_counter() - t0
        err = float(np.mean(psnr(ref, net)))
        if t_net < t_sas and err >= 30.0:
            self.method = "refnet"
        else:
            self.method = "sas"
        self.reason = (f"measured on frame 0 ({self.config.device}): SaS {t_sas * 1e3:.0f} ms, RefNet {t_net * 1e3:.0f} ms "
                       f"at {err:.1f} dB vs SaS")

    def render(self, f: DecodedFrame) -> tuple[np.ndarray | None, list[int]]:
        from lfstream.refocus import focal_stack

        if self.method == "none":
            return None, []
        lf = f.lf
        if self.method in ("refnet", "fourier") or not self.config.skip_planes:
            extra = {"device": self.config.device} if self.method == "refnet" else {}
            return focal_stack(lf, self.config.alphas, method=self.method, **extra), []
        d = f.disparity
        lo, hi = (np.percentile(d, [1, 99]) if d.size else (0.0, 0.0))
        margin = self.config.plane_margin
        inside = (self.slopes >= lo - margin) & (self.slopes <= hi + margin)
        out = np.empty((len(self.slopes), *lf.shape[2:]), np.uint8)
        if inside.any():
            out[inside] = focal_stack(lf, slopes=self.slopes[inside])
        cheap = np.flatnonzero(~inside).tolist()
        if cheap:
            h, w = lf.shape[2:4]
            t0 = time.perf_counter()
            small = np.stack([[cv2.resize(view, (max(1, w // 2), max(1, h // 2)), interpolation=cv2.INTER_AREA)
                               for view in row] for row in lf])
            rough = focal_stack(small, slopes=self.slopes[~inside] / 2.0)
            for k, img in zip(cheap, rough):
                out[k] = cv2.resize(img, (w, h), interpolation=cv2.INTER_LINEAR)
            t_cheap = time.perf_counter() - t0
            if self.cheap_error_db is None:
                # audit once: the exact planes, to report the error and time the skip costs/saves
                from lfstream.metrics import psnr

                t0 = time.perf_counter()
                exact = focal_stack(lf, slopes=self.slopes[~inside])
                t_exact = time.perf_counter() - t0
                self.cheap_error_db = float(np.mean(np.minimum(psnr(exact, out[cheap]), 100.0)))
                self._cheap_ratio = max(t_exact - t_cheap, 0.0) / len(cheap)
            self.cheap_planes += len(cheap)
            self.cheap_saved_s += (self._cheap_ratio or 0.0) * len(cheap)
        return out, cheap


# ----------------------------------------------------------------------------------------
# sink


class Sink:
    """Writes focal stacks (MP4 per plane, PNG per plane and frame, a focal-sweep MP4) and
    optionally the reconstructed LF (lossless FFV1 mosaic video)."""

    def __init__(self, out: Path, config: StreamConfig) -> None:
        self.out = out
        self.config = config
        self.files: list[str] = []
        self._plane_writers: list = []
        self._sweep = None
        self._lf_writer = None

    def write(self, f: Frame) -> None:
        from lfstream.io import VideoWriter, write_image
        from lfstream.lightfield import to_mosaic

        cfg = self.config
        if f.stack is not None:
            if "mp4" in cfg.save:
                if not self._plane_writers:
                    self._plane_writers = [VideoWriter(self.out / f"plane_{k:02d}.mp4", cfg.fps, lossless=False, crf=20,
                                                       preset="veryfast") for k in range(len(f.stack))]
                for w, img in zip(self._plane_writers, f.stack):
                    w.write(img)
            if "sweep" in cfg.save:
                if self._sweep is None:
                    self._sweep = VideoWriter(self.out / "focal_sweep.mp4", cfg.fps, lossless=False, crf=20,
                                              preset="veryfast")
                self._sweep.write(f.stack[f.seq % len(f.stack)])
            if "png" in cfg.save:
                folder = self.out / "frames" / f"frame_{f.seq:06d}"
                folder.mkdir(parents=True, exist_ok=True)
                for k, img in enumerate(f.stack):
                    write_image(folder / f"plane_{k:02d}.png", img)
        if "lf" in cfg.save:
            if self._lf_writer is None:
                u, v = f.decoded.lf.shape[:2]
                self._lf_writer = VideoWriter(self.out / "reconstructed.mkv", cfg.fps, lossless=True,
                                              metadata={"comment": f"lfstream-grid={u}x{v}"})
            self._lf_writer.write(to_mosaic(f.decoded.lf))

    def close(self) -> None:
        """Finalises every open file (also after an error or Ctrl-C)."""
        errors = []
        for w in [*self._plane_writers, self._sweep, self._lf_writer]:
            if w is None:
                continue
            try:
                w.close()
                if w.frames:
                    self.files.append(str(w.path))
            except LFStreamError as exc:
                errors.append(str(exc))
        if errors:
            raise LFFileError("; ".join(errors))


# ----------------------------------------------------------------------------------------
# the pipeline


class Pipeline:
    """Runs the stages of one stream; see the module docstring.

    Args:
        source: iterator of ``(U, V, H, W, 3)`` uint8 frames (``None`` with ``receiver``).
        config: what to do.
        out: output folder of the sink (``None``: nothing written).
        sender: for ``lfstream stream --to``: a connected :class:`~lfstream.transport.TcpSender`;
            the pipeline then ends at the transport.
        receiver: for ``lfstream serve``: a :class:`~lfstream.transport.TcpReceiver`; the
            pipeline then starts at the transport.
        progress: a callable given a status line about twice a second.
    """

    def __init__(self, source: Iterator[np.ndarray] | None, config: StreamConfig, out: Path | None = None,
                 sender=None, receiver=None, progress: Callable[[str], None] | None = None,
                 stream_file: Path | None = None) -> None:
        config.validate()
        self.config = config
        self.source = source
        self.out = out
        self.sender = sender
        self.receiver = receiver
        self.progress = progress
        self.stream_file = stream_file
        self.stop_event = threading.Event()
        self.stats = {name: StageStats(name) for name in ("producer", "encoder", "decoder", "refocus", "sink", "metrics")}
        self.error: PipelineError | None = None
        self.bytes = 0
        self.pixels = 0
        self._originals: dict[int, np.ndarray] = {}
        self._orig_lock = threading.Lock()
        self._psnr: list[float] = []
        self._ssim: list[tuple[int, float]] = []
        self._stack_psnr: dict[int, float] = {}
        self._frame_bpp: dict[int, float] = {}
        self.static_skips = 0
        self.static_saved_s = 0.0
        self.static_error_db: float | None = None
        self._static_full_s = 0.0  # a full decode's time, measured at the first skip
        self.refocuser: Refocuser | None = None
        self.interrupted = False
        self.decoder: Decoder | None = None
        self.sink: Sink | None = None
        self.queues: dict[str, queue.Queue] = {}

    # -- helpers ------------------------------------------------------------------------
    def _fail(self, stage: str, frame: int | None, exc: BaseException) -> None:
        if self.error is None:
            where = f" at frame {frame}" if frame is not None else ""
            self.error = PipelineError(f"stage {stage} failed{where}: {exc}", stage, frame)
            self.error.__cause__ = exc
        self.stop_event.set()

    def _put(self, q: queue.Queue, item) -> bool:
        return put_until_stopped(q, item, self.stop_event)

    def _get(self, q: queue.Queue):
        """The next item, or ``None`` at the end of the stream or on stop."""
        return get_until_stopped(q, self.stop_event)

    def stop(self) -> None:
        self.interrupted = True
        self.stop_event.set()

    # -- stages -------------------------------------------------------------------------
    def _producer(self, q_out: queue.Queue) -> None:
        st, seq = self.stats["producer"], 0
        try:
            it = iter(self.source)
            while not self.stop_event.is_set():
                t0 = time.perf_counter()
                try:
                    lf = next(it)
                except StopIteration:
                    break
                lf = np.ascontiguousarray(lf)
                st.busy_s += time.perf_counter() - t0
                st.frames += 1
                if self.config.metrics and self.sender is None:
                    with self._orig_lock:
                        self._originals[seq] = lf
                if not self._put(q_out, (seq, lf)):
                    break
                seq += 1
        except Exception as exc:
            self._fail("producer", seq, exc)
        finally:
            self._put_end(q_out)

    def _put_end(self, q: queue.Queue) -> None:
        # the end marker (None) must get through even when the consumer is slow
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

    def _consume(self, name: str, q_in: queue.Queue, work: Callable[[Any], Any],
                 forward: Callable[[Any], bool] | None = None, close: Callable[[int | None], None] | None = None) -> None:
        """The loop every consuming stage shares: takes items until the end marker or a stop,
        times ``work`` (its result ``_SKIP`` means: not a frame of this stage), passes the
        result to ``forward`` (False stops the stage), turns an exception into a
        :class:`PipelineError` naming the stage and frame, and always runs ``close`` last."""
        st, seq = self.stats[name], None
        try:
            while (item := self._get(q_in)) is not None:
                seq = item[0] if isinstance(item, tuple) else item.seq
                t0 = time.perf_counter()
                result = work(item)
                if result is _SKIP:
                    continue
                st.busy_s += time.perf_counter() - t0
                st.frames += 1
                if forward is not None and not forward(result):
                    break
        except Exception as exc:
            self._fail(name, seq, exc)
        finally:
            if close is not None:
                close(seq)

    def _encoder(self, q_in: queue.Queue, channel) -> None:
        enc = Encoder(quality=self.config.quality, depth_hint=self.config.depth_hint)
        started = False

        def encode(item: tuple[int, np.ndarray]) -> Packet:
            nonlocal started
            seq, lf = item
            if not started:
                channel.send_header(enc.header(tuple(lf.shape[:2]), tuple(lf.shape[2:4]), self.config.fps))
                started = True
            packet = enc.encode_frame(lf, seq, int(round(seq * 1e6 / self.config.fps)))
            pixels = int(np.prod(lf.shape[:4]))
            n_bytes = len(packet.image) + len(packet.hint) + len(packet.gain)
            self.bytes += n_bytes
            self.pixels += pixels
            self._frame_bpp[seq] = n_bytes * 8 / float(pixels)
            return packet

        def close(seq: int | None) -> None:
            try:
                if not started and self.receiver is None and self.sender is None and not self.stop_event.is_set():
                    self._fail("encoder", None, LFValueError("the source gave no frames"))
                channel.close(self.stop_event)
            except Exception as exc:
                self._fail("transport", seq, exc)

        self._consume("encoder", q_in, encode, lambda packet: channel.send(packet, self.stop_event), close)

    def _decoder(self, channel, q_out: queue.Queue) -> None:
        st, seq = self.stats["decoder"], None
        cfg = self.config
        try:
            header = channel.header(self.stop_event)
            dec = Decoder(header, depth=cfg.depth, hance=cfg.hance, device=cfg.device)
            self.decoder = dec
            prev: DecodedFrame | None = None
            pending: list[Packet] = []
            packets = channel.packets(self.stop_event)
            done = False
            while not done and not self.stop_event.is_set():
                try:
                    pending.append(next(packets))
                except StopIteration:
                    done = True
                if pending and (len(pending) >= cfg.batch or done):
                    seq = pending[0].seq
                    t0 = time.perf_counter()
                    frames = self._decode_with_static_skip(dec, pending, prev)
                    st.busy_s += time.perf_counter() - t0
                    st.frames += len(frames)
                    pending = []
                    for f in frames:
                        prev = f
                        if not self._put(q_out, f):
                            return
        except Exception as exc:
            self._fail("decoder" if not isinstance(exc, OSError) else "transport", seq, exc)
        finally:
            self._put_end(q_out)

    def _decode_with_static_skip(self, dec: Decoder, packets: list[Packet], prev: DecodedFrame | None) -> list[DecodedFrame]:
        """Skip (a): reuse the previous disparity for a near-static centre view."""
        cfg = self.config
        if not (cfg.skip_static and dec.estimates_depth and prev is not None and len(packets) == 1):
            return dec.decode_batch(packets)
        t0 = time.perf_counter()
        centres = dec.decode_centres(packets)
        t_centres = time.perf_counter() - t0
        if float(cv2.absdiff(centres[0], prev.centre).mean()) >= cfg.static_threshold:
            return dec.decode_batch(packets, centres)
        skipped = dec.reconstruct(packets[0], centres[0], prev.disparity)
        t_skip = time.perf_counter() - t0
        self.static_skips += 1
        if self.static_error_db is None:
            # audit the first skip: decode fully, compare, and time what a skip saves
            from lfstream.metrics import mpsnr

            t0 = time.perf_counter()
            full = dec.decode_batch(packets, centres)[0]
            self._static_full_s = t_centres + time.perf_counter() - t0
            self.static_error_db = float(np.minimum(mpsnr(full.lf, skipped.lf), 100.0))
        self.static_saved_s += max(self._static_full_s - t_skip, 0.0)
        return [skipped]

    def _refocus(self, q_in: queue.Queue, q_out: queue.Queue) -> None:
        def render(f: DecodedFrame) -> Frame:
            if self.refocuser is None:
                self.refocuser = Refocuser(self.config, tuple(f.lf.shape[:2]))
                self.refocuser.choose(f.lf)
            stack, cheap = self.refocuser.render(f)
            return Frame(f.seq, f, stack, cheap)

        self._consume("refocus", q_in, render, lambda frame: self._put(q_out, frame), lambda _: self._put_end(q_out))

    def _sink(self, q_in: queue.Queue, q_metrics: queue.Queue | None) -> None:
        sink = self.sink = Sink(self.out, self.config) if self.out is not None else None

        def write(f: Frame) -> Frame:
            if sink is not None:
                sink.write(f)
            if self.config.sink_delay_s:
                time.sleep(self.config.sink_delay_s)
            return f

        def close(seq: int | None) -> None:
            if sink is not None:
                try:
                    sink.close()
                except Exception as exc:
                    self._fail("sink", seq, exc)
            if q_metrics is not None:
                self._put_end(q_metrics)

        forward = (lambda f: self._put(q_metrics, f)) if q_metrics is not None else None
        self._consume("sink", q_in, write, forward, close)

    def _metrics(self, q_in: queue.Queue) -> None:
        from lfstream.metrics import mpsnr, mssim, psnr
        from lfstream.refocus import focal_stack

        def measure(f: Frame):
            with self._orig_lock:
                ref = self._originals.pop(f.seq, None)
                # frames the transport lost never reach this stage: drop their originals
                for k in [k for k in self._originals if k < f.seq]:
                    del self._originals[k]
            if ref is None:
                return _SKIP
            rec = f.decoded.lf
            self._psnr.append((f.seq, float(np.minimum(mpsnr(ref, rec), 100.0))))
            every = self.config.mssim_every
            if every and f.seq % every == 0 and min(ref.shape[2:4]) >= 11:
                self._ssim.append((f.seq, float(mssim(ref, rec))))
                if f.stack is not None:
                    # the focal stack against SaS of the input LF at the same alphas
                    truth = focal_stack(ref, self.config.alphas)
                    self._stack_psnr[f.seq] = float(np.mean(np.minimum(psnr(truth, f.stack), 100.0)))
            return f

        self._consume("metrics", q_in, measure)

    # -- run ----------------------------------------------------------------------------
    def run(self) -> dict:
        from lfstream.transport import FileChannel, InprocChannel, TcpReceiver

        cfg = self.config
        qs = cfg.queue_size
        t_start = time.perf_counter()
        threads: list[threading.Thread] = []
        send_channel = recv_channel = None
        if self.receiver is not None:
            recv_channel = self.receiver
        elif self.sender is not None:
            send_channel = self.sender
        elif cfg.transport == "file":
            send_channel = recv_channel = FileChannel(self.stream_file)
        elif cfg.transport == "tcp":
            # loopback TCP: the sender connects when the encoder sends the stream header
            recv_channel = self.receiver = TcpReceiver("127.0.0.1", 0)
            send_channel = _LazyTcpSender(*self.receiver.address)
        else:
            send_channel = recv_channel = InprocChannel(qs)
        self.queues = {"encode": queue.Queue(qs), "refocus": queue.Queue(qs), "sink": queue.Queue(qs),
                       "metrics": queue.Queue(qs)}
        if self.source is not None:
            threads.append(threading.Thread(target=self._producer, args=(self.queues["encode"],), name="producer"))
            threads.append(threading.Thread(target=self._encoder, args=(self.queues["encode"], send_channel),
                                            name="encoder"))
        if self.sender is None:
            want_metrics = cfg.metrics and self.source is not None
            threads += [
                threading.Thread(target=self._decoder, args=(recv_channel, self.queues["refocus"]), name="decoder"),
                threading.Thread(target=self._refocus, args=(self.queues["refocus"], self.queues["sink"]), name="refocus"),
                threading.Thread(target=self._sink, args=(self.queues["sink"], self.queues["metrics"] if want_metrics else None),
                                 name="sink"),
            ]
            if want_metrics:
                threads.append(threading.Thread(target=self._metrics, args=(self.queues["metrics"],), name="metrics"))
        for t in threads:
            t.daemon = True
            t.start()
        last = 0.0
        try:
            while any(t.is_alive() for t in threads):
                for t in threads:
                    t.join(timeout=0.05)
                if self.progress is not None and time.perf_counter() - last > 0.5:
                    last = time.perf_counter()
                    self.progress(self.status_line(last - t_start))
        except KeyboardInterrupt:
            self.stop()
            deadline = time.perf_counter() + 1.5
            for t in threads:
                t.join(timeout=max(0.0, deadline - time.perf_counter()))
        wall = time.perf_counter() - t_start
        if self.error is not None:
            raise self.error
        return self.summary(wall, recv_channel)

    def status_line(self, elapsed: float) -> str:
        parts = [f"{elapsed:6.1f} s"]
        for name in ("producer", "encoder", "decoder", "refocus", "sink"):
            s = self.stats[name]
            if s.frames:
                parts.append(f"{name[:3]} {s.frames} ({s.frames / max(elapsed, 1e-9):.1f}/s)")
        parts.append("queues " + " ".join(f"{k[:3]} {q.qsize()}/{q.maxsize}" for k, q in self.queues.items()))
        return " | ".join(parts)

    def summary(self, wall: float, channel) -> dict:
        frames = self.stats["sink"].frames if self.sender is None else self.stats["encoder"].frames
        stats = channel.stats.as_dict() if channel is not None and hasattr(channel, "stats") else None
        out = {
            "frames": frames,
            "fps": round(frames / wall, 3) if wall > 0 else None,
            "wall_s": round(wall, 3),
            "bpp": (self.bytes * 8 / self.pixels) if self.pixels else None,
            "bytes": self.bytes,
            "mpsnr": float(np.mean([p for _, p in self._psnr])) if self._psnr else None,
            "mssim": float(np.mean([s for _, s in self._ssim])) if self._ssim else None,
            "per_frame": [{"frame": k, "mpsnr": round(p, 4)} for k, p in self._psnr],
            "mssim_frames": [k for k, _ in self._ssim],
            "stages": {k: v.as_dict() for k, v in self.stats.items() if v.frames},
            "lost": stats["lost"] if stats else 0,
            "transport": {"kind": "tcp" if self.sender is not None or self.receiver is not None else self.config.transport,
                          **(stats or {})},
            "refocus": ({"method": self.refocuser.method, "why": self.refocuser.reason} if self.refocuser else None),
            "skips": {
                "static_frames": {"enabled": self.config.skip_static, "frames": self.static_skips,
                                  "saved_s": round(self.static_saved_s, 4),
                                  "error_mpsnr_db_vs_full": self.static_error_db},
                "out_of_range_planes": {"enabled": self.config.skip_planes,
                                        "planes": self.refocuser.cheap_planes if self.refocuser else 0,
                                        "saved_s": round(self.refocuser.cheap_saved_s, 4) if self.refocuser else 0.0,
                                        "error_psnr_db_vs_exact": self.refocuser.cheap_error_db if self.refocuser else None},
                "jpeg_hance": {"mode": self.config.hance,
                               "ran": bool(self.decoder is not None and self.decoder.uses_hance)},
            },
            "interrupted": self.interrupted,
            "outputs": self.sink.files if self.sink is not None else [],
        }
        ssim_of = dict(self._ssim)
        for row in out["per_frame"]:
            k = row["frame"]
            if k in self._frame_bpp:
                row["bpp"] = round(self._frame_bpp[k], 6)
            if k in ssim_of:
                row["mssim"] = round(ssim_of[k], 6)
            if k in self._stack_psnr:
                row["stack_psnr"] = round(self._stack_psnr[k], 4)
        return out


class _LazyTcpSender:
    """Connects when the encoder sends the header (the loopback receiver is listening)."""

    def __init__(self, host: str, port: int) -> None:
        self._addr = (host, port)
        self._sender = None

    def send_header(self, header) -> None:
        from lfstream.transport import TcpSender

        self._sender = TcpSender(*self._addr)
        self._sender.send_header(header)

    def send(self, packet, stop=None) -> bool:
        return self._sender.send(packet, stop)

    def close(self, stop=None) -> None:
        if self._sender is not None:
            self._sender.close(stop)


def default_output(base: str = "lfstream-out") -> Path:
    """A fresh output folder name in the current directory (never an existing one)."""
    p = Path(base)
    k = 1
    while p.exists():
        p = Path(f"{base}-{k}")
        k += 1
    return p


def prepare_output(out: Path, overwrite: bool = False) -> Path:
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not overwrite)):
        raise LFFileError(f"{out}: exists and is not an empty folder (choose another -o)")
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_summary(out: Path, summary: dict) -> None:
    tmp = out / ".summary.json.tmp"
    tmp.write_text(json.dumps(summary, indent=2, default=str))
    tmp.replace(out / "summary.json")


def stderr_progress(line: str) -> None:
    sys.stderr.write("\r" + line[:200].ljust(120))
    sys.stderr.flush()


__all__ = ["StreamConfig", "Pipeline", "PipelineError", "Refocuser", "Sink", "synthetic_source", "file_source",
           "default_output", "prepare_output", "write_summary", "REFOCUS_MODES", "TRANSPORTS", "SAVE_KINDS"]
