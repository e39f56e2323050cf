"""File-system helpers every writer shares: atomic writes and fresh output folders.

Atomic: a file is written under a hidden temporary name beside its target and renamed into
place only when complete, so an interrupted write never leaves a torn file and never
replaces a good one with a broken one. Fresh folders: a command's default output folder is
never one that already holds results.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from lfstream.errors import LFFileError


def temp_sibling(path: str | os.PathLike, tag: str = "tmp") -> Path:
    """The hidden temporary name a file is written under before it is renamed to ``path``.

    The extension is kept last, because some writers (PyAV) choose the container by it.
    """
    path = Path(path)
    return path.with_name(f".{path.stem}.{tag}{os.getpid()}{path.suffix}")


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yields a temporary path to write; it replaces ``path`` when the block ends normally
    and is deleted when the block raises (the target is then untouched)."""
    path = Path(path)
    tmp = temp_sibling(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        raise LFFileError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    finally:
        tmp.unlink(missing_ok=True)


@contextmanager
def atomic_open(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """A binary file handle whose content lands at ``path`` only if the block completes."""
    with atomic_path(path) as tmp:
        try:
            fh = open(tmp, "wb")
        except OSError as exc:
            raise LFFileError(f"{path}: cannot write ({exc.strerror or exc})") from exc
        with fh:
            yield fh


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Writes ``data`` to ``path`` atomically."""
    with atomic_open(path) as fh:
        fh.write(data)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Writes UTF-8 ``text`` to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def check_new_file(path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Refuses an output file that exists unless ``overwrite``; returns it as a Path."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise LFFileError(f"{path}: already exists (pass overwrite=True / --overwrite to replace it)")
    return path


def fresh_dir(base: str | os.PathLike) -> Path:
    """``base`` if it is absent or an empty folder, else ``base-2``, ``base-3``, ...: the
    default output folder of a command never holds an earlier run's results."""
    base = Path(base)
    candidate, n = base, 1
    while candidate.exists() and (not candidate.is_dir() or any(candidate.iterdir())):
        n += 1
        candidate = base.with_name(f"{base.name}-{n}")
    return candidate


def prepare_output_dir(out: str | os.PathLike, overwrite: bool = False) -> Path:
    """Creates the output folder ``out``; an existing file, or a non-empty folder without
    ``overwrite``, is an error (nothing the user has is overwritten)."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not overwrite)):
        raise LFFileError(f"{out}: exists and is not an empty folder (choose another -o)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LFFileError(f"{out}: cannot create the folder ({exc.strerror or exc})") from exc
    return out


def remove_if_made_empty(folder: str | os.PathLike, made: bool) -> None:
    """Removes the output ``folder`` where this run made it (``made``: it did not exist
    before :func:`prepare_output_dir`) and wrote nothing to it, so a run that failed first
    leaves nothing behind; a folder the user made stays, empty or not."""
    folder = Path(folder)
    if made and folder.is_dir() and not any(folder.iterdir()):
        folder.rmdir()


__all__ = [
    "temp_sibling",
    "atomic_path",
    "atomic_open",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_new_file",
    "fresh_dir",
    "prepare_output_dir",
    "remove_if_made_empty",
]
