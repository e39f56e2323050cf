"""Regenerates the frame-level regression goldens in tests/goldens/ — deliberately.

    ACCEPT=1 python tools/regen_goldens.py

Without ACCEPT=1 it prints the values it would write and the differences to the current
goldens, and writes nothing. The clips are defined in :func:`golden_cases` (shared with the
test, so the test and this tool can never disagree on what is measured).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
GOLDEN_DIR = ROOT / "tests" / "goldens"
SHARED = ROOT.parent / "shared" / "data"


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
    from lfstream.stream import Pipeline, StreamConfig

    # the seed's planes: the goldens pin the codec and the renderer; auto focus is tested apart
    cfg = StreamConfig(refocus="sas", alphas="seed", mssim_every=1, save=())
    summary = Pipeline(iter(frames), cfg, None).run()
    return [{k: row[k] for k in ("frame", "bpp", "mpsnr", "mssim", "stack_psnr")} for row in summary["per_frame"]]


def main(argv: list[str] | None = None) -> int:
    accept = os.environ.get("ACCEPT") == "1"
    for name, frames in golden_cases().items():
        rows = measure(frames)
        path = GOLDEN_DIR / f"pipeline_{name}.json"
        old = json.loads(path.read_text())["frames"] if path.exists() else None
        for k, row in enumerate(rows):
            prev = old[k] if old and k < len(old) else {}
            diffs = {m: round(row[m] - prev[m], 5) for m in row if m in prev and m != "frame"}
            print(f"{name} frame {k}: {row}  diff {diffs}")
        if accept:
            GOLDEN_DIR.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"case": name, "frames": rows}, indent=1) + "\n")
            print(f"wrote {path}")
    if not accept:
        print("nothing written (set ACCEPT=1 to accept these values)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
