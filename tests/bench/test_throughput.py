"""bench/throughput.py's real clip: real views under a panning window, written frame by frame."""

import importlib.util
import sys

import numpy as np
import pytest

from tests.conftest import ROOT

SAMPLE = ROOT.parent / "shared" / "data" / "lytro_translucent"


def _throughput():
    # bench/ on the path's end (its _harness is imported by name; nothing of the library's shadowed)
    if str(ROOT / "bench") not in sys.path:
        sys.path.append(str(ROOT / "bench"))
    spec = importlib.util.spec_from_file_location("bench_throughput", ROOT / "bench" / "throughput.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(not SAMPLE.exists(), reason="needs ../shared/data/lytro_translucent")
def test_the_real_clip_is_a_window_panning_over_the_sample(tmp_path, monkeypatch):
    import lfstream

    throughput = _throughput()
    monkeypatch.setattr(throughput, "REAL_CLIP_FRAMES", 4)
    path = tmp_path / "clip.npy"
    assert throughput.real_clip(path)
    clip = np.load(path, mmap_mode="r")
    lf = lfstream.read_lf(SAMPLE)
    h, w = throughput.REAL_CLIP_SIZE
    assert clip.shape == (4, *lf.shape[:2], h, w, 3) and clip.dtype == np.uint8
    for k in range(4):
        # each frame is one window of the sample's views, all views alike
        y0 = lf.shape[2] - h - abs((2 * k) % (2 * (lf.shape[2] - h)) - (lf.shape[2] - h))
        x0 = lf.shape[3] - w - abs((3 * k) % (2 * (lf.shape[3] - w)) - (lf.shape[3] - w))
        assert np.array_equal(clip[k], lf[:, :, y0:y0 + h, x0:x0 + w])
    assert not np.array_equal(clip[0], clip[1])  # it moves
