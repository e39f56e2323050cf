"""Shared benchmark harness: warm-up, repeated timing with median/IQR, metadata, JSON out.

Every script in bench/ reports ``{"metadata": {...}, "results": [...]}`` where each result
has at least ``name`` and timing fields ``median_s``, ``iqr_s``, ``runs``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

#: The real samples beside the repository (read ../shared/data/README.md).
SHARED = ROOT.parent / "shared" / "data"
#: Every real scene there, by the name benchmarks and training report it under -> the
#: folder (under :data:`SHARED`) that holds its light field.
SHARED_SCENES = {"seahorse": "seahorse5x5/camImagesFlat", "dino": "hci_star/dino", "cotton": "hci_star/cotton",
                 "lytro_bikes": "lytro_bikes", "lytro_translucent": "lytro_translucent", "toys_array": "toys_array"}
#: Shared scenes that networks may train on beside SHARED_SCENES and no benchmark measures.
TRAINING_SCENES = {"greek": "hci_star/greek", "kitchen": "hci_star/kitchen", "rosemary": "hci_star/rosemary"}


#: The instruction-set extensions a ratio can depend on (numba, OpenCV, the codecs pick
#: kernels by them): recorded with every result.
SIMD_FLAGS = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512bw", "avx512vl", "avx512_vnni", "avx512_bf16",
              "amx_tile", "amx_bf16")


def _version_of(module: str) -> str | None:
    try:
        return __import__(module).__version__
    except ImportError:  # e.g. a GPU machine without PyAV
        return None


def metadata() -> dict:
    import cv2
    import numba
    import torch

    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True, check=False).stdout.strip() or None
    except OSError:
        commit = None
    cpu = platform.processor() or platform.machine()
    flags: list[str] = []
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                elif line.startswith("flags"):
                    have = set(line.split(":", 1)[1].split())
                    flags = [f for f in SIMD_FLAGS if f in have]
                    break
    except OSError:
        pass
    return {
        "commit": commit,
        "versions": {"python": platform.python_version(), "torch": torch.__version__, "numpy": np.__version__,
                     "numba": numba.__version__, "opencv": cv2.__version__, "av": _version_of("av")},
        "device": {"cpu": cpu, "cores": os.cpu_count(), "flags": flags,
                   "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None},
        "threads": {"torch": torch.get_num_threads(), "numba": numba.get_num_threads()},
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def timeit(fn: Callable[[], object], runs: int = 5, warmup: int = 1) -> dict:
    """Median, inter-quartile range and best (``min_s``) of ``runs`` calls after ``warmup``
    calls."""
    for _ in range(warmup):
        fn()
    ts = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    q1, med, q3 = np.percentile(ts, [25, 50, 75])
    return {"median_s": float(med), "iqr_s": float(q3 - q1), "min_s": float(min(ts)), "runs": runs}


def parser(description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--json", type=Path, nargs="?", const=Path("-"), help="write JSON (to a file, or stdout with no value)")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--quick", action="store_true", help="smaller sizes, fewer runs (smoke test)")
    return p


def emit(args: argparse.Namespace, results: list[dict], extra: dict | None = None) -> dict:
    doc = {"metadata": metadata(), "results": results}
    if extra:
        doc.update(extra)
    if args.json is not None:
        text = json.dumps(doc, indent=2)
        if str(args.json) == "-":
            print(text)
        else:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(text)
    return doc
