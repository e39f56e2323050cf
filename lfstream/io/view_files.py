"""Folders of view images: the naming schemes (``R_C``, HCI ``input_CamNNN``, Lytro
``NAME_RR_CC``), the scan of a folder into a view grid, missing views, and what kind of
folder a path is."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lfstream.errors import LFFormatError, LFMissingViewsError, LFShapeError
from lfstream.io.images import IMAGE_EXTS, read_image
from lfstream.io.video import VIDEO_EXTS
from lfstream.lightfield import MAX_VIEWS_PER_AXIS

_RE_RC = re.compile(r"^(\d+)_(\d+)$")
_RE_HCI = re.compile(r"^input_Cam(\d{3})$")
_RE_LYTRO = re.compile(r"^(.*?)_(\d{2})_(\d{2})$")


def _view_name_index(stem: str) -> tuple[str, int, int, str] | None:
    """Parses a view file stem into (scheme, row, col, prefix); row/col 0-based (HCI: linear)."""
    m = _RE_HCI.match(stem)
    if m:
        return "hci", int(m.group(1)), -1, ""
    m = _RE_RC.match(stem)
    if m:
        return "rc", int(m.group(1)), int(m.group(2)), ""
    m = _RE_LYTRO.match(stem)
    if m:
        return "lytro", int(m.group(2)) - 1, int(m.group(3)) - 1, m.group(1)
    return None


def _scan_view_files(folder: Path, exts: Sequence[str]) -> tuple[str, dict[tuple[int, int], Path], tuple[int, int]]:
    """Finds the view files of a folder and their grid positions; returns (scheme, map, grid)."""
    entries: dict[str, list[tuple[int, int, Path]]] = {}
    for p in sorted(folder.iterdir()):
        if not p.is_file() or p.suffix.lower() not in exts:
            continue
        parsed = _view_name_index(p.stem)
        if parsed is None:
            continue
        scheme, r, c, _prefix = parsed
        entries.setdefault(scheme, []).append((r, c, p))
    if not entries:
        raise LFFormatError(
            f"{folder}: no view files named R_C, input_CamNNN or NAME_RR_CC with extension in {list(exts)}"
        )
    if len(entries) > 1:
        raise LFFormatError(f"{folder}: mixes view naming schemes {sorted(entries)}")
    scheme, items = next(iter(entries.items()))
    if scheme == "hci":
        # HCI numbers views row-major on an n x n grid; infer n from the largest index.
        top = max(r for r, _, _ in items)
        n = int(np.ceil(np.sqrt(top + 1)))
        views = {(r // n, r % n): p for r, _, p in items}
        grid = (n, n)
    else:
        views = {}
        for r, c, p in items:
            if r < 0 or c < 0:
                raise LFFormatError(f"{p}: view index out of range")
            if (r, c) in views:
                raise LFFormatError(f"{folder}: two files for view ({r}, {c}): {views[(r, c)].name}, {p.name}")
            views[(r, c)] = p
        grid = (max(r for r, _ in views) + 1, max(c for _, c in views) + 1)
    if max(grid) > MAX_VIEWS_PER_AXIS:
        raise LFFormatError(f"{folder}: view grid {grid} exceeds the limit of {MAX_VIEWS_PER_AXIS} per axis")
    return scheme, views, grid


def _missing_message(folder: Path, missing: list[tuple[int, int]], grid: tuple[int, int]) -> str:
    shown = ", ".join(f"({r},{c})" for r, c in missing[:12])
    more = f" and {len(missing) - 12} more" if len(missing) > 12 else ""
    return (
        f"{folder}: {len(missing)} of {grid[0] * grid[1]} views of the {grid[0]}x{grid[1]} grid are missing: "
        f"{shown}{more} (pass allow_missing=True / --allow-missing to load the present views with a mask)"
    )


#: Threads that decode a folder's view images (:func:`_assemble_views`).
VIEW_READ_THREADS = min(4, os.cpu_count() or 1)


def _assemble_views(
    folder: Path,
    views: dict[tuple[int, int], object],
    grid: tuple[int, int],
    load_view,
    allow_missing: bool,
) -> tuple[np.ndarray, np.ndarray | None]:
    missing = _missing_views(folder, views, grid, allow_missing)
    from concurrent.futures import ThreadPoolExecutor

    lf: np.ndarray | None = None
    first: tuple[tuple[int, ...], Path] | None = None  # the first view's shape and file
    items = sorted(views.items())
    # the views decoded on a few threads (OpenCV's decoders release the GIL): lytro_bikes'
    # 49 PNGs 0.25 -> 0.14 s on two cores; each placed by its grid position
    with ThreadPoolExecutor(max_workers=max(1, min(VIEW_READ_THREADS, len(items)))) as pool:
        for ((r, c), src), img in zip(items, pool.map(load_view, [src for _, src in items])):
            if first is None:
                first = (img.shape, src)
                lf = np.zeros(img.shape[:-3] + (grid[0], grid[1]) + img.shape[-3:], np.uint8)
            elif img.shape != first[0]:
                raise LFShapeError(f"{src}: view shape {img.shape} differs from {first[1]} {first[0]}")
            lf[..., r, c, :, :, :] = img
    assert lf is not None
    return lf, _present_mask(views, grid) if missing else None


def _missing_views(folder: Path, views: dict[tuple[int, int], object], grid: tuple[int, int],
                   allow_missing: bool) -> list[tuple[int, int]]:
    """The grid positions without a view; refused (:class:`LFMissingViewsError`) unless
    ``allow_missing``."""
    missing = [(r, c) for r in range(grid[0]) for c in range(grid[1]) if (r, c) not in views]
    if missing and not allow_missing:
        raise LFMissingViewsError(_missing_message(folder, missing, grid), missing)
    return missing


def _present_mask(views: dict[tuple[int, int], object], grid: tuple[int, int]) -> np.ndarray:
    """The ``grid`` mask of the positions that have a view."""
    present = np.zeros(grid, bool)
    for r, c in views:
        present[r, c] = True
    return present


def _read_rgb_view(p: Path) -> np.ndarray:
    img = read_image(p)
    return img[:, :, :3]


def _classify_folder(folder: Path) -> str:
    files = [p for p in folder.iterdir() if not p.name.startswith(".")]
    if not files:
        raise LFFormatError(f"{folder}: empty folder")
    exts = {p.suffix.lower() for p in files if p.is_file()}
    named = [p for p in files if p.is_file() and _view_name_index(p.stem) is not None]
    if named and any(p.suffix.lower() in IMAGE_EXTS for p in named):
        return "sai-folder"
    if named and any(p.suffix.lower() in VIDEO_EXTS for p in named):
        return "view-videos"
    if any(p.is_dir() for p in files) or exts & {".npy", ".npz", ".lfs"} or exts & set(VIDEO_EXTS):
        return "frames-folder"
    raise LFFormatError(f"{folder}: no light-field files recognised (extensions found: {sorted(exts) or 'none'})")


#: Formats whose decoder lives in a higher layer (the codec decodes ``.lfs``): imported by
#: name when one is read (``lfstream.io`` does not import the codec); the function gives
#: ``(frames iterator, header, count)``.
