"""bench/ab.py's statistics: paired per-round ratios, their median and bootstrap interval."""

import importlib.util

import numpy as np

from tests.conftest import ROOT

# loaded from its file, not through sys.path: bench/ holds modules named codec, synth, ...
_spec = importlib.util.spec_from_file_location("bench_ab", ROOT / "bench" / "ab.py")
ab = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ab)


def _rounds(times, digest="x", cpu=None):
    return [{"s": {"wall_s": t, "cpu_s": t if cpu is None else cpu, "digest": digest}} for t in times]


def test_a_change_ten_percent_faster_under_drift_is_found():
    # the host slows down round by round (drift of 2x); head is 10 % faster in every round,
    # measured right after base: the per-round ratios see it, the pooled medians would not
    rng = np.random.default_rng(3)
    drift = np.linspace(1.0, 2.0, 8)
    base = 0.030 * drift * (1 + 0.01 * rng.standard_normal(8))
    head = 0.9 * base * (1 + 0.01 * rng.standard_normal(8))
    s = ab.summarise(_rounds(base), _rounds(head))["s"]
    assert abs(s["ratio"] - 0.9) < 0.02
    lo, hi = s["ratio_90"]
    assert lo <= s["ratio"] <= hi and hi < 1.0 and hi - lo < 0.05
    assert s["head_faster_rounds"] == 8 and s["rounds"] == 8 and s["identical_outputs"]


def test_the_same_code_gives_an_interval_around_one_and_different_outputs_are_flagged():
    rng = np.random.default_rng(4)
    base = 0.030 * (1 + 0.05 * rng.standard_normal(12))
    head = 0.030 * (1 + 0.05 * rng.standard_normal(12))
    s = ab.summarise(_rounds(base), _rounds(head, digest="y"))["s"]
    lo, hi = s["ratio_90"]
    assert lo < 1.0 < hi
    assert not s["identical_outputs"]
    assert s["base_s"] == np.median(base) and s["head_s"] == np.median(head)
