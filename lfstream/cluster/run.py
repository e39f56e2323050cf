"""``lfstream.batch`` (:func:`batch`): encode or decode collections of LF videos, in this process or on Ray.

Every input is split into frame groups (:mod:`lfstream.cluster.jobs`), the groups of all
inputs run as independent jobs — one after another here (``engine="local"``), or as Ray
tasks spread over a cluster's workers (``engine="ray"``; a local cluster that starts and
stops with the call, or a running one by ``address``) — and each input's results are
reassembled in order and written through a temporary name. Jobs are deterministic, so
both engines write the same bytes. A worker that dies has its jobs retried by Ray; an
input that cannot be read or decoded fails alone, named in the report.
"""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from lfstream.cluster.jobs import (
    DecodeOptions,
    EncodeOptions,
    GroupResult,
    decode_group,
    decode_groups,
    encode_group,
    frame_groups,
    split_stream_bytes,
)
from lfstream.errors import LFFormatError, LFStreamError, LFValueError
from lfstream.lightfield import frames_in_range

ENGINES = ("local", "ray")
MODES = ("encode", "decode")
#: Attempts Ray gives a job whose worker died (the first run plus retries).
RAY_MAX_RETRIES = 3
#: Jobs in flight per Ray worker: enough to keep every worker busy while the driver reads
#: the next groups, few enough that the frames waiting in the object store stay bounded.
RAY_JOBS_PER_WORKER = 2


@dataclass
class FileResult:
    """One input's outcome."""

    input: str
    output: str | None = None
    status: str = "pending"  # "ok" or "failed"
    frames: int = 0
    bytes: int = 0
    error: str | None = None


@dataclass
class BatchReport:
    """What a batch did (``lfstream batch --json`` prints :meth:`as_dict`)."""

    engine: str
    workers: int
    mode: str
    files: list[FileResult] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def frames(self) -> int:
        return sum(f.frames for f in self.files if f.status == "ok")

    @property
    def bytes(self) -> int:
        return sum(f.bytes for f in self.files if f.status == "ok")

    @property
    def ok(self) -> bool:
        return all(f.status == "ok" for f in self.files)

    def as_dict(self) -> dict:
        return {"engine": self.engine, "workers": self.workers, "mode": self.mode, "frames": self.frames,
                "bytes": self.bytes, "wall_s": round(self.wall_s, 3),
                "fps": round(self.frames / self.wall_s, 3) if self.wall_s > 0 else None,
                "files": [asdict(f) for f in self.files]}


@dataclass
class _Job:
    file: int
    fn: Callable[..., GroupResult]
    args: tuple


def _decode_suffix(output_format: str) -> str:
    """A decode's output extension: ``.npy``, ``.npz``, a video's, or ``""`` (``"folder"`` too)
    for folders of views; ``npy`` without its dot is ``.npy``. Anything else is refused (an
    unknown one was appended to the name as it was: ``--format folder`` wrote ``clipfolder/``)."""
    from lfstream.io.video import VIDEO_EXTS

    fmt = str(output_format).strip().lower()
    if fmt in ("", "folder"):
        return ""
    fmt = fmt if fmt.startswith(".") else "." + fmt
    if fmt not in (".npy", ".npz", *VIDEO_EXTS):
        raise LFValueError(f"output_format: .npy, .npz, a video's ({', '.join(VIDEO_EXTS)}) or '' for folders of "
                           f"views, got {output_format!r}")
    return fmt


def _output_name(path: Path, suffix: str, taken: set[str]) -> str:
    stem = path.name if path.is_dir() else path.stem
    name, k = f"{stem}{suffix}", 1
    while name in taken:
        k += 1
        name = f"{stem}-{k}{suffix}"
    taken.add(name)
    return name


def _run_local(jobs: Iterable[_Job], on_result: Callable[[int, GroupResult | BaseException], None]) -> None:
    """Runs the jobs one by one as they come (a job's frames are read just before it runs),
    handing each job's input and result to ``on_result`` in order."""
    source = iter(jobs)
    while (job := next(source, None)) is not None:
        try:
            result = job.fn(*job.args)
        except Exception as exc:  # noqa: BLE001 - the input fails alone, with its error in the report
            result = exc
        file, job = job.file, None  # its frames go before the next group is read
        on_result(file, result)
        result = None


class _Outputs:
    """Each input's results, in job order (all of an input's jobs come together), into its
    output: an encode's packets (small) written with the header when its last group is in;
    a decode's frames written group by group as they come (:class:`lfstream.io.FrameWriter`,
    a ``.npz`` too: deflated from its frames when closed), so a decoded video is never all
    in memory. An input whose reading or a job failed leaves no output."""

    def __init__(self, mode: str, files: list[FileResult], plans: dict[int, dict], overwrite: bool) -> None:
        self.mode, self.files, self.plans, self.overwrite = mode, files, plans, overwrite
        self._reset(None)

    def _reset(self, file: int | None) -> None:
        self.file, self.parts, self.writer, self.frames, self.nbytes, self.error = file, [], None, 0, 0, None

    def add(self, file: int, result: GroupResult | BaseException) -> None:
        if file != self.file:
            self.finish()
            self._reset(file)
        if self.error is not None or self.files[file].status == "failed":
            return
        if isinstance(result, BaseException):
            self.error = result
            self.abort()
            return
        if self.mode == "encode":
            self.parts.append(result.packets)
            self.frames += len(result.packets)
            return
        plan = self.plans[file]
        lo, hi = plan["first"] - result.start, plan["stop"] - result.start  # the range, in this group
        frames = result.frames[max(lo, 0): max(hi, 0)]
        self.frames += len(frames)
        self.nbytes += int(frames.nbytes)
        try:
            if self.writer is None:
                from lfstream.io import FrameWriter

                # a folder's frames keep the stream's numbers, as lfstream decode's do
                self.writer = FrameWriter(plan["target"], plan["count"], fps=plan["fps"], overwrite=self.overwrite,
                                          first_index=plan["first"])
            for frame in frames:
                self.writer.write(frame)
        except LFStreamError as exc:
            self.error = exc
            self.abort()

    def finish(self) -> None:
        """Completes the current input's output (or drops it, where it failed)."""
        if self.file is None:
            return
        res, plan = self.files[self.file], self.plans[self.file]
        if res.status == "failed" or self.error is not None:  # its reading or a job failed
            self.abort()
            if self.error is not None:
                res.status, res.error = "failed", f"{res.input}: {self.error}"
            self.file = None
            return
        try:
            if self.mode == "encode":
                from lfstream.codec.bitstream import pack_header
                from lfstream.io._fs import atomic_open

                header = plan["options"].encoder().header(plan["views"], plan["size"], plan["fps"])
                with atomic_open(plan["target"]) as fh:
                    fh.write(pack_header(header))
                    for packets in self.parts:
                        for p in packets:
                            fh.write(p)
                res.bytes = plan["target"].stat().st_size
            elif self.writer is not None:
                self.writer.close()
                res.bytes = plan["target"].stat().st_size if plan["target"].is_file() else self.nbytes
            else:  # a decode that gave no frame
                raise LFStreamError("no frame decoded")
            res.frames, res.status = self.frames, "ok"
        except LFStreamError as exc:
            self.abort()
            res.status, res.error = "failed", f"{res.input}: {exc}"
        self.file = None

    def abort(self) -> None:
        """Discards the current input's partial output."""
        if self.writer is not None:
            self.writer.abort()
            self.writer = None
        self.parts = []


def _prepend(box: list, rest: Iterator) -> Iterator:
    """``box``'s one item, then ``rest``: the item handed over, not held (``itertools.chain``
    keeps its first iterable, and so a group of frames, for as long as it runs)."""
    yield box.pop()
    yield from rest


def _remote_call(fn: Callable[..., GroupResult], args: tuple, fail_once: str | None) -> GroupResult:
    if fail_once is not None and not os.path.exists(fail_once):
        # fault injection for tests: the first attempt of this job kills its worker process
        open(fail_once, "w").close()
        os._exit(1)
    return fn(*args)


def _ray():
    try:
        import ray
    except ImportError:
        raise LFValueError("engine='ray' needs Ray: pip install 'lfstream[ray]' (or pip install ray)") from None
    return ray


def _run_ray(jobs: Iterable[_Job], address: str | None, workers: int | None, fail_once: Path | None,
             on_result: Callable[[int, GroupResult | BaseException], None]) -> int:
    """Runs the jobs as Ray tasks, at most :data:`RAY_JOBS_PER_WORKER` per worker in flight
    (a job's frames are read and put into Ray's object store when it is submitted, so a
    long video is never all in memory at once), handing each job's input and result to
    ``on_result`` in job order; returns the cluster's CPUs."""
    ray = _ray()
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
        else:
            # a local cluster for this call only, on loopback
            ray.init(num_cpus=workers or os.cpu_count() or 1, include_dashboard=False, log_to_driver=False,
                     configure_logging=False, _node_ip_address="127.0.0.1")
    try:
        n_workers = int(ray.cluster_resources().get("CPU", 1))
        remote = ray.remote(max_retries=RAY_MAX_RETRIES, retry_exceptions=False)(_remote_call)
        in_flight: deque = deque()

        def collect_oldest() -> None:
            file, ref = in_flight.popleft()
            try:
                result = ray.get(ref)
            except Exception as exc:  # noqa: BLE001 - RayTaskError wraps the job's own error
                result = getattr(exc, "cause", None) or exc
            on_result(file, result)

        for k, job in enumerate(jobs):
            if len(in_flight) >= RAY_JOBS_PER_WORKER * n_workers:
                collect_oldest()
            in_flight.append((job.file, remote.remote(job.fn, job.args, str(fail_once) if fail_once and k == 0
                                                       else None)))
        while in_flight:
            collect_oldest()
        return n_workers
    finally:
        if started:
            ray.shutdown()


def batch(inputs: Sequence[str | os.PathLike], output: str | os.PathLike, *, mode: str = "encode",
          engine: str = "local", address: str | None = None, workers: int | None = None, group_frames: int = 8,
          encode: EncodeOptions = EncodeOptions(), decode: DecodeOptions = DecodeOptions(), read=None,
          output_format: str = ".npy", overwrite: bool = False, _fail_once: Path | None = None) -> BatchReport:
    """Encodes LF videos to ``OUTPUT/<name>.lfs`` (``mode="encode"``) or decodes ``.lfs``
    streams to ``OUTPUT/<name><output_format>`` (``mode="decode"``).

    Args:
        inputs: LF videos or light fields in any readable format (encode), ``.lfs`` (decode).
        output: the output folder (created, and removed again, empty, where every input
            failed; existing files are kept unless ``overwrite``).
        engine: ``"local"`` (this process) or ``"ray"``.
        address: a running Ray cluster (``ray start --head`` prints it); default: a local
            cluster started and stopped by this call.
        workers: CPUs of the local Ray cluster (default: all).
        group_frames: frames per job; a long video spreads over workers by groups.
        encode, decode: the codec options; read: :class:`~lfstream.io.ReadOptions`.

    Returns:
        :class:`BatchReport`; an input that failed has ``status="failed"`` and its error.
    """
    from lfstream.io import ReadOptions
    from lfstream.io._fs import prepare_output_dir, remove_if_made_empty

    if mode not in MODES or engine not in ENGINES:
        raise LFValueError(f"mode: one of {', '.join(MODES)}; engine: one of {', '.join(ENGINES)}; "
                           f"got {mode!r}, {engine!r}")
    if not isinstance(group_frames, int) or group_frames < 1:
        raise LFValueError(f"group_frames: a positive integer, got {group_frames!r}")
    if engine == "ray":
        _ray()  # fail early with the install hint
    read = read or ReadOptions()
    if mode == "decode":
        output_format = _decode_suffix(output_format)
        if read.angular or read.crop or read.grid or read.flip_u or read.flip_v or read.allow_missing:
            # (they were ignored)
            raise LFValueError("read options (angular, views crop, grid, flips, allow_missing) shape light fields "
                               "read for an encode; a decode takes first_frame and max_frames")
    t0 = time.perf_counter()
    created = not Path(output).exists()
    out_dir = prepare_output_dir(output, overwrite=True)
    report = BatchReport(engine=engine, workers=1, mode=mode)
    plans: dict[int, dict] = {}
    taken: set[str] = set()

    def encode_jobs(i: int, path: Path, target: Path) -> Iterator[_Job]:
        # an LF video is read a group of frames at a time, as its jobs are run or submitted:
        # a long video (or a collection of them) is never all in memory (before: every
        # input read whole, and every group copied, before the first job ran)
        from lfstream.io import open_lf_frames

        video = open_lf_frames(path, read)
        frames, present, fps = video.frames, video.present, video.fps
        first = next(frames, None)
        if first is None:
            raise LFFormatError(f"{path}: contains no frames")
        # the default's choice (preset, or the views) once per input, on its first frame
        options = encode.for_input(np.ascontiguousarray(first), present)
        plans[i] = {"target": target, "views": tuple(first.shape[:2]), "size": tuple(first.shape[2:4]),
                    "fps": fps or 30.0, "options": options}
        first = [first]  # handed over to the groups, not kept here
        for start, group in frame_groups(_prepend(first, frames), group_frames):
            yield _Job(i, encode_group, (group, start, plans[i]["fps"], options, present))
            del group  # not held while the next group is read

    def decode_jobs(i: int, path: Path, target: Path) -> Iterator[_Job]:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise LFStreamError(f"{path}: cannot read ({exc.strerror or exc})") from exc
        header, header_bytes, packets, raw = split_stream_bytes(data)
        if not packets:
            raise LFValueError(f"{path}: stream holds no frames")
        # a frame range (--first-frame, --max-frames; they were ignored here): the groups
        # that hold it, each decoded from its self-contained start, the frames outside it
        # dropped as they are written
        first = read.first_frame
        stop = first + frames_in_range(len(packets), first, read.max_frames, path)
        plans[i] = {"target": target, "fps": header.fps, "count": stop - first, "first": first, "stop": stop}
        for a, b in decode_groups(packets, group_frames):
            if b > first and a < stop:
                yield _Job(i, decode_group, (header_bytes, raw[a:b], a, decode))

    def all_jobs() -> Iterator[_Job]:
        for i, src in enumerate(inputs):
            path = Path(src)
            res = FileResult(input=str(path))
            report.files.append(res)
            try:
                name = _output_name(path, ".lfs" if mode == "encode" else output_format, taken)
                target = out_dir / name
                if target.exists() and not overwrite:
                    raise LFValueError(f"{target}: already exists (pass overwrite=True / --overwrite to replace it)")
                res.output = str(target)
                yield from (encode_jobs if mode == "encode" else decode_jobs)(i, path, target)
            except LFStreamError as exc:  # the input fails alone (also part way: its groups are dropped)
                res.status, res.error = "failed", f"{path}: {exc}" if str(path) not in str(exc) else str(exc)

    jobs = all_jobs()
    outputs = _Outputs(mode, report.files, plans, overwrite)
    first_job = [next(jobs, None)]
    try:
        if first_job[0] is not None:  # (no Ray cluster started for inputs that all failed)
            jobs = _prepend(first_job, jobs)
            if engine == "ray":
                report.workers = _run_ray(jobs, address, workers, _fail_once, outputs.add)
            else:
                _run_local(jobs, outputs.add)
        outputs.finish()
    except BaseException:
        outputs.abort()
        raise
    if not any(f.status == "ok" for f in report.files):  # every input failed
        remove_if_made_empty(out_dir, created)
    report.wall_s = time.perf_counter() - t0
    return report


__all__ = ["ENGINES", "MODES", "RAY_MAX_RETRIES", "FileResult", "BatchReport", "batch"]
