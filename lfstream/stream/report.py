"""What a stream run reports: typed statistics each stage owns, and the summary built
from them once every stage has finished (no field is written by two threads)."""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lfstream.io._fs import atomic_write_text


@dataclass
class StageStats:
    """Frames a stage handled, the wall time it was busy and the CPU time its own thread
    spent meanwhile (its own thread writes it). The CPU of the worker threads a parallel
    kernel starts is in the process's total (the summary's ``process_cpu_s``), not here."""

    name: str
    frames: int = 0
    busy_s: float = 0.0
    cpu_s: float = 0.0

    def add(self, frames: int, seconds: float, cpu_seconds: float = 0.0) -> None:
        self.frames += frames
        self.busy_s += seconds
        self.cpu_s += cpu_seconds

    def as_dict(self) -> dict:
        return {"frames": self.frames, "time_s": round(self.busy_s, 4), "thread_cpu_s": round(self.cpu_s, 4),
                "ms_per_frame": round(1e3 * self.busy_s / self.frames, 2) if self.frames else None,
                "fps": round(self.frames / self.busy_s, 2) if self.busy_s > 0 else None}


@dataclass
class RateStats:
    """Bytes the encoder produced (encoder thread)."""

    bytes: int = 0
    pixels: int = 0
    frame_bpp: dict[int, float] = field(default_factory=dict)
    frame_quality: dict[int, int] = field(default_factory=dict)  # the centre view's quality per frame

    def add(self, seq: int, n_bytes: int, pixels: int, quality: int | None = None) -> None:
        self.bytes += n_bytes
        self.pixels += pixels
        self.frame_bpp[seq] = n_bytes * 8 / float(pixels)
        if quality is not None:
            self.frame_quality[seq] = int(quality)


@dataclass
class StaticSkipStats:
    """Skip (a): frames whose disparity was reused (decoder thread)."""

    enabled: bool
    frames: int = 0
    saved_s: float = 0.0
    error_db: float | None = None  # the first skip, audited against a full decode
    full_decode_s: float = 0.0  # a full decode's time, measured at that audit

    def as_dict(self) -> dict:
        return {"enabled": self.enabled, "frames": self.frames, "saved_s": round(self.saved_s, 4),
                "error_mpsnr_db_vs_full": self.error_db}


@dataclass
class QualityStats:
    """Decoded frames against the input (metrics thread)."""

    mpsnr: list[tuple[int, float]] = field(default_factory=list)
    mssim: list[tuple[int, float]] = field(default_factory=list)
    stack_psnr: dict[int, float] = field(default_factory=dict)


def build_summary(*, wall_s: float, warmup_s: float = 0.0, process_cpu_s: float | None = None, frames: int,
                  stages: dict[str, StageStats], rate: RateStats,
                  quality: QualityStats, static: StaticSkipStats,
                  receive: dict | None, transport: str, refocus: dict | None, hance: dict,
                  interrupted: bool, outputs: list[str], focal_planes: list[dict] | None = None,
                  plane_updates: list[dict] | None = None, coding: dict | None = None) -> dict:
    """The summary a run returns and writes as ``summary.json`` (keys are a contract)."""
    out = {
        "frames": frames,
        "fps": round(frames / wall_s, 3) if wall_s > 0 else None,
        "wall_s": round(wall_s, 3),
        # the whole process's CPU over the same time: every stage and every kernel's workers
        "process_cpu_s": None if process_cpu_s is None else round(process_cpu_s, 3),
        # loading the compiled kernels before the clock started (lfstream.stream.warmup)
        "warmup_s": round(warmup_s, 3),
        "bpp": (rate.bytes * 8 / rate.pixels) if rate.pixels else None,
        "bytes": rate.bytes,
        # what the encoder coded (the default chooses on the first frame: lfstream.codec.rate)
        "coding": coding,
        "mpsnr": float(np.mean([p for _, p in quality.mpsnr])) if quality.mpsnr else None,
        "mssim": float(np.mean([s for _, s in quality.mssim])) if quality.mssim else None,
        "per_frame": [{"frame": k, "mpsnr": round(p, 4)} for k, p in quality.mpsnr],
        "mssim_frames": [k for k, _ in quality.mssim],
        "stages": {k: v.as_dict() for k, v in stages.items() if v.frames},
        "lost": receive["lost"] if receive else 0,
        "transport": {"kind": transport, **(receive or {})},
        "refocus": refocus,
        "planes": focal_planes or [],  # index, slope, alpha of every focal plane (as at the end)
        "plane_updates": plane_updates or [],  # frame and slopes each time the planes were fitted
        "skips": {"static_frames": static.as_dict(), "jpeg_hance": hance},
        "interrupted": interrupted,
        "outputs": outputs,
    }
    ssim_of = dict(quality.mssim)
    for row in out["per_frame"]:
        k = row["frame"]
        if k in rate.frame_bpp:
            row["bpp"] = round(rate.frame_bpp[k], 6)
        if k in rate.frame_quality:
            row["quality"] = rate.frame_quality[k]
        if k in ssim_of:
            row["mssim"] = round(ssim_of[k], 6)
        if k in quality.stack_psnr:
            row["stack_psnr"] = round(quality.stack_psnr[k], 4)
    return out


def stopped_summary(transport: str) -> dict:
    """The summary of a run stopped (Ctrl-C) before any stage ran: the same keys as every
    summary, nothing done, ``interrupted`` true."""
    return build_summary(wall_s=0.0, frames=0, stages={}, rate=RateStats(), quality=QualityStats(),
                         static=StaticSkipStats(enabled=False), receive=None,
                         transport=transport, refocus=None,
                         hance={"mode": None, "networks": None, "ran": False, "precision": None},
                         interrupted=True, outputs=[])


def write_summary(out: Path, summary: dict) -> None:
    """``summary.json`` in ``out``, written atomically."""
    # strict JSON (RFC 8259): the summary caps PSNR, and a non-finite value left would be a bug
    atomic_write_text(Path(out) / "summary.json", json.dumps(summary, indent=2, default=str, allow_nan=False))


def stderr_progress(line: str) -> None:
    """A status line rewritten in place on stderr."""
    sys.stderr.write("\r" + line[:200].ljust(120))
    sys.stderr.flush()


__all__ = ["StageStats", "RateStats", "StaticSkipStats", "QualityStats", "build_summary",
           "stopped_summary", "write_summary", "stderr_progress"]
