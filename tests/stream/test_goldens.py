"""Frame-level regression: per-frame bpp, MPSNR, MSSIM and focal-stack PSNR of the pipeline
on a deterministic synthetic clip and a real slow pan (seahorse), against tests/goldens/.

Regenerate deliberately with ``ACCEPT=1 python tools/regen_goldens.py``.
"""

import json
import sys

import pytest

from tests.conftest import ROOT

sys.path.insert(0, str(ROOT / "tools"))
import regen_goldens  # noqa: E402

# metric -> absolute tolerance (bpp: relative); JPEG and the warp are deterministic, the
# slack covers float summation order across BLAS/OpenCV builds
TOLERANCE = {"bpp": 0.01, "mpsnr": 0.05, "mssim": 1e-3, "stack_psnr": 0.05}
CASES = regen_goldens.golden_cases()


@pytest.mark.parametrize("case", ["synthetic", "seahorse_pan"])
def test_pipeline_matches_goldens(case):
    if case not in CASES:
        pytest.skip("sample data not present for this case")
    golden = json.loads((regen_goldens.GOLDEN_DIR / f"pipeline_{case}.json").read_text())["frames"]
    rows = regen_goldens.measure(CASES[case])
    assert len(rows) == len(golden), f"{case}: {len(rows)} frames, golden has {len(golden)}"
    moved = []
    for row, ref in zip(rows, golden):
        for metric, tol in TOLERANCE.items():
            limit = tol * abs(ref[metric]) if metric == "bpp" else tol
            if abs(row[metric] - ref[metric]) > limit:
                moved.append(f"frame {row['frame']} {metric}: {row[metric]} vs golden {ref[metric]} (tolerance {limit:.3g})")
    assert not moved, f"{case} moved:\n" + "\n".join(moved)


def test_encoder_bitstream_is_bit_exact_reproducible():
    import numpy as np

    import lfstream

    frames = np.stack(CASES["synthetic"])
    a = lfstream.encode(frames, depth_hint=True)
    b = lfstream.encode(frames.copy(), depth_hint=True)
    assert a == b
