"""The sink: focal stacks and reconstructed light fields to files, finalised on any exit."""

from __future__ import annotations

from pathlib import Path

from lfstream.errors import LFFileError, LFStreamError
from lfstream.io import VideoWriter, grid_metadata, write_image
from lfstream.lightfield import to_mosaic
from lfstream.stream.config import StreamConfig
from lfstream.stream.frames import StackFrame


class Sink:
    """Writes focal stacks (MP4 per plane, PNG per plane and frame, a focal-sweep MP4) and
    optionally the reconstructed LF (lossless FFV1 mosaic video)."""

    def __init__(self, out: Path, config: StreamConfig) -> None:
        self.out = out
        self.config = config
        self.files: list[str] = []
        self._plane_writers: list = []
        self._sweep = None
        self._lf_writer = None

    def write(self, f: StackFrame) -> None:
        cfg = self.config
        if f.stack is not None:
            if "mp4" in cfg.save or "mp4-lossless" in cfg.save:
                if not self._plane_writers:
                    lossless = "mp4-lossless" in cfg.save
                    self._plane_writers = [VideoWriter(self.out / f"plane_{k:02d}.mp4", cfg.fps, lossless=lossless,
                                                       crf=18, preset="veryfast") for k in range(len(f.stack))]
                for w, img in zip(self._plane_writers, f.stack):
                    w.write(img)
            if "sweep" in cfg.save:
                if self._sweep is None:
                    self._sweep = VideoWriter(self.out / "focal_sweep.mp4", cfg.fps, lossless=False, crf=20,
                                              preset="veryfast")
                self._sweep.write(f.stack[f.seq % len(f.stack)])
            if "png" in cfg.save:
                folder = self.out / "frames" / f"frame_{f.seq:06d}"
                folder.mkdir(parents=True, exist_ok=True)
                for k, img in enumerate(f.stack):
                    write_image(folder / f"plane_{k:02d}.png", img)
        if "lf" in cfg.save:
            if self._lf_writer is None:
                u, v = f.decoded.lf.shape[:2]
                self._lf_writer = VideoWriter(self.out / "reconstructed.mkv", cfg.fps, lossless=True,
                                              metadata=grid_metadata((u, v)))
            self._lf_writer.write(to_mosaic(f.decoded.lf))

    def close(self) -> None:
        """Finalises every open file (also after an error or Ctrl-C)."""
        errors = []
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


__all__ = ["Sink"]
