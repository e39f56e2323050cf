"""Frame-by-frame comparison of two light fields or LF videos.

:func:`frame_metrics` measures one pair of frames (per-view PSNR and SSIM, the largest
absolute difference); :func:`compare` walks two inputs in step — arrays, or any path
lfstream reads, videos and ``.lfs`` streams decoded one frame at a time — and yields a
:class:`FrameResult` per frame, judged against :class:`Thresholds`; :func:`compare_report`
collects them into a :class:`ComparisonReport`. Memory stays that of a few frames however
long the video: a ``.npy`` is memory-mapped, videos are decoded lazily.

Metrics come from :mod:`lfstream.metrics`: PSNR on 8-bit levels, SSIM as Wang et al. 2004
with an 11x11 Gaussian window (sigma 1.5) over the valid region, per channel and averaged,
as scikit-image's ``structural_similarity(gaussian_weights=True, sigma=1.5,
use_sample_covariance=False)``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lfstream.errors import LFFormatError, LFShapeError, LFValueError
from lfstream.lightfield import check_lf
from lfstream.metrics import PSNR_CAP_DB

#: Where a threshold applies: ``view`` — every view of a frame must pass (the worst view
#: decides); ``frame`` — the frame's means (MPSNR, MSSIM) must.
SCOPES = ("view", "frame")


@dataclass(frozen=True)
class Thresholds:
    """What a frame must meet to pass. With none given a frame must be identical.

    Attributes:
        min_psnr: least PSNR in dB (the worst view's, or the frame's MPSNR; see ``scope``).
        min_ssim: least SSIM (the worst view's, or the frame's MSSIM).
        max_abs: largest absolute difference of any sample, in 8-bit levels.
        scope: ``view`` or ``frame`` (:data:`SCOPES`).
    """

    min_psnr: float | None = None
    min_ssim: float | None = None
    max_abs: float | None = None
    scope: str = "view"

    def __post_init__(self) -> None:
        if self.scope not in SCOPES:
            raise LFValueError(f"scope: expected one of {', '.join(SCOPES)}, got {self.scope!r}")
        for name in ("min_psnr", "min_ssim", "max_abs"):
            value = getattr(self, name)
            if value is not None and not np.isfinite(value):
                raise LFValueError(f"{name}: must be a finite number, got {value!r}")

    @property
    def exact(self) -> bool:
        """Whether no threshold is given, so only identical frames pass."""
        return self.min_psnr is None and self.min_ssim is None and self.max_abs is None


@dataclass(frozen=True)
class FrameMetrics:
    """One pair of frames measured.

    Attributes:
        psnr: ``(U, V)`` per-view PSNR in dB (``inf`` where a view is identical; NaN where a
            view is missing in either input).
        ssim: ``(U, V)`` per-view SSIM (NaN where missing).
        max_abs: largest absolute difference of any sample of a present view, in 8-bit levels.
    """

    psnr: np.ndarray
    ssim: np.ndarray
    max_abs: float

    @property
    def mpsnr(self) -> float:
        return float(np.nanmean(self.psnr))

    @property
    def mssim(self) -> float:
        return float(np.nanmean(self.ssim))

    @property
    def worst_view(self) -> tuple[int, int]:
        """``(u, v)`` of the lowest-PSNR view (the first of equals, in row-major order)."""
        flat = np.where(np.isnan(self.psnr), np.inf, self.psnr).ravel()
        u, v = np.unravel_index(int(np.argmin(flat)), self.psnr.shape)
        return int(u), int(v)


@dataclass(frozen=True)
class FrameResult:
    """One frame's comparison and verdict.

    Attributes:
        frame: the frame's number in its source (``first_frame`` counted in).
        metrics: the measurements.
        passed: whether it meets the thresholds.
        failures: why not, one phrase per threshold missed.
    """

    frame: int
    metrics: FrameMetrics
    passed: bool
    failures: tuple[str, ...] = ()

    @property
    def identical(self) -> bool:
        return self.metrics.max_abs == 0

    def to_json(self) -> dict:
        """The frame's row of ``lfstream compare --json`` (infinite PSNRs capped at
        :data:`~lfstream.metrics.PSNR_CAP_DB`, with ``identical`` saying so)."""
        m = self.metrics
        u, v = m.worst_view
        return {"frame": self.frame, "mpsnr": _cap(m.mpsnr), "mssim": m.mssim, "worst_view": [u, v],
                "worst_view_psnr": _cap(float(m.psnr[u, v])), "worst_view_ssim": float(np.nanmin(m.ssim)),
                "max_abs": m.max_abs, "identical": self.identical, "passed": self.passed,
                "failures": list(self.failures)}


@dataclass
class ComparisonReport:
    """Every frame's result and the verdict.

    Attributes:
        reference, test: what was compared (paths, or ``"array"``).
        views, size: the common view grid ``(U, V)`` and view size ``(H, W)``.
        thresholds: what the frames were judged against.
        frames: each frame's :class:`FrameResult`, in order.
        worst: the reference's and the test's worst view of the worst frame, ``(H, W, 3)``
            uint8 each (for a report's crops), or ``None``.
    """

    reference: str
    test: str
    views: tuple[int, int]
    size: tuple[int, int]
    thresholds: Thresholds
    frames: list[FrameResult] = field(default_factory=list)
    worst: tuple[int, tuple[int, int], np.ndarray, np.ndarray] | None = None

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.frames)

    @property
    def failed_frames(self) -> list[int]:
        return [r.frame for r in self.frames if not r.passed]

    def to_json(self) -> dict:
        """``lfstream compare --json``'s object."""
        t = self.thresholds
        return {"passed": self.passed, "failed_frames": self.failed_frames, "reference": self.reference,
                "test": self.test, "views": list(self.views), "size": list(self.size),
                "thresholds": {"min_psnr": t.min_psnr, "min_ssim": t.min_ssim, "max_abs": t.max_abs,
                               "scope": t.scope, "exact": t.exact},
                "frames": [r.to_json() for r in self.frames]}


def _cap(db: float) -> float:
    return float(min(db, PSNR_CAP_DB))


def _levels(frame: np.ndarray) -> np.ndarray:
    """A frame as 8-bit levels: uint8 as it is, 16-bit samples as 16-bit images are read,
    floats in ``[0, 1]`` scaled (kept as float32 so nothing is rounded)."""
    if frame.dtype == np.uint8:
        return frame
    if frame.dtype == np.uint16:
        from lfstream.io.images import eight_bit

        return eight_bit(frame)
    return np.asarray(frame, np.float32) * np.float32(255.0)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    levels = _levels(np.asarray(image))
    return np.array(levels if levels.dtype == np.uint8 else np.clip(np.round(levels), 0, 255).astype(np.uint8))


def frame_metrics(reference: np.ndarray, test: np.ndarray, present: np.ndarray | None = None) -> FrameMetrics:
    """Per-view PSNR and SSIM and the largest absolute difference of two light fields.

    Args:
        reference: the expected light field.
        test: the one to judge, of the same shape.
        present: ``(U, V)`` bool mask of the views to measure (``None``: all); missing views
            are NaN in the per-view arrays and left out of the means.

    Returns:
        The :class:`FrameMetrics`.

    Shape:
        - reference, test: ``(U, V, H, W, C)``, uint8, uint16 or float in ``[0, 1]``
        - present: ``(U, V)``
    """
    from lfstream.metrics import psnr, ssim

    if reference.shape != test.shape:
        raise LFShapeError(f"frames differ in shape: {tuple(reference.shape)} against {tuple(test.shape)}")
    if reference.ndim != 5:
        raise LFShapeError(f"expected a (U, V, H, W, C) light field, got {tuple(reference.shape)}")
    a, b = _levels(np.asarray(reference)), _levels(np.asarray(test))
    if a.dtype != b.dtype:
        a, b = a.astype(np.float32), b.astype(np.float32)
    u, v = a.shape[:2]
    mask = np.ones((u, v), bool) if present is None else np.asarray(present, bool)
    if mask.shape != (u, v) or not mask.any():
        raise LFShapeError(f"present: expected a ({u}, {v}) mask with a view present, got {mask.shape}")
    rows_a, rows_b = a[mask], b[mask]  # (N, H, W, C): the present views
    per_psnr = np.atleast_1d(psnr(rows_a, rows_b, data_range=255.0))
    per_ssim = np.atleast_1d(ssim(rows_a, rows_b, data_range=255.0))
    if a.dtype == np.uint8:
        import cv2

        diff = cv2.absdiff(rows_a.reshape(len(rows_a), -1), rows_b.reshape(len(rows_b), -1))
        max_abs = float(diff.max())
    else:
        max_abs = float(np.abs(rows_a - rows_b).max())
    out_psnr = np.full((u, v), np.nan)
    out_ssim = np.full((u, v), np.nan)
    out_psnr[mask] = per_psnr
    out_ssim[mask] = per_ssim
    return FrameMetrics(out_psnr, out_ssim, max_abs)


def judge(frame: int, metrics: FrameMetrics, thresholds: Thresholds) -> FrameResult:
    """The verdict on one frame's :class:`FrameMetrics`."""
    t = thresholds
    failures = []
    if t.exact:
        if metrics.max_abs > 0:
            failures.append(f"not identical (max |diff| {metrics.max_abs:g})")
        return FrameResult(frame, metrics, not failures, tuple(failures))
    per_view = t.scope == "view"
    if t.min_psnr is not None:
        got = float(np.nanmin(metrics.psnr)) if per_view else metrics.mpsnr
        if not got >= t.min_psnr:
            where = f"view {metrics.worst_view} PSNR" if per_view else "MPSNR"
            failures.append(f"{where} {got:.2f} dB < {t.min_psnr:g}")
    if t.min_ssim is not None:
        got = float(np.nanmin(metrics.ssim)) if per_view else metrics.mssim
        if not got >= t.min_ssim:
            if per_view:
                uu, vv = np.unravel_index(int(np.nanargmin(metrics.ssim)), metrics.ssim.shape)
                where = f"view ({int(uu)}, {int(vv)}) SSIM"
            else:
                where = "MSSIM"
            failures.append(f"{where} {got:.4f} < {t.min_ssim:g}")
    if t.max_abs is not None and metrics.max_abs > t.max_abs:
        failures.append(f"max |diff| {metrics.max_abs:g} > {t.max_abs:g}")
    return FrameResult(frame, metrics, not failures, tuple(failures))


@dataclass
class FrameSource:
    """Frames of one input, read one at a time.

    Attributes:
        frames: ``(U, V, H, W, C)`` frames.
        name: the path, or ``"array"``.
        count: how many frames it yields, where known before reading them.
        views, size: ``(U, V)`` and ``(H, W)``.
        present: ``(U, V)`` mask of existing views, ``None``: all.
        first_frame: the source's number of the first frame yielded.
    """

    frames: Iterator[np.ndarray]
    name: str
    count: int | None
    views: tuple[int, int]
    size: tuple[int, int]
    present: np.ndarray | None = None
    first_frame: int = 0


def open_frames(source, options=None) -> FrameSource:
    """A :class:`FrameSource` of an array or of any path lfstream reads.

    Args:
        source: an ``(U, V, H, W, C)`` or ``(T, U, V, H, W, C)`` array, or a path.
        options: :class:`~lfstream.io.ReadOptions` for a path (crop, flips, frame range).
    """
    from lfstream.io import ReadOptions, open_lf_frames

    opts = options or ReadOptions()
    if not isinstance(source, (str, os.PathLike)):
        lf = np.asarray(source)
        check_lf(lf, name="array")
        lf = lf if lf.ndim == 6 else lf[None]
        stop = None if opts.max_frames is None else opts.first_frame + opts.max_frames
        lf = lf[opts.first_frame:stop]
        return FrameSource(iter(lf), "array", len(lf), tuple(lf.shape[1:3]), tuple(lf.shape[3:5]),
                           first_frame=opts.first_frame)
    path = Path(source)
    if path.suffix.lower() == ".npy" and path.is_file() and opts.crop is None and not (opts.flip_u or opts.flip_v):
        return _npy_frames(path, opts)
    video = open_lf_frames(path, opts)
    return FrameSource(video.frames, str(path), video.count, tuple(video.views), tuple(video.size), video.present,
                       opts.first_frame)


def _npy_frames(path: Path, opts) -> FrameSource:
    """A ``.npy`` read one frame at a time from its file (not memory-mapped: mapped pages
    would stay in the process's resident memory), so a long video is never in memory whole."""
    from lfstream.errors import LFFileError

    try:
        fh = open(path, "rb")  # noqa: SIM115 - closed when the frames are done
    except OSError as exc:
        raise LFFileError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    try:
        version = np.lib.format.read_magic(fh)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read_header(fh, max_header_size=1 << 16)
        offset = fh.tell()
    except (OSError, ValueError) as exc:
        fh.close()
        raise LFFormatError(f"{path}: not a readable .npy array ({exc})") from exc
    if len(shape) not in (5, 6) or shape[-1] != 3 or fortran or dtype.hasobject:
        fh.close()
        raise LFFormatError(f"{path}: expected a C-order (U, V, H, W, 3) or (T, U, V, H, W, 3) array, got {shape}")
    if not (dtype == np.uint8 or dtype == np.uint16 or dtype.kind == "f"):
        fh.close()
        raise LFFormatError(f"{path}: {dtype} samples; expected uint8, uint16 or float in [0, 1]")
    shape = shape if len(shape) == 6 else (1, *shape)
    frame_shape = shape[1:]
    frame_bytes = int(np.prod(frame_shape)) * dtype.itemsize
    if offset + shape[0] * frame_bytes > path.stat().st_size:
        fh.close()
        raise LFFormatError(f"{path}: shorter than its header's {shape} array")
    stop = shape[0] if opts.max_frames is None else min(shape[0], opts.first_frame + opts.max_frames)
    count = max(0, stop - opts.first_frame)

    def frames() -> Iterator[np.ndarray]:
        with fh:
            for k in range(opts.first_frame, stop):
                fh.seek(offset + k * frame_bytes)
                frame = np.fromfile(fh, dtype, int(np.prod(frame_shape))).reshape(frame_shape)
                if frame.dtype.kind == "f" and not np.isfinite(frame).all():
                    raise LFFormatError(f"{path}: frame {k} holds NaN or Inf")
                yield frame

    return FrameSource(frames(), str(path), count, tuple(shape[1:3]), tuple(shape[3:5]), first_frame=opts.first_frame)


def compare(reference, test, thresholds: Thresholds | None = None, options=None,
            test_options=None) -> Iterator[FrameResult]:
    """Compares two inputs frame by frame.

    Args:
        reference: the expected light field or video: an array or a path.
        test: the one to judge.
        thresholds: what a frame must meet (default: identical).
        options: :class:`~lfstream.io.ReadOptions` for both paths (``test_options``, if
            given, for the test).

    Yields:
        A :class:`FrameResult` per frame, numbered as in the reference.

    Raises:
        LFShapeError: the inputs differ in views, view size or frame count.
    """
    ref, tst = open_frames(reference, options), open_frames(test, test_options or options)
    yield from compare_sources(ref, tst, thresholds or Thresholds())


def compare_sources(ref: FrameSource, tst: FrameSource, thresholds: Thresholds) -> Iterator[FrameResult]:
    """:func:`compare` of two opened :class:`FrameSource` s."""
    if ref.views != tst.views or ref.size != tst.size:
        raise LFShapeError(f"{ref.name} is {ref.views[0]}x{ref.views[1]} views of {ref.size[0]}x{ref.size[1]}, "
                           f"{tst.name} {tst.views[0]}x{tst.views[1]} of {tst.size[0]}x{tst.size[1]}")
    if ref.count is not None and tst.count is not None and ref.count != tst.count:
        raise LFShapeError(f"{ref.name} has {ref.count} frames, {tst.name} {tst.count}")
    present = ref.present
    if tst.present is not None:
        present = tst.present if present is None else present & tst.present
    k = 0
    ref_it, tst_it = iter(ref.frames), iter(tst.frames)
    sentinel = object()
    while True:
        a, b = next(ref_it, sentinel), next(tst_it, sentinel)
        if a is sentinel or b is sentinel:
            if a is not b:
                longer, shorter = (ref.name, tst.name) if b is sentinel else (tst.name, ref.name)
                raise LFShapeError(f"{shorter} ends after {k} frames, {longer} goes on")
            return
        yield judge(ref.first_frame + k, frame_metrics(a, b, present), thresholds)
        k += 1


def compare_report(reference, test, thresholds: Thresholds | None = None, options=None, test_options=None,
                   keep_worst: bool = False, on_frame=None) -> ComparisonReport:
    """:func:`compare` collected into a :class:`ComparisonReport`.

    Args:
        keep_worst: also keep the worst frame's worst view of both inputs (for an HTML
            report's crops): two views' worth of memory.
        on_frame: called with each :class:`FrameResult` as it is made (a progress line).
    """
    thresholds = thresholds or Thresholds()
    ref, tst = open_frames(reference, options), open_frames(test, test_options or options)
    report = ComparisonReport(ref.name, tst.name, ref.views, ref.size, thresholds)
    worst_db = np.inf
    if keep_worst:
        ref_frames, tst_frames = _LastFrame(ref), _LastFrame(tst)
    for result in compare_sources(ref, tst, thresholds):
        report.frames.append(result)
        u, v = result.metrics.worst_view
        db = float(result.metrics.psnr[u, v])
        if keep_worst and (db < worst_db or report.worst is None):
            worst_db = db
            report.worst = (result.frame, (u, v), _to_uint8(ref_frames.last[u, v]), _to_uint8(tst_frames.last[u, v]))
        if on_frame is not None:
            on_frame(result)
    return report


class _LastFrame:
    """Wraps a source's iterator so the frame last handed out stays reachable."""

    def __init__(self, source: FrameSource) -> None:
        self._it = iter(source.frames)
        self.last: np.ndarray | None = None
        source.frames = self

    def __iter__(self) -> _LastFrame:
        return self

    def __next__(self) -> np.ndarray:
        self.last = next(self._it)
        return self.last

