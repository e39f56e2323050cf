"""The sink: focal stacks and reconstructed light fields to files, finalised on any exit."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from lfstream.errors import LFFileError, LFStreamError
from lfstream.io import VideoWriter, grid_metadata, write_image
from lfstream.io._fs import atomic_write_text
from lfstream.lightfield import to_mosaic
from lfstream.stream.config import StreamConfig
from lfstream.stream.frames import StackFrame


class Sink:
    """Writes focal stacks (MP4 per plane, PNG per plane and frame, a focal-sweep MP4) and
    optionally the reconstructed LF (``reconstructed.avi``, a lossless Ut Video mosaic video,
    many times faster to write than FFV1); beside them
    ``planes.json`` (every plane's index, slope and alpha, and the frames where the planes
    were fitted) and ``contact_sheet.png`` (the first frame's stack at a glance). Each plane
    MP4 records its plane in the ``comment`` tag."""

    def __init__(self, out: Path, config: StreamConfig) -> None:
        self.out = out
        self.config = config
        self.files: list[str] = []
        self._plane_writers: list = []
        self._sweep = None
        self._lf_writer = None
        self._plane_log: list[dict] = []  # frame and slopes, whenever the planes changed
        self._slopes = None  # the latest planes
        self._disparity: list[dict] = []  # per frame, low resolution, for the viewer's click to focus

    def _note_planes(self, f: StackFrame) -> None:
        slopes = [round(float(s), 6) for s in f.slopes] if f.slopes is not None else []
        if f.slopes is not None:
            self._slopes = f.slopes
        if not self._plane_log or self._plane_log[-1]["slopes"] != slopes:
            self._plane_log.append({"frame": f.seq, "slopes": slopes})
            if len(self._plane_log) == 1 and slopes:
                self._contact_sheet(f.stack, slopes)

    def _contact_sheet(self, stack, slopes: list[float]) -> None:
        path = self.out / "contact_sheet.png"
        write_image(path, contact_sheet(stack, slopes))
        self.files.append(str(path))

    def write(self, f: StackFrame) -> None:
        cfg = self.config
        if f.stack is not None:
            from lfstream.viewer import disparity_record

            self._note_planes(f)
            self._disparity.append(disparity_record(f.seq, f.decoded.disparity))
            if "mp4" in cfg.save or "mp4-lossless" in cfg.save:
                if not self._plane_writers:
                    lossless = "mp4-lossless" in cfg.save
                    # one encoder thread per plane: this stage feeds a dozen writers in turn,
                    # and x264's own frame threads per writer only oversubscribe the cores
                    # low delay, so
                    # that closing does not encode a backlog of every plane (crf 17: the
                    # short lookahead's quality at crf 18 was 0.4 dB lower); the fast motion
                    # search takes a third off x264's time for the same bytes and quality
                    self._plane_writers = [
                        VideoWriter(self.out / f"plane_{k:02d}.mp4", cfg.fps, lossless=lossless, crf=17, preset="veryfast",
                                    metadata={"comment": plane_label(k, s)}, threads=1, low_delay=True,
                                    fast_search=True)
                        for k, s in enumerate(self._plane_log[-1]["slopes"] or [None] * len(f.stack))]
                for w, img in zip(self._plane_writers, f.stack):
                    w.write(img)
            if "sweep" in cfg.save:
                if self._sweep is None:
                    self._sweep = VideoWriter(self.out / "focal_sweep.mp4", cfg.fps, lossless=False, crf=20,
                                              preset="veryfast", low_delay=True, fast_search=True)
                self._sweep.write(f.stack[f.seq % len(f.stack)])
            if "png" in cfg.save:
                folder = self.out / "frames" / f"frame_{f.seq:06d}"
                folder.mkdir(parents=True, exist_ok=True)
                for k, img in enumerate(f.stack):
                    write_image(folder / f"plane_{k:02d}.png", img)
        if "lf" in cfg.save:
            if self._lf_writer is None:
                u, v = f.decoded.lf.shape[:2]
                self._lf_writer = VideoWriter(self.out / "reconstructed.avi", cfg.fps, lossless=True,
                                              metadata=grid_metadata((u, v)))
            self._lf_writer.write(to_mosaic(f.decoded.lf))

    def close(self) -> None:
        """Finalises every open file (also after an error or Ctrl-C)."""
        errors = []
        if self._slopes is not None:
            from lfstream.refocus.planes import plane_records

            planes = plane_records(self._slopes, self.config.camera)
            try:
                atomic_write_text(self.out / "planes.json", json.dumps({"planes": planes, "updates": self._plane_log},
                                                                        indent=1))
                self.files.append(str(self.out / "planes.json"))
                from lfstream.viewer import write_disparity_json

                self.files.append(str(write_disparity_json(self.out, self._disparity)))
            except LFStreamError as exc:
                errors.append(str(exc))
        for w in [*self._plane_writers, self._sweep, self._lf_writer]:
            if w is None:
                continue
            try:
                w.close()
                if w.frames:
                    self.files.append(str(w.path))
            except LFStreamError as exc:
                errors.append(str(exc))
        if errors:
            raise LFFileError("; ".join(errors))


def plane_label(index: int, slope: float | None) -> str:
    """``lfstream-plane=K slope=S alpha=A``: what a plane video records about its plane."""
    if slope is None:
        return f"lfstream-plane={index}"
    from lfstream.optics import alpha_from_slope

    alpha = f"{alpha_from_slope(slope):.4g}" if slope < 1 else "none"
    return f"lfstream-plane={index} slope={slope:+.4f} alpha={alpha}"


def contact_sheet(stack: np.ndarray, slopes: list[float], columns: int = 4, width: int = 240) -> np.ndarray:
    """One image of a focal stack: the planes as labelled thumbnails, row by row.

    Shape:
        - stack: ``(K, H, W, 3)`` uint8
        - output: ``(rows * (h + 18), columns * w, 3)`` uint8, ``w <= width``
    """
    k, h, w = stack.shape[:3]
    scale = min(1.0, width / w)
    tw, th = max(1, int(round(w * scale))), max(1, int(round(h * scale)))
    cols = min(columns, k)
    rows = -(-k // cols)
    label_h = 18
    sheet = np.full((rows * (th + label_h), cols * tw, 3), 255, np.uint8)
    for i, (img, s) in enumerate(zip(stack, slopes)):
        r, c = divmod(i, cols)
        y, x = r * (th + label_h), c * tw
        sheet[y + label_h:y + label_h + th, x:x + tw] = cv2.resize(img, (tw, th), interpolation=cv2.INTER_AREA)
        cv2.putText(sheet, f"{i}: slope {s:+.2f}", (x + 3, y + 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1,
                    cv2.LINE_AA)
    return sheet


__all__ = ["Sink", "plane_label", "contact_sheet"]
