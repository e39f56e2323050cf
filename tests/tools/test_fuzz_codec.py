"""tools/fuzz_codec.py: the codec's random round trip (a short run here; the tool is the long one)."""

import numpy as np

import lfstream
from tools.fuzz_codec import CONTENTS, Case, draw_case, fuzz, main, run_case


def test_a_short_run_round_trips_every_case_it_does_not_refuse():
    result = fuzz(cases=10, seed=3, min_size=8, max_size=40)
    assert result["failed"] == 0, result["failures"]
    assert result["decoded"] + result["refused"] == 10 and result["decoded"] >= 5


def test_the_draws_cover_videos_single_frames_every_content_and_the_options():
    rng = np.random.default_rng(0)
    cases = [draw_case(rng, 8, 24) for _ in range(120)]
    assert {c.content for c in cases} == set(CONTENTS)
    assert {c.lf.ndim for c in cases} == {5, 6}
    assert all(c.lf.dtype == np.uint8 and 8 <= c.lf.shape[-3] <= 24 and 8 <= c.lf.shape[-2] <= 24 for c in cases)
    keys = set().union(*(c.options for c in cases))
    assert {"quality", "bpp", "preset", "residual", "depth_hint", "hance_map", "present"} <= keys
    assert all(c.options["present"][c.lf.shape[0] // 2, c.lf.shape[1] // 2] for c in cases if "present" in c.options)


def test_the_inverted_hint_range_case_decodes_and_a_broken_contract_is_reported(monkeypatch):
    lf = np.random.default_rng(984).integers(0, 256, (3, 3, 16, 16, 3), dtype=np.uint8)
    assert run_case(Case(lf, "noise", {"quality": 1})) == "decoded"
    real = lfstream.decode
    monkeypatch.setattr(lfstream, "decode", lambda data, **kw: real(data, **kw)[:, :1])  # a decoder that loses views
    result = fuzz(cases=3, seed=1, min_size=8, max_size=16)
    assert result["failed"] >= 1 and "AssertionError" in result["failures"][0]
    assert main(["--cases", "2", "--seed", "1", "--max-size", "16"]) == 1
