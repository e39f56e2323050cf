"""PFM disparity maps (the HCI benchmark's format)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lfstream.errors import LFFileError, LFFormatError, LFShapeError
from lfstream.io._fs import atomic_write_bytes
from lfstream.lightfield import MAX_VIEW_SIDE


def read_pfm(path: Path) -> np.ndarray:
    """Reads a PFM file (HCI benchmark disparity format) as float32 ``(H, W)`` or ``(H, W, 3)``.

    Rows are stored bottom-to-top in PFM; the result is top-to-bottom.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            header = fh.readline().strip()
            if header not in (b"Pf", b"PF"):
                raise LFFormatError(f"{path}: not a PFM file (header {header[:8]!r})")
            dims = fh.readline().split()
            scale_line = fh.readline().strip()
            try:
                w, h = int(dims[0]), int(dims[1])
                scale = float(scale_line)
            except (ValueError, IndexError) as exc:
                raise LFFormatError(f"{path}: malformed PFM header") from exc
            if not (0 < w <= MAX_VIEW_SIDE and 0 < h <= MAX_VIEW_SIDE) or scale == 0:
                raise LFFormatError(f"{path}: PFM size {w}x{h} or scale {scale} out of range")
            ch = 3 if header == b"PF" else 1
            count = w * h * ch
            data = np.fromfile(fh, dtype="<f4" if scale < 0 else ">f4", count=count)
    except FileNotFoundError as exc:
        raise LFFileError(f"{path}: no such file") from exc
    except IsADirectoryError as exc:
        raise LFFileError(f"{path}: is a folder, not a PFM file") from exc
    if data.size != count:
        raise LFFormatError(f"{path}: truncated PFM ({data.size} of {count} values)")
    arr = data.reshape((h, w, ch) if ch == 3 else (h, w))[::-1]
    return np.ascontiguousarray(arr.astype(np.float32))


def write_pfm(path: Path, disp: np.ndarray) -> None:
    """Writes float32 ``(H, W)`` (or ``(H, W, 3)``) as little-endian PFM."""
    arr = np.asarray(disp, dtype=np.float32)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
        raise LFShapeError(f"{path}: PFM needs (H, W) or (H, W, 3), got {arr.shape}")
    h, w = arr.shape[:2]
    header = f"{'PF' if arr.ndim == 3 else 'Pf'}\n{w} {h}\n-1.0\n".encode()
    body = np.ascontiguousarray(arr[::-1]).astype("<f4").tobytes()
    atomic_write_bytes(Path(path), header + body)


__all__ = ["read_pfm", "write_pfm"]
