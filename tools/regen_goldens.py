"""Regenerates the frame-level regression goldens in tests/goldens/ — deliberately.

    ACCEPT=1 python tools/regen_goldens.py

Without ACCEPT=1 it prints the values it would write and the differences to the current
goldens, and writes nothing. The clips are defined in :func:`golden_cases` (shared with the
test, so the test and this tool can never disagree on what is measured). The files are
``lfstream golden`` files (:mod:`lfstream.testing.golden`): the pipeline's per-frame bpp,
MPSNR, MSSIM and focal-stack PSNR, and the decoder's frames (digests and metrics against
the input).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
GOLDEN_DIR = ROOT / "tests" / "goldens"
SHARED = ROOT.parent / "shared" / "data"
#: Metric -> tolerance of the pipeline goldens (bpp relative): JPEG and the warp are
#: deterministic, the slack covers float summation order across BLAS/OpenCV builds.
PIPELINE_TOLERANCE = {"bpp": {"rel": 0.01}, "mpsnr": {"abs": 0.05}, "mssim": {"abs": 1e-3},
                      "stack_psnr": {"abs": 0.05}}
#: The pipeline's configuration the goldens pin (the seed's planes: the goldens pin the codec
#: and the renderer; auto focus is tested apart).
PIPELINE_SETTINGS = {"refocus": "sas", "alphas": "seed", "mssim_every": 1, "save": []}


def golden_cases() -> dict:
    """name -> list of frames (U, V, H, W, 3) uint8; the real case only where the samples exist."""
    from lfstream.stream import synthetic_source

    cases = {"synthetic": list(synthetic_source(frames=4, views=7, size=(64, 96), seed=11))}
    sea = SHARED / "seahorse5x5" / "camImagesFlat"
    if sea.exists():
        from lfstream.io import read_lf

        lf = read_lf(sea)
        # a slow pan: a 128x160 window moving 6 px right and 3 px down per frame
        cases["seahorse_pan"] = [np.ascontiguousarray(lf[:, :, 180 + 3 * t:308 + 3 * t, 150 + 6 * t:310 + 6 * t])
                                 for t in range(4)]
    return cases


def measure(frames: list[np.ndarray]) -> list[dict]:
    """The pipeline's per-frame rows: frame, bpp, mpsnr, mssim, stack_psnr."""
    from lfstream.stream import Pipeline, StreamConfig

    settings = {**PIPELINE_SETTINGS, "save": tuple(PIPELINE_SETTINGS["save"])}
    summary = Pipeline(iter(frames), StreamConfig(**settings), None).run()
    return [{k: row[k] for k in ("frame", "bpp", "mpsnr", "mssim", "stack_psnr")} for row in summary["per_frame"]]


def decoded(frames: list[np.ndarray]) -> np.ndarray:
    """The default encode of ``frames`` decoded: the frames the decoder's golden pins."""
    import lfstream

    return lfstream.decode(lfstream.encode(np.stack(frames)))


def goldens() -> dict[str, object]:
    """file name -> the :class:`~lfstream.testing.golden.Golden` to write there."""
    from lfstream.testing import golden

    out = {}
    for name, frames in golden_cases().items():
        out[f"pipeline_{name}.json"] = golden.golden_from_rows(
            measure(frames), PIPELINE_TOLERANCE, settings={"pipeline": PIPELINE_SETTINGS, "case": name})
    frames = golden_cases()["synthetic"]
    g = golden.record(decoded(frames), reference=np.stack(frames),
                      settings={"encode": "lfstream.encode defaults", "case": "synthetic"})
    g.reference = "tools/regen_goldens.py golden_cases()['synthetic']"
    out["decode_synthetic.json"] = g
    return out


def main(argv: list[str] | None = None) -> int:
    from lfstream.testing.golden import load_golden

    accept = os.environ.get("ACCEPT") == "1"
    for file, new in goldens().items():
        path = GOLDEN_DIR / file
        old = {f.frame: f for f in load_golden(path).frames} if path.exists() else {}
        for f in new.frames:
            prev = old.get(f.frame)
            diffs = {m: round(v - prev.metrics[m], 5) for m, v in f.metrics.items() if prev and m in prev.metrics}
            same = prev is not None and prev.sha256 == f.sha256 and f.sha256 is not None
            print(f"{file} frame {f.frame}: {f.metrics}  diff {diffs}{'  (same bytes)' if same else ''}")
        if accept:
            new.write(path, overwrite=True)
            print(f"wrote {path}")
    if not accept:
        print("nothing written (set ACCEPT=1 to accept these values)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
