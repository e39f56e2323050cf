"""lfstream.testing: frame metrics against lfstream.metrics, thresholds, streaming inputs,
assert_lf_close's messages, golden files, the HTML report."""

import json

import numpy as np
import pytest

import lfstream
from lfstream.errors import LFShapeError, LFValueError
from lfstream.metrics import mpsnr, mssim, psnr
from lfstream.testing import Thresholds, assert_lf_close, compare, compare_report, frame_metrics
from lfstream.testing import golden as gold


def _clip(rng, frames=5, shape=(3, 3, 24, 28, 3)):
    return rng.integers(0, 256, size=(frames, *shape), dtype=np.uint8)


def _degrade(frame, rng, amount=12, view=None):
    out = frame.copy()
    target = out if view is None else out[view]
    noise = rng.integers(-amount, amount + 1, size=target.shape)
    target[...] = np.clip(target.astype(int) + noise, 0, 255).astype(np.uint8)
    return out


def test_frame_metrics_agree_with_lfstream_metrics(rng):
    a = _clip(rng, 1)[0]
    b = _degrade(a, rng)
    m = frame_metrics(a, b)
    assert m.mpsnr == pytest.approx(mpsnr(a, b), abs=1e-9)
    assert m.mssim == pytest.approx(mssim(a, b), abs=1e-9)
    per_view = psnr(a, b)
    assert m.worst_view == tuple(int(i) for i in np.unravel_index(np.argmin(per_view), per_view.shape))
    assert m.max_abs == np.abs(a.astype(int) - b.astype(int)).max()


def test_float_input_is_compared_on_the_8_bit_scale(rng):
    a = _clip(rng, 1)[0]
    m = frame_metrics(a, a.astype(np.float32) / 255)
    assert m.max_abs < 1e-3 and m.mpsnr > 90


def test_one_degraded_frame_is_exactly_the_failing_frame(rng):
    ref = _clip(rng, 6)
    test = ref.copy()
    test[4] = _degrade(ref[4], rng, amount=30)
    results = list(compare(ref, test, Thresholds(min_psnr=35)))
    assert [r.frame for r in results if not r.passed] == [4]
    assert all(r.identical for r in results if r.frame != 4)


def test_identical_inputs_pass_with_no_threshold_and_a_change_does_not(rng):
    ref = _clip(rng, 3)
    assert all(r.passed and r.identical for r in compare(ref, ref.copy()))
    moved = ref.copy()
    moved[1, 0, 0, 0, 0, 0] ^= 1
    assert [r.passed for r in compare(ref, moved)] == [True, False, True]


def test_scope_view_judges_the_worst_view_and_frame_the_mean(rng):
    ref = _clip(rng, 1)
    test = _degrade(ref, rng, amount=3)
    test[0] = _degrade(test[0], rng, amount=60, view=(0, 0))  # one bad view among nine
    m = frame_metrics(ref[0], test[0])
    floor = (m.mpsnr + float(np.nanmin(m.psnr))) / 2  # between the worst view and the mean
    per_view = list(compare(ref, test, Thresholds(min_psnr=floor, scope="view")))
    per_frame = list(compare(ref, test, Thresholds(min_psnr=floor, scope="frame")))
    assert not per_view[0].passed and "view (0, 0)" in per_view[0].failures[0]
    assert per_frame[0].passed


def test_thresholds_are_checked(rng):
    with pytest.raises(LFValueError):
        Thresholds(scope="pixel")
    with pytest.raises(LFValueError):
        Thresholds(min_psnr=float("nan"))


def test_shapes_and_lengths_must_agree(rng):
    ref = _clip(rng, 3)
    with pytest.raises(LFShapeError):
        list(compare(ref, ref[:, :, :, :20]))
    with pytest.raises(LFShapeError):
        list(compare(ref, ref[:2]))


def test_missing_views_are_left_out(rng):
    a = _clip(rng, 1)[0]
    b = a.copy()
    b[0, 0] = 0  # a missing view, zero-filled
    present = np.ones((3, 3), bool)
    present[0, 0] = False
    m = frame_metrics(a, b, present)
    assert np.isnan(m.psnr[0, 0]) and m.max_abs == 0 and np.isinf(m.mpsnr)


def test_paths_stream_frame_by_frame_with_frame_numbers_of_the_source(tmp_path, rng):
    ref = _clip(rng, 8)
    test = ref.copy()
    test[6] = _degrade(ref[6], rng, amount=30)
    np.save(tmp_path / "ref.npy", ref)
    lfstream.write_lf(tmp_path / "test.avi", test)  # a lossless mosaic video, read lazily
    opts = lfstream.ReadOptions(first_frame=5, max_frames=2)
    results = list(compare(tmp_path / "ref.npy", tmp_path / "test.avi", Thresholds(min_psnr=35), options=opts))
    assert [(r.frame, r.passed) for r in results] == [(5, True), (6, False)]


def test_assert_lf_close_names_frame_view_and_metric(rng):
    ref = _clip(rng, 4)
    test = ref.copy()
    test[2] = _degrade(ref[2], rng, amount=40, view=(1, 2))
    assert_lf_close(ref, ref.copy())
    assert_lf_close(test, ref, min_psnr=10)
    with pytest.raises(AssertionError) as e:
        assert_lf_close(test, ref, min_psnr=35)
    msg = str(e.value)
    assert "1 of 4 frames" in msg and "frame 2" in msg and "view (1, 2)" in msg and "PSNR" in msg
    with pytest.raises(AssertionError, match="max |diff|"):
        assert_lf_close(test, ref, max_abs=3)
    with pytest.raises(AssertionError, match="not comparable"):
        assert_lf_close(ref[:, :2], ref)


def test_golden_record_and_check_classify_every_frame(tmp_path, rng):
    original = _clip(rng, 5)
    decoded = original.copy()
    decoded[:] = np.clip(original.astype(int) + 3, 0, 255)  # a lossy decode
    g = gold.record(decoded, reference=original, settings={"why": "test"})
    path = g.write(tmp_path / "g.json")
    loaded = gold.load_golden(path)
    assert len(loaded.frames) == 5 and loaded.settings == {"why": "test"} and loaded.lfstream
    assert gold.check(decoded, loaded, reference=original).frames_with("identical") == list(range(5))

    now = decoded.copy()
    now[1, 0, 0, 0, 0, 0] ^= 1  # one sample: within tolerance
    now[3] = _degrade(original[3], rng, amount=40)  # far worse
    report = gold.check(now, loaded, reference=original)
    assert report.frames_with("changed") == [1] and report.frames_with("regressed") == [3]
    assert not report.passed and report.to_json()["failed_frames"] == [3]
    # a golden without a reference: any change of bytes regresses (nothing says by how much)
    bare = gold.record(decoded)
    assert gold.check(now, bare).frames_with("regressed") == [1, 3]
    # a frame fewer: the last one is missing
    assert gold.check(decoded[:4], loaded, reference=original[:4]).frames_with("regressed") == [4]


def test_golden_strict_fails_an_improvement_beyond_tolerance(rng):
    g = gold.golden_from_rows([{"frame": 0, "mpsnr": 30.0, "bpp": 0.1}],
                              {"mpsnr": {"abs": 0.05}, "bpp": {"rel": 0.01}})
    better = [{"frame": 0, "mpsnr": 31.0, "bpp": 0.1}]
    assert gold.check_values(g, better, strict=False).frames_with("changed") == [0]
    assert gold.check_values(g, better, strict=True).frames_with("moved") == [0]
    bigger = [{"frame": 0, "mpsnr": 30.0, "bpp": 0.102}]  # 2 % more bits: worse
    assert gold.check_values(g, bigger).frames_with("regressed") == [0]
    assert gold.check_values(g, [{"frame": 0, "mpsnr": 30.01, "bpp": 0.1005}]).passed


def test_golden_files_are_checked_on_load(tmp_path):
    from lfstream.errors import LFFormatError

    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"frames": []}))
    with pytest.raises(LFFormatError, match="not a golden file"):
        gold.load_golden(bad)
    bad.write_text("{")
    with pytest.raises(LFFormatError):
        gold.load_golden(bad)


def test_html_report_is_self_contained(tmp_path, rng):
    from lfstream.testing.html import write_html

    ref = _clip(rng, 4)
    test = ref.copy()
    test[2] = _degrade(ref[2], rng, amount=30)
    report = compare_report(ref, test, Thresholds(min_psnr=35), keep_worst=True)
    assert report.worst[0] == 2
    page = write_html(report, tmp_path / "r.html").read_text()
    assert "failed: frames 2" in page and page.count("data:image/png;base64,") == 4  # heat map + 3 crops
    assert "http://" not in page.replace("http://www.w3.org/2000/svg", "")  # nothing fetched
