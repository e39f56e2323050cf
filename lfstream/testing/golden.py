"""Golden files: per-frame digests and metric references a test suite checks against.

A golden file (JSON, ``"format": "lfstream-golden"``, version 1) records for every frame of
an input the SHA-256 of its samples and, where a reference was given, its metrics against
that reference (MPSNR, MSSIM, the worst view's PSNR, the largest difference), with the
lfstream version and the settings that made it, and the tolerances a check applies. Any
other per-frame measurements (a pipeline's bits per pixel, say) can be recorded beside them
(:func:`golden_from_rows`).

A check classifies every frame:

- ``identical``: the same digest;
- ``changed``: other bytes, but every recorded metric within its tolerance (or better);
- ``regressed``: a metric worse than its golden value by more than its tolerance, a threshold
  missed, the bytes changed where no metric can say by how much (a golden without a
  reference), or the frame missing;
- ``moved``: with ``strict``, a metric better by more than its tolerance (the golden no
  longer describes the code; re-record it deliberately).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lfstream.errors import LFFormatError, LFValueError
from lfstream.testing.compare import FrameMetrics, Thresholds, frame_metrics, judge, open_frames

FORMAT = "lfstream-golden"
VERSION = 1
#: Frame statuses a check reports, best first.
STATUSES = ("identical", "changed", "moved", "regressed")
#: For each metric the recorder knows: whether a higher value is better.
HIGHER_IS_BETTER = {"mpsnr": True, "mssim": True, "worst_view_psnr": True, "max_abs": False, "bpp": False,
                    "stack_psnr": True}
#: Default tolerances of the metrics :func:`record` measures: absolute, in each metric's unit.
DEFAULT_TOLERANCE = {"mpsnr": {"abs": 0.05}, "mssim": {"abs": 1e-3}, "worst_view_psnr": {"abs": 0.1},
                     "max_abs": {"abs": 2.0}}


def frame_digest(frame: np.ndarray) -> str:
    """SHA-256 of a frame's shape, dtype and samples (C order)."""
    a = np.ascontiguousarray(frame)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(memoryview(a).cast("B"))
    return h.hexdigest()


@dataclass
class GoldenFrame:
    """One frame of a golden file.

    Attributes:
        frame: its number in the source.
        sha256: :func:`frame_digest` of its samples, or ``None`` where not recorded.
        metrics: metric name -> value.
    """

    frame: int
    sha256: str | None = None
    metrics: dict[str, float] = field(default_factory=dict)


@dataclass
class Golden:
    """A golden file's content.

    Attributes:
        frames: one :class:`GoldenFrame` per frame, in order.
        tolerance: metric -> ``{"abs": x}`` or ``{"rel": x}``.
        views, size: the input's view grid and view size (``None``: not recorded).
        reference: the reference the metrics were measured against, as given.
        lfstream: the version that recorded it.
        settings: what made it (reading options, a pipeline's configuration, ...).
    """

    frames: list[GoldenFrame]
    tolerance: dict[str, dict[str, float]] = field(default_factory=dict)
    views: tuple[int, int] | None = None
    size: tuple[int, int] | None = None
    reference: str | None = None
    lfstream: str = ""
    settings: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "lfstream": self.lfstream, "settings": self.settings,
                "reference": self.reference, "views": list(self.views) if self.views else None,
                "size": list(self.size) if self.size else None, "tolerance": self.tolerance,
                "frames": [asdict(f) for f in self.frames]}

    def write(self, path: str | os.PathLike, overwrite: bool = False) -> Path:
        """Writes the file atomically; refuses to replace one unless ``overwrite``."""
        from lfstream.io._fs import atomic_write_text, check_new_file

        path = check_new_file(path, overwrite)
        atomic_write_text(path, json.dumps(self.to_json(), indent=1, allow_nan=False) + "\n")
        return path


def load_golden(path: str | os.PathLike) -> Golden:
    """Reads a golden file, naming it in any error."""
    from lfstream.errors import LFFileError

    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise LFFileError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LFFormatError(f"{path}: not a golden file (not JSON: {exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise LFFormatError(f"{path}: not a golden file (no \"format\": \"{FORMAT}\")")
    if doc.get("version") != VERSION:
        raise LFFormatError(f"{path}: golden file version {doc.get('version')!r}; this lfstream reads {VERSION}")
    try:
        frames = [GoldenFrame(int(f["frame"]), f.get("sha256"), {k: float(v) for k, v in f.get("metrics", {}).items()})
                  for f in doc["frames"]]
        views = tuple(doc["views"]) if doc.get("views") else None
        size = tuple(doc["size"]) if doc.get("size") else None
        tolerance = {k: {kk: float(vv) for kk, vv in v.items()} for k, v in doc.get("tolerance", {}).items()}
    except (KeyError, TypeError, ValueError) as exc:
        raise LFFormatError(f"{path}: damaged golden file ({exc!r})") from exc
    return Golden(frames, tolerance, views, size, doc.get("reference"), doc.get("lfstream", ""),
                  doc.get("settings") or {})


def _metric_row(m: FrameMetrics) -> dict[str, float]:
    from lfstream.metrics import PSNR_CAP_DB

    u, v = m.worst_view
    return {"mpsnr": min(m.mpsnr, PSNR_CAP_DB), "mssim": m.mssim,
            "worst_view_psnr": min(float(m.psnr[u, v]), PSNR_CAP_DB), "max_abs": m.max_abs}


def record(source, reference=None, options=None, settings: dict | None = None,
           tolerance: dict[str, dict[str, float]] | None = None) -> Golden:
    """Records a golden of ``source`` (an array or any path lfstream reads), frame by frame.

    Args:
        source: the light field or LF video whose frames the golden pins.
        reference: where given, each frame's metrics against it are recorded too (the
            original a decoder's output is judged against, say).
        options: :class:`~lfstream.io.ReadOptions` for the paths.
        settings: recorded as they are (what made ``source``).
        tolerance: per metric, overriding :data:`DEFAULT_TOLERANCE`.
    """
    from lfstream.version import __version__

    src = open_frames(source, options)
    ref = open_frames(reference, options) if reference is not None else None
    if ref is not None and (ref.views != src.views or ref.size != src.size):
        from lfstream.errors import LFShapeError

        raise LFShapeError(f"{src.name} is {src.views} views of {src.size}, the reference {ref.name} "
                           f"{ref.views} of {ref.size}")
    frames = []
    ref_frames = iter(ref.frames) if ref is not None else None
    for k, frame in enumerate(src.frames):
        gf = GoldenFrame(src.first_frame + k, frame_digest(frame))
        if ref_frames is not None:
            expected = next(ref_frames, None)
            if expected is None:
                from lfstream.errors import LFShapeError

                raise LFShapeError(f"the reference {ref.name} ends after {k} frames, {src.name} goes on")
            gf.metrics = _metric_row(frame_metrics(expected, frame, src.present))
        frames.append(gf)
    tol = {**DEFAULT_TOLERANCE, **(tolerance or {})} if ref is not None else dict(tolerance or {})
    return Golden(frames, tol, src.views, src.size, None if reference is None else str(reference), __version__,
                  settings or {})


def golden_from_rows(rows: Sequence[dict], tolerance: dict[str, dict[str, float]], settings: dict | None = None,
                     digests: Sequence[str] | None = None) -> Golden:
    """A golden of measurements made elsewhere: ``rows`` of ``{"frame": k, metric: value, ...}``
    (a pipeline's per-frame summary, say), with ``digests`` of the frames where known."""
    from lfstream.version import __version__

    frames = [GoldenFrame(int(r["frame"]), digests[i] if digests else None,
                          {k: float(v) for k, v in r.items() if k != "frame"}) for i, r in enumerate(rows)]
    return Golden(frames, dict(tolerance), lfstream=__version__, settings=settings or {})


@dataclass(frozen=True)
class FrameCheck:
    """One frame's verdict in a golden check.

    Attributes:
        frame: its number.
        status: one of :data:`STATUSES`.
        reasons: what moved, one phrase each.
        metrics: the values measured now.
    """

    frame: int
    status: str
    reasons: tuple[str, ...] = ()
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.status in ("identical", "changed")


@dataclass
class GoldenReport:
    """Every frame's :class:`FrameCheck`."""

    frames: list[FrameCheck]

    @property
    def passed(self) -> bool:
        return all(f.passed for f in self.frames)

    def frames_with(self, status: str) -> list[int]:
        return [f.frame for f in self.frames if f.status == status]

    def to_json(self) -> dict:
        return {"passed": self.passed, **{s: self.frames_with(s) for s in STATUSES},
                "failed_frames": [f.frame for f in self.frames if not f.passed],
                "frames": [{"frame": f.frame, "status": f.status, "reasons": list(f.reasons),
                            "metrics": f.metrics} for f in self.frames]}


def _limit(tol: dict[str, float], golden: float) -> float:
    return tol.get("abs", 0.0) + tol.get("rel", 0.0) * abs(golden)


def judge_values(golden: GoldenFrame, now: dict[str, float], tolerance: dict[str, dict[str, float]],
                 strict: bool = False) -> tuple[str, list[str]]:
    """Compares one frame's measured metrics with its golden values: ``(status, reasons)``
    with status ``changed``, ``moved`` or ``regressed``."""
    status, reasons = "changed", []
    for name, want in golden.metrics.items():
        if name not in now:
            return "regressed", [f"{name} not measured"]
        got = now[name]
        limit = _limit(tolerance.get(name, {}), want)
        delta = got - want
        if not math.isfinite(got) or abs(delta) > limit:
            worse = (delta < 0) == HIGHER_IS_BETTER.get(name, True) or not math.isfinite(got)
            reasons.append(f"{name} {got:.6g} against golden {want:.6g} (tolerance {limit:.3g})")
            if worse:
                status = "regressed"
            elif strict and status != "regressed":
                status = "moved"
    return status, reasons


def check_values(golden: Golden, rows: Sequence[dict], strict: bool = True) -> GoldenReport:
    """Checks measurements made elsewhere (``rows`` as :func:`golden_from_rows` takes them)
    against ``golden``; missing or extra frames regress."""
    by_frame = {int(r["frame"]): r for r in rows}
    out = []
    for gf in golden.frames:
        row = by_frame.pop(gf.frame, None)
        if row is None:
            out.append(FrameCheck(gf.frame, "regressed", ("frame missing",)))
            continue
        now = {k: float(v) for k, v in row.items() if k != "frame"}
        status, reasons = judge_values(gf, now, golden.tolerance, strict)
        out.append(FrameCheck(gf.frame, status, tuple(reasons), now))
    out += [FrameCheck(k, "regressed", ("frame not in the golden",)) for k in sorted(by_frame)]
    return GoldenReport(out)


def check(source, golden: Golden, reference=None, options=None, thresholds: Thresholds | None = None,
          strict: bool = False, on_frame=None) -> GoldenReport:
    """Checks every frame of ``source`` against ``golden``.

    Args:
        source: the light field or LF video to check (an array or a path).
        golden: what :func:`record` made.
        reference: the reference for the metrics (default: the golden's own, where it
            recorded one and the path exists).
        options: :class:`~lfstream.io.ReadOptions` for the paths.
        thresholds: absolute floors a frame must also meet against the reference.
        strict: a metric *better* than its golden value by more than the tolerance is
            ``moved`` (a failure) rather than ``changed``.
        on_frame: called with each :class:`FrameCheck` as it is made.
    """
    src = open_frames(source, options)
    if golden.views is not None and (tuple(golden.views) != src.views or tuple(golden.size) != src.size):
        from lfstream.errors import LFShapeError

        raise LFShapeError(f"{src.name} is {src.views[0]}x{src.views[1]} views of {src.size[0]}x{src.size[1]}; "
                           f"the golden was recorded on {golden.views[0]}x{golden.views[1]} of "
                           f"{golden.size[0]}x{golden.size[1]}")
    ref_src = None
    has_metrics = any(f.metrics for f in golden.frames)
    if reference is None and has_metrics and golden.reference and Path(golden.reference).exists():
        reference = golden.reference
    if reference is not None:
        ref_src = open_frames(reference, options)
    elif has_metrics:
        raise LFValueError("this golden records metrics against a reference: give it (--reference)")
    ref_frames = iter(ref_src.frames) if ref_src is not None else None
    expected = {f.frame: f for f in golden.frames}
    out = []
    for k, frame in enumerate(src.frames):
        number = src.first_frame + k
        gf = expected.pop(number, None)
        ref_frame = next(ref_frames, None) if ref_frames is not None else None
        if gf is None:
            result = FrameCheck(number, "regressed", ("frame not in the golden",))
        elif gf.sha256 == frame_digest(frame):
            result = FrameCheck(number, "identical")
        elif not gf.metrics or ref_frame is None:
            result = FrameCheck(number, "regressed", ("bytes changed; the golden has no reference to say by how much",))
        else:
            m = frame_metrics(ref_frame, frame, src.present)
            now = _metric_row(m)
            status, reasons = judge_values(gf, now, golden.tolerance, strict)
            if thresholds is not None and not thresholds.exact:
                verdict = judge(number, m, thresholds)
                if not verdict.passed:
                    status, reasons = "regressed", [*reasons, *verdict.failures]
            result = FrameCheck(number, status, tuple(reasons), now)
        out.append(result)
        if on_frame is not None:
            on_frame(result)
    # frames the golden has and the source lacks (only those in its range, where one was asked)
    last = src.first_frame + len(out)
    for number, _ in sorted(expected.items()):
        if number >= src.first_frame and (options is None or options.max_frames is None or number < last):
            out.append(FrameCheck(number, "regressed", ("frame missing",)))
    return GoldenReport(out)


def read_rows(path: str | os.PathLike) -> list[dict]:
    """The per-frame rows of a golden file as :func:`check_values` takes them."""
    return [{"frame": f.frame, **f.metrics} for f in load_golden(path).frames]


__all__ = ["FORMAT", "VERSION", "STATUSES", "DEFAULT_TOLERANCE", "Golden", "GoldenFrame", "GoldenReport", "FrameCheck",
           "frame_digest", "record", "check", "check_values", "golden_from_rows", "load_golden", "judge_values",
           "read_rows"]
