"""What ``stream`` and ``serve`` share: the pipeline flags, the config they build, the report."""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from lfstream.cli._common import coding_layers, emit, float_in, int_in, parse_float_list, path_arg
from lfstream.codec.decoder import BATCH_RANGE, DEPTH_MODES, HANCE_MODES, NETWORK_PRESETS
from lfstream.stream.config import FOCUS_MODES, QUEUE_RANGE, REFOCUS_MODES, SAVE_KINDS, StreamConfig


def parse_focus(text: str) -> str | tuple[float, ...]:
    """``auto``, ``seed`` or a comma list of alphas."""
    return text if text in FOCUS_MODES else tuple(parse_float_list(text))


def add_pipeline_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", type=path_arg, help="output folder (default: a new ./lfstream-out[-N])")
    p.add_argument("--overwrite", action="store_true",
                   help="write into an -o folder that already holds files (its files of the same names are replaced)")
    p.add_argument("--refocus", choices=REFOCUS_MODES, default="auto",
                   help="focal-stack renderer (auto: picked per device by measured speed and error)")
    p.add_argument("--alphas", type=parse_focus, default="auto", metavar="auto|seed|A,B,...",
                   help="focal planes: auto (default: the scene's own disparity range, planes a depth of field "
                        "apart), seed (the seed's 0.125 ... 2.0) or a list of alphas")
    p.add_argument("--device", default="cpu", help="where the networks run: cpu or cuda")
    p.add_argument("--batch", type=int_in(BATCH_RANGE), default=1, help="frames per network batch in the decoder")
    p.add_argument("--depth", choices=DEPTH_MODES, default="auto",
                   help="per-view disparity at the decoder: auto (what the stream carries), hint, flat or net "
                   "(Depth-Net: refines the hint; on a stream without one, the seed's path: the disparity from the "
                   "restored centre view)")
    p.add_argument("--hance", choices=HANCE_MODES, default="auto",
                   help="JPEG-Hance on the centre view: auto (by the stream's strength maps and the device), on or off")
    p.add_argument("--networks", choices=NETWORK_PRESETS, default="fast",
                   help="the decoder's networks' shipped weights: fast, or paper (JPEG-Hance at the seed's size)")
    cam = p.add_argument_group("camera (optional: each focal plane then records its refocus distance)")
    cam.add_argument("--focal-length", type=float_in(1e-3, 1e6), metavar="MM", help="main-lens focal length")
    cam.add_argument("--f-number", type=float_in(0.1, 1000), help="main-lens f-number")
    cam.add_argument("--microlenses", type=int_in((1, 1 << 20)), metavar="M", help="microlenses per axis")
    cam.add_argument("--pixels-per-lens", type=int_in((1, 64)), metavar="N", help="pixels per axis under a microlens")
    p.add_argument("--save", default="mp4", help=f"comma list of {', '.join(SAVE_KINDS)} "
                   "(mp4: one per focal plane)")
    p.add_argument("--no-skip-static", action="store_true", help="always recompute the disparity")
    p.add_argument("--mssim-every", type=int_in((0, 1 << 30)), default=StreamConfig.mssim_every,
                   help="MSSIM on every N-th frame, from frame 0 (default: once a second of 30 fps video; 0: "
                        "never; MPSNR on all); the summary lists the frames in mssim_frames")
    p.add_argument("--queue-size", type=int_in(QUEUE_RANGE), default=4,
                   help="frames each bounded queue between two stages holds (default 4)")
    p.add_argument("--no-viewer", action="store_true", help="do not write index.html (click-to-focus page)")
    p.add_argument("--progress", action="store_true", help="a status line on stderr (default when it is a terminal)")
    p.add_argument("--json", action="store_true", help="print the run's summary as one JSON object")


@contextlib.contextmanager
def single_threaded_opencv() -> Iterator[None]:
    """OpenCV calls run on one thread while a pipeline runs, as before afterwards.

    The pipeline's stages already keep the cores busy; OpenCV's own pool then only doubles
    the CPU its calls cost (its workers wait actively) without shortening them: measured on
    the 2-core development machine, the sink's 13 colour conversions a frame 13-17 -> 7 ms
    of CPU at the same wall time, the encoder 72-75 -> 62-68 ms of CPU a frame. A process
    setting: the command decides it, not the library."""
    import cv2

    from lfstream.codec.workers import single_thread

    with single_thread(cv2.getNumThreads, cv2.setNumThreads):
        yield


@contextlib.contextmanager
def frozen_garbage_collector() -> Iterator[Callable[[], None]]:
    """Yields the ``on_warm`` of a :class:`~lfstream.stream.Pipeline` that collects once and
    then freezes every object alive (the modules, the kernels, the networks), so that the
    stream's garbage collections no longer walk them; unfrozen afterwards.

    With torch and numba loaded a full collection walks hundreds of thousands of objects that
    live as long as the process, and the stream's allocations set one off every few frames
    (measured on the docs' experiments page). A process setting: the command decides it."""
    import gc

    def freeze() -> None:
        gc.collect()
        gc.freeze()

    try:
        yield freeze
    finally:
        gc.unfreeze()


def check_output_folder(out: Path | None) -> None:
    """``-o`` of ``stream``/``serve`` names a folder: a name with a file extension is almost
    certainly a mistake (``-o out.mp4``), refused before anything is created."""
    if out is not None and out.suffix and not out.is_dir():
        from lfstream.errors import LFValueError

        raise LFValueError(f"-o {out}: the output is a folder (it receives {', '.join(SAVE_KINDS)} outputs and "
                           f"summary.json); give a name without the extension {out.suffix!r}")


def camera_from_args(args: argparse.Namespace):
    """The :class:`~lfstream.optics.PlenopticCamera` the camera flags describe, or ``None``."""
    given = [args.focal_length, args.f_number, args.microlenses, args.pixels_per_lens]
    if not any(x is not None for x in given):
        return None
    if any(x is None for x in given):
        from lfstream.errors import LFValueError

        raise LFValueError("--focal-length, --f-number, --microlenses and --pixels-per-lens go together "
                           "(the camera that captured the input)")
    from lfstream.optics import PlenopticCamera

    return PlenopticCamera(focal_length_mm=args.focal_length, f_number=args.f_number, microlenses=args.microlenses,
                           pixels_per_lens=args.pixels_per_lens)


def pipeline_config(args: argparse.Namespace, **extra) -> StreamConfig:
    """The :class:`StreamConfig` the flags describe (``extra``: fields only ``stream`` sets)."""
    cfg = StreamConfig(camera=camera_from_args(args), refocus=args.refocus, alphas=args.alphas, device=args.device,
                       batch=args.batch, depth=args.depth,
                       hance=args.hance, networks=args.networks,
                       save=tuple(s for s in args.save.split(",") if s), skip_static=not args.no_skip_static,
                       mssim_every=args.mssim_every, queue_size=args.queue_size, **extra)
    cfg.validate()
    return cfg


def progress_callback(args: argparse.Namespace):
    """The status-line printer, when asked for or when stderr is a terminal (never under --json)."""
    from lfstream.stream.report import stderr_progress

    return stderr_progress if (args.progress or (sys.stderr.isatty() and not args.json)) else None


#: Mosaic video formats whose decoding can be a stream's slowest stage (x264 RGB, FFV1, VP9),
#: and what a Ut Video ``.avi`` costs instead (bench/video_io.py, 7x7x375x540: 296 -> 63 ms
#: of CPU a noisy frame from .mp4, 488 from .mkv).
SLOW_TO_READ = (".mp4", ".mov", ".mkv", ".webm")


def _reading_note(summary: dict, source: Path | None) -> str | None:
    """A line for a stream whose slowest stage is reading a mosaic video that a Ut Video
    ``.avi`` would read several times faster; ``None`` otherwise."""
    stages = summary.get("stages", {})
    if source is None or Path(source).suffix.lower() not in SLOW_TO_READ or "producer" not in stages:
        return None
    slowest = max(stages, key=lambda name: stages[name]["ms_per_frame"] or 0)
    if slowest != "producer":
        return None
    return (f"  reading {source} was the slowest stage: a lossless .avi (Ut Video) decodes in a third to a fifth "
            f"of the CPU time (lfstream convert {source} {Path(source).with_suffix('.avi').name})")


def _text(summary: dict, out: Path | None, source: Path | None = None) -> str:
    lines = [f"{summary['frames']} frame(s), {summary['fps'] or 0} frames/s end to end"
             + (f", {summary['bpp']:.5f} bpp" if summary.get("bpp") else "")
             + (f", MPSNR {summary['mpsnr']:.2f} dB" if summary.get("mpsnr") is not None else "")
             + (f", MSSIM {summary['mssim']:.4f}" if summary.get("mssim") is not None else "")
             + f", lost {summary['lost']}" + (" (interrupted)" if summary.get("interrupted") else "")]
    for name, s in summary.get("stages", {}).items():
        lines.append(f"  {name:9s} {s['frames']:5d} frames  {s['ms_per_frame'] or 0:8.1f} ms/frame")
    c = summary.get("coding")
    if c:
        lines.append(f"  coding: {c['preset']} q{c['quality']}"
                     + coding_layers(c["depth_hint"], c["residual"], c["residual_mode"], c.get("hint_scale"))
                     + (" + JPEG-Hance strength maps" if c.get("hance_map") else "")
                     + (f"; the prediction checked at {c['prediction_db']:.1f} dB" if c.get("prediction_db") is not None
                        else ""))
    if summary.get("refocus"):
        lines.append(f"  refocus: {summary['refocus']['method']} ({summary['refocus']['why']})"
                     + (f"; the views reordered to the convention (view axes {summary['refocus']['view_axes']})"
                        if summary["refocus"].get("view_axes") else ""))
    note = _reading_note(summary, source)
    if note:
        lines.append(note)
    if out is not None:
        lines.append(f"  outputs in {out} (summary.json)")
    return "\n".join(lines)


def write_page(args: argparse.Namespace, summary: dict, out: Path | None) -> Path | None:
    """The click-to-focus page (``index.html``) for the run's planes, unless ``--no-viewer``
    or nothing was rendered; its path goes into the summary as ``viewer``."""
    if out is None or args.no_viewer or not summary.get("frames") or not summary.get("planes"):
        return None
    from lfstream.errors import LFStreamError
    from lfstream.viewer import write_viewer

    try:
        path = write_viewer(out, fps=summary.get("fps"))
    except LFStreamError as exc:  # e.g. --save without mp4/png: nothing to show
        summary["viewer"], summary["viewer_note"] = None, str(exc)
        return None
    summary["viewer"] = str(path)
    return path


def report(args: argparse.Namespace, summary: dict, out: Path | None) -> None:
    """Writes ``summary.json`` into ``out`` and prints the summary (JSON or text)."""
    from lfstream.stream.report import write_summary

    if out is not None:
        write_summary(out, summary)
    if not args.json:
        sys.stderr.write("\n")
    emit(args, summary, lambda s: _text(s, out, getattr(args, "input", None)))


__all__ = ["add_pipeline_options", "check_output_folder", "pipeline_config", "progress_callback",
           "report", "single_threaded_opencv", "write_page"]
