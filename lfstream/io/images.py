"""Single images: RGB(A) files and lenslet (ESLF) images."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lfstream.errors import LFFileError, LFFormatError, LFShapeError, LFValueError
from lfstream.io._fs import atomic_write_bytes
from lfstream.lightfield import MAX_VIEWS_PER_AXIS, from_sensor

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".webp")


def read_image(path: Path) -> np.ndarray:
    """Reads an image file as uint8 RGB ``(H, W, 3)``, or RGBA ``(H, W, 4)`` if it has alpha.

    16-bit images are scaled to 8 bits (``round(x / 257)``); grayscale becomes three equal
    channels.
    """
    path = Path(path)
    if not path.is_file():
        raise LFFileError(f"{path}: no such file")
    data = np.fromfile(str(path), dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise LFFormatError(f"{path}: not a readable image")
    if img.dtype == np.uint16:
        img = eight_bit(img)
    elif img.dtype != np.uint8:
        raise LFFormatError(f"{path}: unsupported image sample type {img.dtype}")
    if img.ndim == 2:
        return np.repeat(img[:, :, None], 3, axis=2)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def eight_bit(samples: np.ndarray) -> np.ndarray:
    """16-bit samples (uint16, 0..65535) as 8-bit ones: ``round(x / 257)``, exact in integers
    (65535 / 257 = 255)."""
    return ((samples.astype(np.uint32) + 128) // 257).astype(np.uint8)


def write_image(path: Path, img: np.ndarray) -> None:
    """Writes a uint8 RGB ``(H, W, 3)`` image; the format follows the extension."""
    path = Path(path)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (1, 3):
        raise LFShapeError(f"{path}: expected uint8 (H, W, 3) image, got {img.dtype} {img.shape}")
    bgr = img if img.shape[2] == 1 else cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(path.suffix or ".png", bgr)
    if not ok:
        raise LFFileError(f"{path}: cannot encode image with extension {path.suffix!r}")
    atomic_write_bytes(path, buf.tobytes())


def read_eslf(path: Path, angular: int, crop: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Reads a Lytro-style lenslet image whose microlens images are ``angular x angular`` pixels.

    Returns ``(lf, weight)``: ``lf`` is ``(k, k, H, W, 3)`` uint8 with ``k = crop or angular``
    (the central views), ``weight`` the alpha channel as ``(k, k, H, W)`` float32 in
    ``[0, 1]`` (``None`` without alpha). Black or masked corner views are common in such
    files; the weight keeps that information instead of pretending those samples are dark.
    """
    if not isinstance(angular, (int, np.integer)) or not 1 <= angular <= MAX_VIEWS_PER_AXIS:
        raise LFValueError(f"angular: must be an integer in 1..{MAX_VIEWS_PER_AXIS}, got {angular!r}")
    img = read_image(path)
    h, w = img.shape[:2]
    if h % angular or w % angular:
        raise LFShapeError(f"{path}: image size {h}x{w} is not a multiple of the angular size {angular}")
    full = from_sensor(img, angular)  # (N, N, H, W, 3 or 4)
    if crop is not None:
        if not 1 <= crop <= angular:
            raise LFValueError(f"crop: must be in 1..{angular}, got {crop}")
        s = angular // 2 - crop // 2
        full = full[s : s + crop, s : s + crop]
    full = np.ascontiguousarray(full)
    weight = None
    if full.shape[-1] == 4:
        weight = full[..., 3].astype(np.float32) / 255.0
        full = np.ascontiguousarray(full[..., :3])
    return full, weight


__all__ = ["IMAGE_EXTS", "read_image", "write_image", "read_eslf", "eight_bit"]
