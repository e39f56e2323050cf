"""Shared fixtures: sample data location, device/dtype parametrisation, tolerances."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import settings

# CI draws the property tests' examples from a fixed seed, so a landing does not hinge on
# which random examples a run drew (one run found a real bug that way: the fix and its
# regression test are in tests/codec/hint/test_hint.py); a local run keeps drawing new ones, and
# tools/fuzz_codec.py is the long random run
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"

# the built-in clip's cache (lfstream.stream.sources.cache_dir) goes to a temporary folder,
# never into the user's ~/.cache, and starts empty for every test run
os.environ["LFSTREAM_CACHE"] = tempfile.mkdtemp(prefix="lfstream-test-cache-")

#: Absolute tolerance per floating dtype for values in [0, 1].
TOLERANCE = {torch.float64: 1e-9, torch.float32: 1e-5, torch.float16: 2e-3, torch.bfloat16: 1e-2}

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.fixture(params=DEVICES)
def device(request) -> torch.device:
    return torch.device(request.param)


@pytest.fixture(params=[torch.float32, torch.float64], ids=["f32", "f64"])
def dtype(request) -> torch.dtype:
    return request.param


def shared(*parts: str) -> Path:
    """Path under ../shared/data; skips the test where the samples are absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"sample data not present: {p}")
    return p


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def random_lf(rng: np.random.Generator, shape=(3, 5, 12, 16, 3)) -> np.ndarray:
    return rng.integers(0, 256, size=shape, dtype=np.uint8)


def shifted_views(lf: np.ndarray, idx, slope: float) -> np.ndarray:
    """The listed views (u, v) of ``lf`` (U, V, H, W[, C]) resampled at (y - slope*du, x - slope*dv),
    i.e. aligned to the centre view for content at disparity ``slope``: (n, H, W[, C]) float32."""
    import cv2

    from lfstream.lightfield import as_float

    u0, v0 = lf.shape[0] // 2, lf.shape[1] // 2
    out = []
    for u, v in idx:
        m = np.float32([[1, 0, -slope * (v - v0)], [0, 1, -slope * (u - u0)]])
        out.append(cv2.warpAffine(as_float(lf[u, v]), m, (lf.shape[3], lf.shape[2]),
                                  flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP))
    return np.stack(out)


@pytest.fixture(scope="module")
def unpredictable():
    """Views that no disparity explains: each a smooth texture moved by its own random
    offset (as a camera rig that is not a grid), which a sequence codec's motion search
    follows and a warp of the centre view cannot."""
    import cv2

    rng = np.random.default_rng(5)
    base = cv2.GaussianBlur(rng.uniform(0, 255, (96, 128, 3)).astype(np.float32), (0, 0), 2.5)
    base = cv2.normalize(base, None, 0, 255, cv2.NORM_MINMAX)
    lf = np.empty((5, 5, 64, 96, 3), np.uint8)
    for a in range(5):
        for b in range(5):
            dy, dx = (0, 0) if (a, b) == (2, 2) else rng.integers(0, 32, 2)
            lf[a, b] = np.clip(base[dy:dy + 64, dx:dx + 96] + 0.5, 0, 255).astype(np.uint8)
    return lf
