"""Outputs that cannot destroy what the user gave: one check of an output path against the
inputs before any work, output folders claimed by one run at a time, and sizes checked
against memory and disk before anything is allocated.

Every command calls :func:`check_output` for each file or folder it will write, before it
reads its input, and :class:`OutputFolder` for a folder of results; both raise
:class:`~lfstream.errors.LFFileError` / :class:`~lfstream.errors.LFValueError` in one line
that names the output (``what``: the option that gave it, ``-o``, ``--html``, ...).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from lfstream.errors import LFFileError, LFValueError

#: The lock file an :class:`OutputFolder` holds while its run writes there.
LOCK_NAME = ".lfstream-lock"
#: Kinds :func:`check_output` takes for ``kinds``: ``"folder"`` (a name without an extension)
#: or file extensions.
FOLDER = "folder"
#: The file formats a light field or LF video is written to (:func:`lfstream.io.write_lf`).
LF_OUTPUTS = (".npy", ".npz", ".mp4", ".mkv", ".avi", ".mov", ".webm", ".nut")


def _resolved(path: Path) -> Path:
    try:
        return path.expanduser().resolve()
    except (OSError, RuntimeError):  # a loop of links: compared as written
        return path.expanduser().absolute()


def _within(a: Path, b: Path) -> bool:
    """Whether ``a`` is ``b`` or lies inside it."""
    return a == b or b in a.parents


def check_output(path: str | os.PathLike, inputs: Iterable[str | os.PathLike | None] = (), *, overwrite: bool = False,
                 kinds: Sequence[str] | None = None, what: str = "-o") -> Path:
    """Checks an output before any work and returns it as a Path.

    Refused, whatever ``overwrite`` says: an empty name, a name longer than the file system
    allows, an output that is an input, lies inside an input folder or holds an input, an
    extension not in ``kinds``, a folder that cannot be written. Refused without
    ``overwrite``: an output that exists (a folder that holds anything).

    Args:
        path: the output file or folder.
        inputs: the command's inputs (``None`` entries are skipped).
        overwrite: whether an existing output may be replaced.
        kinds: accepted extensions (lower case, with the dot) and/or :data:`FOLDER`;
            ``None``: any.
        what: how the message names the output (the option that gave it).
    """
    text = os.fspath(path)
    if not text.strip():
        raise LFValueError(f"{what}: an empty path; name the output")
    path = Path(text)
    existing_parent = _existing_parent(path)
    try:
        limit = os.pathconf(existing_parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    if len(os.fsencode(path.name)) > limit:
        raise LFValueError(f"{what} {path}: the file name is longer than the file system's {limit} bytes")
    out = _resolved(path)
    for given in inputs:
        if given is None or not os.fspath(given).strip():
            continue
        src = _resolved(Path(given))
        if _within(out, src) or _within(src, out):
            relation = "is" if out == src else ("lies inside" if _within(out, src) else "holds")
            raise LFValueError(f"{what} {path}: {relation} the input {given}; write the output elsewhere "
                               "(an input is never overwritten)")
    if kinds is not None:
        ext = path.suffix.lower()
        ok = (ext in kinds) or (FOLDER in kinds and not ext) or (FOLDER in kinds and path.is_dir())
        if not ok:
            wants = ", ".join(k if k != FOLDER else "a folder" for k in kinds)
            raise LFValueError(f"{what} {path}: this command writes {wants}, not {ext or 'a folder'}")
    if path.exists() and not overwrite:
        if path.is_file() or (path.is_dir() and any(p.name != LOCK_NAME for p in path.iterdir())):
            raise LFFileError(f"{what} {path}: already exists (--overwrite replaces it)")
    is_folder = kinds is not None and FOLDER in kinds and not path.suffix
    parent = _resolved(path).parent
    if not is_folder and not parent.is_dir():
        raise LFFileError(f"{what} {path}: the folder {parent} does not exist")
    _probe_writable(existing_parent, path, what)
    if path.exists() and not os.access(path, os.W_OK):
        raise LFFileError(f"{what} {path}: cannot write it (permission denied)")
    return path


def _probe_writable(folder: Path, path: Path, what: str) -> None:
    """Creates and removes a file in ``folder``: the one test that also holds for root and
    for file systems that take no files (``/proc``)."""
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=".lfstream-probe-", dir=folder)
    except OSError as exc:
        raise LFFileError(f"{what} {path}: cannot write in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)


def _existing_parent(path: Path) -> Path:
    """The nearest folder of ``path`` that exists (its own, or above it)."""
    p = _resolved(path).parent
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


class OutputFolder:
    """A folder of results claimed by one run: created where absent, and holding
    :data:`LOCK_NAME` (the run's process id) while the run writes there, so a second run
    naming the same folder is refused rather than mixing its files in. A context manager;
    :meth:`release` removes the lock, and the folder too where this run made it and wrote
    nothing. A lock whose process is gone is taken over.

    Args:
        path: the folder.
        overwrite: whether a folder that holds files may receive more.
        what: how messages name it.
    """

    def __init__(self, path: str | os.PathLike, overwrite: bool = False, what: str = "-o") -> None:
        self.path = Path(path)
        self.what = what
        self.made = False
        self._lock: Path | None = None
        self._claim(overwrite)

    def _claim(self, overwrite: bool) -> None:
        path = self.path
        if path.exists() and not path.is_dir():
            raise LFFileError(f"{self.what} {path}: exists and is not a folder")
        try:
            path.mkdir(parents=True)
            self.made = True
        except FileExistsError:
            if not path.is_dir():
                raise LFFileError(f"{self.what} {path}: exists and is not a folder") from None
        except OSError as exc:
            raise LFFileError(f"{self.what} {path}: cannot create the folder ({exc.strerror or exc})") from exc
        lock = path / LOCK_NAME
        for _ in range(2):
            try:
                fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                if _lock_is_stale(lock):
                    lock.unlink(missing_ok=True)
                    continue
                raise LFFileError(f"{self.what} {path}: another lfstream run is writing there "
                                  f"(process {_lock_pid(lock)}); choose another folder") from None
            except OSError as exc:
                raise LFFileError(f"{self.what} {path}: cannot write there ({exc.strerror or exc})") from exc
            with os.fdopen(fd, "w") as fh:
                fh.write(str(os.getpid()))
            self._lock = lock
            break
        if not overwrite and not self.made and any(p.name != LOCK_NAME for p in path.iterdir()):
            self.release()
            raise LFFileError(f"{self.what} {path}: exists and is not an empty folder (choose another, or "
                              "--overwrite to add to it)")

    def release(self) -> None:
        """Removes the lock; a folder this run made and left empty goes too."""
        if self._lock is not None:
            self._lock.unlink(missing_ok=True)
            self._lock = None
        if self.made and self.path.is_dir() and not any(self.path.iterdir()):
            self.path.rmdir()

    def __enter__(self) -> OutputFolder:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _lock_pid(lock: Path) -> int | None:
    try:
        return int(lock.read_text().strip() or "0") or None
    except (OSError, ValueError):
        return None


def _lock_is_stale(lock: Path) -> bool:
    """Whether the run that made ``lock`` is gone (a killed run's lock)."""
    pid = _lock_pid(lock)
    if pid is None:
        return False  # being written this instant, or not ours: leave it
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def fresh_output_folder(base: str | os.PathLike, what: str = "-o") -> OutputFolder:
    """The first of ``base``, ``base-2``, ``base-3``, ... that is absent or an empty folder no
    other run holds, claimed (the default output folder of a command never mixes runs)."""
    base = Path(base)
    n = 1
    while True:
        candidate = base if n == 1 else base.with_name(f"{base.name}-{n}")
        if not candidate.exists() or (candidate.is_dir() and not any(candidate.iterdir())):
            try:
                return OutputFolder(candidate, what=what)
            except LFFileError:
                pass  # taken meanwhile by another run
        n += 1
        if n > 100000:
            raise LFFileError(f"{what} {base}: no free folder name")


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``), else ``None``."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return None


def check_memory(nbytes: int, what: str) -> None:
    """Refuses, before anything is allocated, ``nbytes`` that would not fit in the memory
    available now (one line with the size and the limit)."""
    avail = available_memory()
    if avail is not None and nbytes > avail:
        raise LFValueError(f"{what}: needs {_size(nbytes)} of memory, {_size(avail)} available")


def check_disk(path: str | os.PathLike, nbytes: int, what: str) -> None:
    """Refuses an output of ``nbytes`` that would not fit on the disk that receives ``path``."""
    try:
        st = os.statvfs(_existing_parent(Path(path)))
    except OSError:
        return
    free = st.f_bavail * st.f_frsize
    if nbytes > free:
        raise LFValueError(f"{what}: needs {_size(nbytes)} of disk, {_size(free)} free where {path} goes")


def _size(n: int) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return str(n)



__all__ = ["LOCK_NAME", "FOLDER", "LF_OUTPUTS", "check_output", "OutputFolder", "fresh_output_folder", "available_memory",
           "check_memory", "check_disk"]
