"""Rate control by the model (lfstream.codec.rate.model): its size model against the sizes it
then measures, the families it picks, a video held to its budget, and its fit against the
exhaustive search on the same scene."""

import numpy as np
import pytest

import lfstream
from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.rate import SEARCHES
from lfstream.codec.rate import model as rate_model
from lfstream.codec.rate.follow import FRAME_CAP
from lfstream.codec.rate.model import (
    RATE_TOLERANCE_MODEL,
    SEQUENCE_CODINGS,
    _crop,
    choose_rate,
    fit_quality,
    quality_for,
)
from lfstream.errors import LFValueError
from lfstream.metrics import bpp, mpsnr
from lfstream.synth import synth_clip


@pytest.fixture(scope="module")
def frame():
    """A 5x5 frame large enough for AV1 trials on a mosaic of the views."""
    return np.ascontiguousarray(synth_clip(1, 5, (192, 256), seed=3, noise=2.0, vignetting=0.2).lf)


def _log_linear(a: float, b: float):
    calls = []

    def size(q: int) -> int:
        calls.append(q)
        return int(np.exp(a + b * q))

    return size, calls


@pytest.mark.parametrize("target", [3e3, 2e4, 9e4])
def test_fit_quality_lands_near_the_target_in_few_probes(target):
    """A log-linear size curve (the codecs' shape) is fitted in at most three probes, within
    one quality step, and not past the tolerance."""
    size, calls = _log_linear(7.0, 0.045)
    q = fit_quality(size, target, 0.038)
    assert len(calls) <= 3
    exact = (np.log(target) - 7.0) / 0.045
    assert abs(q - exact) <= 1.0
    assert size(q) <= target * 1.08


def test_fit_quality_stays_within_the_range_and_under_the_limit():
    size, _ = _log_linear(9.0, 0.05)
    assert fit_quality(size, 1.0, 0.04) == QUALITY_RANGE[0]  # nothing fits: the smallest probed
    assert fit_quality(size, 1e12, 0.04) == QUALITY_RANGE[1]


def test_quality_for_follows_the_prior_slope():
    assert quality_for(1000.0, 40, 1000.0) == 40
    up = quality_for(1000.0, 40, 1000.0 * np.exp(0.038 * 10))
    assert up == 50
    assert quality_for(1.0, 40, 1e12) == QUALITY_RANGE[1]


def test_the_trial_mosaic_takes_a_quarter_of_every_view_from_all_four_quadrants():
    lf = np.zeros((7, 7, 384, 544, 3), np.uint8)  # large enough for a mosaic (TRIAL_WHOLE_PIXELS)
    lf[:, :, :192, :272] = 10  # each quadrant its own value
    lf[:, :, :192, 272:] = 20
    lf[:, :, 192:, :272] = 30
    lf[:, :, 192:, 272:] = 40
    m = _crop(lf)
    assert m.shape[2] * m.shape[3] <= 384 * 544 // 4 and m.shape[2] % 16 == 0 and m.shape[3] % 16 == 0
    assert set(np.unique(m)) == {10, 20, 30, 40}
    small = np.zeros((3, 3, 192, 256, 3), np.uint8)
    assert _crop(small).shape == small.shape  # a small light field: tried whole


@pytest.mark.parametrize("target", [0.05, 0.15])
def test_the_model_lands_within_the_tolerance_and_reports_its_predictions(frame, target):
    choice = choose_rate(frame, target, 30.0)
    got = bpp(len(choice.stream()), frame.shape)
    assert abs(got - target) / target <= RATE_TOLERANCE_MODEL, (target, got)
    families = {c["family"] for c in choice.candidates}
    assert families == {"centre", "prediction", "views"}
    coded = [c for c in choice.candidates if c["coded"]]
    assert coded and all(np.isfinite(c["predicted_db"]) for c in choice.candidates)
    # the size model predicted the coded family's bytes within a third before coding it
    for c in coded:
        assert abs(np.log(c["bpp"] / c["predicted_bpp"])) < np.log(1.34), c
    # the stream is what it says: decoded, it has the measured quality
    dec = lfstream.decode(choice.stream())[0]
    assert float(mpsnr(frame[0], dec)) == pytest.approx(choice.mpsnr_first_frame, abs=1e-6)


def test_the_model_codes_fewer_sequences_than_the_full_search_within_its_stated_bound(frame, monkeypatch):
    from lfstream.codec import residual

    calls = {"n": 0}
    real = residual._encode_sequence

    def counting(*a, **k):
        calls["n"] += 1
        return real(*a, **k)

    monkeypatch.setattr(residual, "_encode_sequence", counting)
    choose_rate(frame, 0.1, 30.0, search="model")
    model_calls = calls["n"]
    calls["n"] = 0
    choose_rate(frame, 0.1, 30.0, search="full")
    # at most two trials a family, and SEQUENCE_CODINGS codings of each of at most two families
    assert model_calls <= 2 * 2 + 2 * SEQUENCE_CODINGS
    assert model_calls < calls["n"], (model_calls, calls["n"])


def test_the_model_keeps_the_full_searchs_quality(frame):
    """Within a fraction of a dB of the exhaustive search at about the same size."""
    model = choose_rate(frame, 0.1, 30.0, search="model")
    full = choose_rate(frame, 0.1, 30.0, search="full")
    assert model.mpsnr_first_frame >= full.mpsnr_first_frame - 0.5, (model.candidates, full.bpp)


def test_a_video_is_held_to_its_budget_and_no_frame_passes_the_cap():
    clip = np.ascontiguousarray(synth_clip(6, 5, (192, 256), seed=8, noise=2.0, motion=0.5).lf)
    choice = choose_rate(clip, 0.08, 30.0)
    data = choice.stream()
    assert abs(bpp(len(data), clip.shape) - 0.08) / 0.08 <= 0.10
    frame_bpp = [bpp(p.size(choice.header.version), clip.shape[1:]) for p in choice.packets]
    assert max(frame_bpp) <= FRAME_CAP * 0.08
    assert lfstream.decode(data).shape == clip.shape


def test_the_candidate_rows_have_one_schema_whatever_the_search(frame):
    model = choose_rate(frame, 0.1, 30.0, search="model").candidates
    full = choose_rate(frame, 0.1, 30.0, search="full").candidates
    keys = {frozenset(c) for c in model + full}
    assert len(keys) == 1, keys
    assert {c["family"] for c in full} <= {"centre", "prediction", "views"}


def test_the_model_is_the_default_search_and_the_fast_preset_keeps_the_quick_one(frame, monkeypatch):
    seen = []
    monkeypatch.setattr(rate_model, "model_configuration", lambda *a, **k: seen.append("model"))
    monkeypatch.setattr(rate_model, "choose_configuration", lambda *a, search=None, **k: seen.append(search))
    choose_rate(frame, 0.1, 30.0)
    choose_rate(frame, 0.1, 30.0, preset="fast")
    assert seen == ["model", "full", "quick"]  # the model returned None: the full search decided
    assert SEARCHES[0] == "model"
    with pytest.raises(LFValueError, match="search"):
        choose_rate(frame, 0.1, 30.0, search="exhaustive")
