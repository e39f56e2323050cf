"""What the subcommands share: argument types with ranges from the library's constants,
the reading options, and the one way a result is printed (strict JSON or text)."""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from lfstream.io.readers import ReadOptions


def path_arg(text: str) -> Path:
    """A path argument; an empty one is refused (``Path("")`` would be the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path")
    return Path(text)


def one_output(args: argparse.Namespace) -> Path:
    """The output of a command that takes it as ``-o`` or, in its older form, positionally."""
    from lfstream.errors import LFValueError

    given = [p for p in (getattr(args, "output", None), getattr(args, "output_pos", None)) if p is not None]
    if not given:
        raise LFValueError("-o/--output: name the output")
    if len(given) == 2 and given[0] != given[1]:
        raise LFValueError(f"two outputs given ({given[1]} and -o {given[0]}); give one")
    return given[0]


def parse_grid(text: str, what: str = "grid", example: str = "7x7") -> tuple[int, int]:
    """Parses ``UxV`` (or ``N``) into a view grid (``what``/``example``: the message's words)."""
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must look like {example}, got {text!r}") from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"{what} must look like {example}, got {text!r}")
    return parts[0], parts[1]


def parse_size(text: str) -> tuple[int, int]:
    """Parses ``HxW``."""
    return parse_grid(text, "size (HxW)", "375x540")


def parse_float_list(text: str) -> list[float]:
    """Parses ``0.5,1,2`` (commas or spaces) into numbers."""
    try:
        values = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of numbers, got {text!r}") from None
    if not values or not all(math.isfinite(x) for x in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def int_in(bounds: tuple[int, int]) -> Callable[[str], int]:
    """An argparse type: an integer within ``bounds`` (inclusive), taken from the library."""
    lo, hi = bounds

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer in {lo}..{hi}, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo}..{hi}, got {value}")
        return value

    parse.__name__ = f"integer {lo}..{hi}"
    return parse


def float_in(lo: float, hi: float) -> Callable[[str], float]:
    """An argparse type: a finite number within ``[lo, hi]``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number in {lo:g}..{hi:g}, got {text!r}") from None
        if not (math.isfinite(value) and lo <= value <= hi):
            raise argparse.ArgumentTypeError(f"must be in {lo:g}..{hi:g}, got {text}")
        return value

    parse.__name__ = f"number {lo:g}..{hi:g}"
    return parse


def add_coding_options(p: argparse.ArgumentParser) -> None:
    """How ``encode`` and ``stream`` code a light field: ``--quality`` or ``--bpp``,
    ``--preset``, ``--residual``, ``--residual-mode``, ``--hance-map`` (one wording for both)."""
    from lfstream.codec.centre.jpeg import QUALITY_RANGE
    from lfstream.codec.encoder import PRESETS
    from lfstream.codec.residual import RESIDUAL_MODES

    rate = p.add_mutually_exclusive_group()
    rate.add_argument("--quality", type=int_in(QUALITY_RANGE), default=50, help="quality of the centre view (default 50)")
    rate.add_argument("--bpp", type=float_in(1e-5, 24), help="target size in bits per pixel: rate control on the first "
                      "frame picks the preset (unless --preset), quality, hint and residual from a model of bits "
                      "against quality, then follows the running budget")
    p.add_argument("--preset", choices=tuple(PRESETS), help="centre-view coding: fast (JPEG), balanced "
                   "(AV1, SVT preset 12), best (AV1, SVT preset 8). Default: fast from 7x7 views up, balanced "
                   "below, best up to 3x3, and the views as one AV1 sequence where the first frame shows that "
                   "warping cannot predict them; --bpp with fast searches only the quality: tens of ms")
    p.add_argument("--residual", type=int_in(QUALITY_RANGE), metavar="Q",
                   help="quality 1..100 of the residual layer: every view's prediction error coded as one AV1 "
                   "sequence (more bits, quality that keeps rising with rate; default: none, --bpp decides itself)")
    p.add_argument("--residual-mode", choices=RESIDUAL_MODES, default="prediction",
                   help="what the residual layer codes: prediction (the prediction's error, the default), views "
                   "(the views themselves: for scenes warping cannot predict; no warp at decode; with "
                   "--preset balanced|best and --residual equal to --quality the centre view is the views "
                   "sequence's key frame) or half-views (the same at half size, for the lowest rates)")
    p.add_argument("--hance-map", action="store_true",
                   help="send a JPEG-Hance strength map with each JPEG centre view, measured by the encoder on "
                   "the decoded light field (on key frames a decode, the network and a warp per strength; a few "
                   "ms the frames between); decoding with --hance auto (the default) or on then blends the "
                   "network's correction by it")


def add_read_options(p: argparse.ArgumentParser) -> None:
    """Options every command that reads a light field shares (:class:`ReadOptions`)."""
    from lfstream.lightfield import MAX_VIEWS_PER_AXIS

    g = p.add_argument_group("reading")
    g.add_argument("--angular", type=int_in((1, MAX_VIEWS_PER_AXIS)),
                   help="microlens size in pixels of a lenslet (ESLF) image (Lytro Illum: 14)")
    g.add_argument("--views", "--crop", dest="crop", type=int_in((1, MAX_VIEWS_PER_AXIS)),
                   help="keep the central N x N views")
    g.add_argument("--grid", type=parse_grid, help="view grid UxV of a mosaic image or video without metadata")
    g.add_argument("--flip-u", action="store_true", help="reverse the order of view rows")
    g.add_argument("--flip-v", action="store_true", help="reverse the order of view columns")
    g.add_argument("--allow-missing", action="store_true", help="load a folder with missing views, with a mask")
    g.add_argument("--max-frames", type=int_in((1, 1 << 30)), help="read at most this many frames")
    add_first_frame(g)


def add_first_frame(p) -> None:
    """``--first-frame N``: where a command starts reading an LF video (with ``--max-frames``, a range)."""
    p.add_argument("--first-frame", type=int_in((0, 1 << 30)), default=0,
                   help="start at this frame of a video (0: the first; the frames before are skipped, decoding "
                   "as little of them as the format allows)")


def read_options(args: argparse.Namespace) -> ReadOptions:
    """The :class:`ReadOptions` the reading flags describe."""
    return ReadOptions(angular=args.angular, crop=args.crop, grid=args.grid, flip_u=args.flip_u, flip_v=args.flip_v,
                       allow_missing=args.allow_missing, max_frames=args.max_frames, first_frame=args.first_frame)


def load_from_args(args: argparse.Namespace):
    """The :class:`~lfstream.io.LoadedLF` of ``args.input`` read with the reading flags."""
    from lfstream.io.readers import load_lf

    return load_lf(args.input, read_options(args))


@dataclasses.dataclass
class InputFrames:
    """A command's input as frames (:func:`read_input`).

    Attributes:
        first: frame 0 ``(U, V, H, W, C)`` (the encoder's check and the refocus's view axes
            look at it first).
        frames: every frame in order, frame 0 included.
        count: how many (``None`` where an LF video read frame by frame does not say).
        whole: the ``(T, U, V, H, W, C)`` array where the input was read whole, else ``None``.
        present: ``(U, V)`` mask of the views that exist, ``None`` for all.
        fps: the input's frame rate, if it records one.
        disparity: the input's ground-truth disparity where it was read whole with one
            (a ``.npz`` of :func:`lfstream.io.write_lf`'s, the range's frames; a still's with
            a leading frame axis, as ``whole`` has), else ``None``.
    """

    first: np.ndarray
    frames: Iterable[np.ndarray]
    count: int | None
    whole: np.ndarray | None
    present: np.ndarray | None
    fps: float | None
    disparity: np.ndarray | None = None


def read_input(args: argparse.Namespace, whole: bool = False, count_frames: bool = False) -> InputFrames:
    """``args.input`` read with the reading flags: an LF video (a mosaic video, an ``.lfs``)
    frame by frame (:func:`lfstream.io.open_video_lf`: one 30 MB frame of 7x7x375x540 in
    memory, not the whole video; ``count_frames``: its frames counted where the container
    keeps no count) unless the caller needs it ``whole``; anything else read whole.

    Raises:
        LFStreamError: what the readers raise; a video without a frame.
    """
    from lfstream.errors import LFFormatError
    from lfstream.io import open_video_lf, reads_lazily
    from lfstream.lightfield import check_lf

    if not whole and reads_lazily(args.input):
        video = open_video_lf(args.input, read_options(args), count_frames=count_frames)
        first = next(video.frames, None)
        if first is None:
            raise LFFormatError(f"{args.input}: contains no frames")
        check_lf(first)  # checked as a light field read whole is
        return InputFrames(first, itertools.chain([first], video.frames), video.count, None, video.present, video.fps)
    loaded = load_from_args(args)  # with --allow-missing, only the centre view must exist
    check_lf(loaded.lf)
    still = loaded.lf.ndim == 5
    lf = loaded.lf[None] if still else loaded.lf
    disparity = loaded.disparity  # a still's map goes with it into the one-frame video
    disparity = disparity[None] if still and disparity is not None else disparity
    return InputFrames(lf[0], lf, len(lf), lf, loaded.present, loaded.fps, disparity)


class _SigtermRelay:
    """The SIGTERM handler of :func:`sigterm_as_ctrl_c`; ``came`` records that it fired."""

    def __init__(self) -> None:
        self.came: list[int] = []

    def __call__(self, signum, frame) -> None:
        self.came.append(signum)
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):
            handler(signal.SIGINT, frame)
        else:  # SIGINT ignored (a background job) or left to the system: stop as Ctrl-C would
            raise KeyboardInterrupt


@contextmanager
def sigterm_as_ctrl_c() -> Iterator[list[int]]:
    """SIGTERM handled exactly as Ctrl-C: it calls whatever SIGINT handler is in force (the
    default raises KeyboardInterrupt; a block that must finish a frame first defers it), so
    every command finalises its outputs and removes its temporary files the same way. Yields
    a list that holds SIGTERM once it came. Main thread only (elsewhere a no-op)."""
    relay = _SigtermRelay()
    if threading.current_thread() is not threading.main_thread():
        yield relay.came
        return
    previous = signal.signal(signal.SIGTERM, relay)
    try:
        yield relay.came
    finally:
        signal.signal(signal.SIGTERM, previous)


def _deferrable_signals() -> list[int]:
    """The stop signals a block may hold back: Ctrl-C where Python's own handler raises it,
    SIGTERM where the CLI relays it as Ctrl-C (:func:`sigterm_as_ctrl_c`)."""
    if threading.current_thread() is not threading.main_thread():
        return []
    out = []
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        out.append(signal.SIGINT)
    if isinstance(signal.getsignal(signal.SIGTERM), _SigtermRelay):
        out.append(signal.SIGTERM)
    return out


@contextmanager
def interrupt_after() -> Iterator[None]:
    """Ctrl-C (or SIGTERM) inside the block takes effect when it ends, so what the block
    writes (one frame's outputs, a file being finalised) is written whole."""
    signals = _deferrable_signals()
    if not signals:
        yield
        return
    caught: list[int] = []
    previous = {sig: signal.signal(sig, lambda signum, frame: caught.append(signum)) for sig in signals}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if caught:
        previous[caught[0]](caught[0], None)  # Python's handler, or the relay: raises KeyboardInterrupt
        raise KeyboardInterrupt


#: Exit statuses of a run stopped by Ctrl-C (SIGINT) and by SIGTERM: 128 + the signal.
EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143


class FrameBoundaryStop:
    """Ctrl-C (and SIGTERM, which the CLI relays as Ctrl-C) inside the block stops
    :meth:`frames` at the next frame boundary, so the frames already done are kept whole
    (an encode's stream of them is finalised); a second Ctrl-C stops at once. Only where
    Ctrl-C raises KeyboardInterrupt (Python's own handler, in the main thread)."""

    def __init__(self) -> None:
        self.stopped = False
        self.signal: int | None = None
        self._previous: dict | None = None

    def __enter__(self) -> FrameBoundaryStop:
        self._previous = {sig: signal.signal(sig, self._handle) for sig in _deferrable_signals()}
        return self

    def _handle(self, signum, frame) -> None:
        if self.stopped:  # asked twice: now
            raise KeyboardInterrupt
        self.stopped = True
        self.signal = signum

    def __exit__(self, *exc) -> None:
        for sig, handler in (self._previous or {}).items():
            signal.signal(sig, handler)
        relay = (self._previous or {}).get(signal.SIGTERM)
        if self.stopped and self.signal == signal.SIGTERM and isinstance(relay, _SigtermRelay):
            relay.came.append(signal.SIGTERM)  # for the exit status: stopped by SIGTERM

    def frames(self, frames: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
        """``frames`` until a stop was asked for."""
        for frame in frames:
            if self.stopped:
                return
            yield frame
            if self.stopped:
                return


def coding_layers(depth_hint: bool, residual: int | None, residual_mode: str | None,
                  hint_scale: int | None = None) -> str:
    """The layers of a stream beside its centre view, as the text outputs print them:
    `` + hint 1/8 + residual q40 (views)`` (the hint's resolution where it is known)."""
    hint = (" + hint" + (f" 1/{hint_scale}" if hint_scale else "")) if depth_hint else ""
    return hint + (f" + residual q{residual} ({residual_mode})" if residual is not None else "")


def _json_default(o: object):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def strict_json(obj: object) -> object:
    """``obj`` with every non-finite float replaced by ``None`` and the reason beside it in a
    ``KEY_note`` entry (``+inf`` PSNR: identical images), so the output is RFC 8259 JSON."""
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            out[k] = strict_json(v)
            if isinstance(v, (float, np.floating)) and not math.isfinite(v):
                out[f"{k}_note"] = "infinite (identical images)" if v > 0 else "not finite"
            elif isinstance(v, (list, tuple, np.ndarray)) and any(
                    isinstance(x, (float, np.floating)) and not math.isfinite(x) for x in np.ravel(np.asarray(v, object))):
                out[f"{k}_note"] = "null entries are infinite (identical images) or not finite"
        return out
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return strict_json(obj.tolist())
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def emit(args: argparse.Namespace, result: dict, text: Callable[[dict], str] | str) -> None:
    """Prints ``result`` as one strict JSON object under ``--json``, else ``text(result)``."""
    if getattr(args, "json", False):
        print(json.dumps(strict_json(result), indent=2, default=_json_default, allow_nan=False))
    else:
        print(text(result) if callable(text) else text)


__all__ = ["parse_grid", "parse_size", "parse_float_list", "int_in", "float_in", "add_read_options", "add_first_frame",
           "read_options", "load_from_args", "InputFrames", "read_input", "emit", "interrupt_after"]
