"""The depth hint: the fused kernels against plain references, the per-scene range, the
temporal coding (full / delta / repeat), version-1 compatibility and loss handling."""

import struct

import numba
import numpy as np
import pytest
import zstandard

from lfstream.codec import hint as H
from lfstream.codec.hint.kernels import joint_upsample, sweep_cost, winner_subpixel
from lfstream.errors import BitstreamError, LFValueError
from lfstream.synth import fronto_parallel_plane, synth_clip


def _bilinear(img, y, x):
    h, w = img.shape
    y = min(max(y, 0.0), h - 1.0)
    x = min(max(x, 0.0), w - 1.0)
    y0, x0 = int(np.floor(y)), int(np.floor(x))
    y1, x1 = min(y0 + 1, h - 1), min(x0 + 1, w - 1)
    ay, ax = y - y0, x - x0
    top = img[y0, x0] * (1 - ax) + img[y0, x1] * ax
    bot = img[y1, x0] * (1 - ax) + img[y1, x1] * ax
    return top * (1 - ay) + bot * ay


def test_grey_block_means_equal_opencvs_conversion_and_area_resampling(rng):
    import cv2

    from lfstream.codec.hint.kernels import block_means

    # blocks of one pixel: every 8-bit level divided by 255, as the float conversion does
    levels = np.arange(256, dtype=np.uint8).reshape(1, 16, 16)
    out = np.empty((1, 16, 16), np.float32)
    block_means(levels, 1, out)
    np.testing.assert_array_equal(out, levels.astype(np.float32) * np.float32(1 / 255.0))
    # block means as OpenCV's area resampling of that grey, to the bit at the working scales in use
    lf = rng.integers(0, 256, (3, 3, 37, 53, 3), dtype=np.uint8)
    keys = [(1, 1), (0, 2), (2, 0)]
    for scale in (1, 2, 4, 8):
        hs, ws = 37 // scale, 53 // scale
        ref = np.stack([cv2.resize(cv2.cvtColor(lf[k][: hs * scale, : ws * scale], cv2.COLOR_RGB2GRAY)
                                   .astype(np.float32), (ws, hs), interpolation=cv2.INTER_AREA) for k in keys])
        np.testing.assert_array_equal(H._grids(lf, keys, scale), ref * np.float32(1 / 255.0))
    # a view smaller than one block: the mean of the pixels it has, at the caller's scale
    # (3 x 9 pixels in blocks of 4: one row of two blocks, the ninth column left out)
    small = np.ascontiguousarray(lf[:, :, :3, :9])
    ref = cv2.resize(cv2.cvtColor(small[1, 1, :, :8], cv2.COLOR_RGB2GRAY).astype(np.float32), (2, 1),
                     interpolation=cv2.INTER_AREA) / 255.0
    np.testing.assert_allclose(H._grids(small, [(1, 1)], 4)[0], ref, rtol=0, atol=1e-6)
    # the working scale's own path (two rows, column pairs) and the general one it leaves
    # to where a block is cut short (one row, an odd last column): the same sums and roundings
    grey = rng.integers(0, 256, (2, 5, 9), dtype=np.uint8)
    for rows in (5, 1):
        part = np.ascontiguousarray(grey[:, :rows])
        got = np.empty((2, max(1, rows // 2), 4), np.float32)
        block_means(part, 2, got)
        for n in range(2):
            for i in range(got.shape[1]):
                block = part[n, 2 * i: 2 * i + 2, :8].astype(np.int64).reshape(-1, 4, 2).transpose(1, 0, 2)
                sums, count = block.reshape(4, -1).sum(axis=1), block[0].size
                want = (sums.astype(np.float32) * np.float32(1.0 / count)) * np.float32(1 / 255.0)
                np.testing.assert_array_equal(got[n, i], want)


def test_sweep_cost_matches_a_plain_reference(rng):
    images = rng.random((5, 9, 11), dtype=np.float32)
    # views off both axes, on the centre's row and on its column (the kernel's three spans)
    offsets = np.float32([[-1, -1], [0, 2], [1.5, -0.5], [-2, 0]])
    # the last shift moves the outer views' taps past the whole row (the clamped path)
    shifts = np.float32([-1.3, 0.0, 0.4, 2.2, -6.1])
    cost = np.empty((5, 9, 11), np.float32)
    sweep_cost(images, offsets, shifts, cost)
    for k, s in enumerate(shifts):
        for y in range(9):
            for x in range(11):
                ref = np.mean([abs(_bilinear(images[1 + j], y - s * du, x - s * dv) - images[0, y, x])
                               for j, (du, dv) in enumerate(offsets)])
                assert cost[k, y, x] == pytest.approx(ref, abs=1e-5)


def test_the_on_axis_spans_equal_the_general_span_to_the_bit(rng):
    """A view on the centre's row (vertical weight 0) or column (horizontal weight 0) takes
    a span with one interpolation; its costs must equal the general span's bit for bit,
    or the hint's bytes change."""
    from lfstream.codec.hint.kernels import _sweep_span, _sweep_span_col, _sweep_span_row

    w = 301
    r0, r1, centre, acc = (rng.standard_normal(w).astype(np.float32) for _ in range(4))
    for ox in (-3, 0, 2):
        lo, hi = max(-ox, 0), w - 1 - max(ox, 0)
        for weight in np.float32([0.0, 0.25, 0.37, 0.999]):
            ref, got = acc.copy(), acc.copy()
            _sweep_span(r0, r1, centre, weight, np.float32(0), ox, lo, hi, ref)
            _sweep_span_row(r0, centre, weight, ox, lo, hi, got)
            np.testing.assert_array_equal(got, ref)
            ref, got = acc.copy(), acc.copy()
            _sweep_span(r0, r1, centre, np.float32(0), weight, ox, lo, hi, ref)
            _sweep_span_col(r0, r1, centre, weight, ox, lo, hi, got)
            np.testing.assert_array_equal(got, ref)


def test_winner_subpixel_finds_the_parabola_minimum():
    shifts = np.linspace(-1, 1, 9).astype(np.float32)
    true = np.float32([[-0.33, 0.1, 0.62]])
    cost = ((shifts[:, None, None] - true[None]) ** 2).astype(np.float32)  # exact parabolas
    out = np.empty(true.shape, np.float32)
    winner_subpixel(cost, shifts, out)
    assert np.allclose(out, true, atol=1e-5)



def test_winner_subpixel_matches_a_plain_reference_with_ties(rng):
    # costs on a coarse grid of values, so many pixels have several equal minima: the
    # first (lowest) candidate must win, as a per-pixel scan picks it
    shifts = np.linspace(-2, 2, 11).astype(np.float32)
    cost = (rng.integers(0, 6, (11, 7, 23)) * 0.25).astype(np.float32)
    out = np.empty((7, 23), np.float32)
    winner_subpixel(cost, shifts, out)
    step = shifts[1] - shifts[0]
    for y in range(7):
        for x in range(23):
            c = cost[:, y, x]
            k = int(np.argmin(c))  # numpy's argmin: the first minimum
            off = 0.0
            if 0 < k < 10:
                denom = c[k - 1] - 2 * c[k] + c[k + 1]
                if denom > 1e-9:
                    off = min(max(0.5 * (c[k - 1] - c[k + 1]) / denom, -0.5), 0.5)
            assert abs(out[y, x] - (shifts[k] + off * step)) < 1e-6, (y, x)

def _jbu_reference(small, gsmall, guide, scale, lut, y, x):
    hs, ws = small.shape
    py = min(max((y + 0.5) / scale - 0.5, 0.0), hs - 1.0)
    px = min(max((x + 0.5) / scale - 0.5, 0.0), ws - 1.0)
    acc = wsum = 0.0
    for iy in range(max(int(py) - 1, 0), min(int(py) + 3, hs)):
        for ix in range(max(int(px) - 1, 0), min(int(px) + 3, ws)):
            sw = max(0.0, 1 - abs(py - iy) / 2) * max(0.0, 1 - abs(px - ix) / 2)
            wt = sw * lut[abs(int(guide[y, x]) - int(gsmall[iy, ix]))]
            acc += wt * small[iy, ix]
            wsum += wt
    return acc / wsum


def test_joint_upsample_matches_a_reference_at_any_thread_count(rng):
    """The kernel once read outside its lookup table (uint8 differences wrapped): its
    output then changed from run to run and with the thread count."""
    small = rng.random((12, 17), dtype=np.float32)
    gsmall = rng.integers(0, 256, (12, 17), dtype=np.uint8)
    guide = rng.integers(0, 256, (48, 68), dtype=np.uint8)
    lut = H._RANGE_LUT
    outs = []
    threads = numba.get_num_threads()
    try:
        for n in sorted({1, threads}):
            numba.set_num_threads(n)
            out = np.full((48, 68), np.nan, np.float32)
            joint_upsample(small, gsmall, guide, np.float32(4), lut, out)
            outs.append(out)
    finally:
        numba.set_num_threads(threads)
    assert all(np.array_equal(outs[0], o) for o in outs)
    for y, x in [(0, 0), (7, 30), (47, 67), (20, 3), (33, 51)]:
        assert outs[0][y, x] == pytest.approx(_jbu_reference(small, gsmall, guide, 4.0, lut, y, x), abs=1e-5)


@pytest.mark.parametrize("d", [-6.0, -1.25, 0.0, 0.8, 5.5])
def test_plane_disparity_within_the_search_range_the_scene_needs(d):
    """A fronto-parallel plane at disparities well past the old fixed +-2.5 px/step range
    is found by the range pass; the estimate is within 0.05 px/step."""
    clip = fronto_parallel_plane(7, (128, 192), d, seed=3)
    hm = H.estimate_hint_map(clip.lf[0])
    inner = hm.disparity[4:-4, 4:-4]
    assert hm.search[0] <= d <= hm.search[1]
    assert abs(float(np.median(inner)) - d) < 0.05, (d, float(np.median(inner)))


def test_hint_accuracy_on_a_layered_scene_with_vignetting():
    """Vignetting differs between views; the high-passed cost is not fooled by it (the first
    estimator, on plain luma, measured MSEx100 408 on this kind of scene)."""
    clip = synth_clip(1, 7, (192, 256), seed=1, noise=1.5, vignetting=0.2)
    err = H.disparity_errors(H.estimate_disparity(clip.lf[0]), clip.disparity[0, 3, 3])
    assert err["mse_x100"] < 40, err


def test_periodic_textures_do_not_widen_the_range_or_fool_the_sweep():
    """Stripes and checkers match the outer ring of views at false disparities (their period
    over the ring's baseline); the views next to the centre break the tie. Twelve layered
    scenes (their true range within -0.8..1.5 px/step): measured mean MSEx100 17.5 and search
    ranges within -3.2..4.7 with the inner views, 28.7 and down to -9.3 with the ring alone."""
    assert set(H.sweep_views(7, 7)) >= {(2, 3), (4, 3), (3, 2), (3, 4), (0, 0), (6, 6)}
    errors = []
    for seed in range(12):
        clip = synth_clip(1, 7, (128, 192), seed=seed, noise=2.0, vignetting=0.3, motion=0, camera_pan=0)
        hm = H.estimate_hint_map(clip.lf[0])
        assert -4.0 < hm.search[0] and hm.search[1] < 5.5, (seed, hm.search)
        errors.append(H.disparity_errors(H.estimate_disparity(clip.lf[0]), clip.disparity[0, 3, 3])["mse_x100"])
    assert np.mean(errors) < 22.0, errors


def test_full_payload_round_trip_is_exact_on_the_8_bit_grid(rng):
    small = np.cumsum(rng.normal(0, 0.05, (23, 31)), axis=1).astype(np.float32)
    hm = H.HintMap(small, 4, (float(small.min()), float(small.max())))
    payload = H.encode_hint(hm, H.HintOptions(precision=0.0))
    qh = H.quantise(hm)
    back = H._parse(payload, (92, 124), 0, {})
    assert np.array_equal(back.q, qh.q) and back.scale == 4
    assert np.allclose(back.values(), small, atol=(small.max() - small.min()) / 255 / 2 + 1e-6)


@pytest.mark.parametrize("reach", [1.0, 3.0, 6.0])
def test_precision_bounds_the_displacement_error_at_the_outermost_view(rng, reach):
    """With ``precision`` p the quantised values use every k-th level and the decoded map
    moves no view's sample by more than p / 2 px (rounding to the nearest level)."""
    small = np.cumsum(rng.normal(0, 0.05, (23, 31)), axis=1).astype(np.float32)
    hm = H.HintMap(small, 4, (float(small.min()), float(small.max())), reach=reach)
    for p in (0.05, 0.2, 0.5):
        qh = H.quantise(hm, precision=p)
        k = H.level_step(qh.hi - qh.lo, reach, p)
        assert k >= 1 and np.all((qh.q % k == 0) | (qh.q == 255))
        err = np.abs(qh.values() - small).max() * reach
        assert err <= p / 2 + 1e-5, (p, k, err)
        back = H._parse(H.encode_hint(hm, H.HintOptions(precision=p)), (92, 124), 0, {})
        assert np.array_equal(back.q, qh.q)
    # coarser levels: a smaller payload
    fine = len(H.encode_hint(hm, H.HintOptions(precision=0.0)))
    assert len(H.encode_hint(hm, H.HintOptions(precision=0.5))) < fine


def test_median_and_precision_options_are_validated():
    for bad in (dict(median=2), dict(median=7), dict(precision=-0.1), dict(precision=float("nan")),
                dict(min_spacing=-0.1), dict(min_spacing=float("inf"))):
        with pytest.raises(LFValueError):
            H.HintOptions(**bad).validate()


@pytest.mark.parametrize("views, spacing", [(7, 0.25), (5, 0.25), (3, 0.5)])
def test_the_working_sweeps_candidates_are_at_least_min_spacing_apart(monkeypatch, views, spacing):
    """Candidates step the outermost view's shift by ``step`` working pixels, but never
    closer than ``min_spacing`` px per view step: on 7x7 grids the floor binds (1/6 px by
    ``step`` alone), on 5x5 and 3x3 it does not; ``min_spacing=0`` is ``step`` alone."""
    from lfstream.codec.hint import kernels as _kernels

    seen = []
    real = _kernels.sweep_cost

    def spy(images, offsets, shifts, cost):
        seen.append(np.asarray(shifts, np.float64))
        return real(images, offsets, shifts, cost)

    monkeypatch.setattr(_kernels, "sweep_cost", spy)
    lf = fronto_parallel_plane(views, (48, 64), 0.6, seed=2).lf[0]
    opts = H.HintOptions(max_disparity=2.0)  # no range pass: the one sweep is the working one
    H.estimate_hint_map(lf, opts)
    work = opts.work_scale
    reach = views // 2
    (shifts,) = seen
    np.testing.assert_allclose(np.diff(shifts) * work, spacing, rtol=1e-5)  # shifts are per working px
    seen.clear()
    H.estimate_hint_map(lf, H.HintOptions(max_disparity=2.0, min_spacing=0.0))
    np.testing.assert_allclose(np.diff(seen[0]) * work, opts.step * work / reach, rtol=1e-5)


def test_a_development_builds_version_1_payload_is_refused_with_one_line():
    q = np.arange(6 * 8, dtype=np.uint8).reshape(6, 8) * 5
    v1 = struct.pack("<BffHH", 1, -1.0, 2.0, 6, 8) + zstandard.ZstdCompressor(level=19).compress(q.tobytes())
    with pytest.raises(BitstreamError, match="payload format 1, made by an older lfstream; re-encode"):
        H.decode_hint(v1, (24, 32))


def test_static_video_hints_cost_a_few_bytes_and_decode_like_full_ones():
    clip = synth_clip(5, 5, (64, 96), seed=4, motion=0.0, camera_pan=0.0)
    tracker = H.HintTracker()
    payloads = [tracker.encode(f, k) for k, f in enumerate(clip.lf)]
    kinds = [p[1] for p in payloads]
    assert kinds[0] == H.KIND_FULL and all(k in (H.KIND_DELTA, H.KIND_REPEAT) for k in kinds[1:])
    assert max(len(p) for p in payloads[1:]) < len(payloads[0]) // 2
    dec = H.HintDecoder()
    decoded = [dec.decode(p, (64, 96), frame=k) for k, p in enumerate(payloads)]
    fresh = [H.decode_hint(H.encode_hint(H.estimate_hint_map(f)), (64, 96)) for f in clip.lf]
    for a, b in zip(decoded, fresh):
        # two grids (the key hint's range, the frame's own), each within precision / 2 at
        # the outermost view (reach 2 for 5 x 5 views), plus a level of the 8-bit grid
        assert np.abs(a - b).max() < H.HintOptions().precision / 2 + 0.02


def test_start_encode_sets_the_hint_at_once_and_codes_the_same_payloads():
    """start_encode's future holds encode's bytes, key hints and deltas alike, and the hint
    it sends (``last``) is known before the payload is asked for; on a worker thread (the
    lane, say) the payload is coded before it returns."""
    from lfstream.codec.workers import beside

    clip = synth_clip(3, 5, (64, 96), seed=5, motion=0.5, camera_pan=0.0).lf
    one, other = H.HintTracker(H.HintOptions(key_interval=2)), H.HintTracker(H.HintOptions(key_interval=2))
    for k, frame in enumerate(clip):
        job = one.start_encode(frame, k)
        assert one.last is not None and one.last.q.shape == (16, 24)
        assert job.result(10.0) == other.encode(frame, k)
        assert np.array_equal(one.last.q, other.last.q)
    on_lane = beside(lambda: H.HintTracker().start_encode(clip[0], 0)).result(10.0)
    assert on_lane.done() and on_lane.result() == H.HintTracker().encode(clip[0], 0)


def test_a_lost_reference_is_a_clear_error_and_a_key_hint_recovers():
    clip = synth_clip(4, 5, (64, 96), seed=6, motion=0.0, camera_pan=0.0)
    tracker = H.HintTracker(H.HintOptions(key_interval=3))
    payloads = [tracker.encode(f, k) for k, f in enumerate(clip.lf)]
    assert payloads[3][1] == H.KIND_FULL  # a key hint every 3 frames
    dec = H.HintDecoder()
    dec.decode(payloads[0], (64, 96), frame=0)
    with pytest.raises(H.HintReferenceError, match="frame 1"):
        dec.decode(payloads[2], (64, 96), frame=2)  # frame 1 never arrived
    assert dec.decode(payloads[3], (64, 96), frame=3).shape == (64, 96)


@pytest.mark.parametrize("cut", [0, 1, 10, 22])
def test_truncated_payloads_are_bitstream_errors(cut):
    lf = synth_clip(1, 5, (48, 64), seed=2).lf[0]
    payload = H.encode_hint(H.estimate_hint_map(lf))
    with pytest.raises(BitstreamError, match="frame 7"):
        H.decode_hint(payload[:cut], (48, 64), frame=7)


# -- view axes (a capture whose view grid is not the convention's) ---------------------------

@pytest.fixture(scope="module")
def square_scene():
    return synth_clip(1, 7, (256, 256), seed=0).lf[0]


def test_a_light_field_that_follows_the_convention_keeps_the_identity(square_scene):
    axes = H.estimate_view_axes(square_scene)
    assert H.is_standard(axes)
    payload = H.encode_hint(H.estimate_hint_map(square_scene))
    assert payload[0] == H.HINT_FORMAT and not payload[1] & H.KIND_AXES  # no view axes sent


def test_flipped_view_rows_are_detected_sent_and_warped(square_scene):
    import lfstream
    from lfstream.metrics import mpsnr

    flipped = np.ascontiguousarray(square_scene[::-1])  # rows of views in reverse order
    axes = H.estimate_view_axes(flipped)
    # measured [[-1.027, 0.013], [-0.021, 1]]
    assert np.abs(axes - np.diag([-1.0, 1.0])).max() < 0.06
    hm = H.estimate_hint_map(flipped)
    payload = H.encode_hint(hm)
    assert payload[0] == H.HINT_FORMAT and payload[1] & H.KIND_AXES
    qh = H.HintDecoder().parse(payload, (256, 256), frame=0)
    assert np.array_equal(qh.axes, hm.axes)
    # decoded quality: measured 28.06 dB with the axes, 23.90 without, 28.18 unflipped
    auto = mpsnr(flipped, lfstream.decode(lfstream.encode(flipped))[0])
    standard = mpsnr(flipped, lfstream.decode(lfstream.encode(flipped, hint_options=H.HintOptions(geometry="standard")))[0])
    plain = mpsnr(square_scene, lfstream.decode(lfstream.encode(square_scene))[0])
    assert auto > standard + 2.0 and auto > plain - 0.5


@pytest.mark.parametrize("turn", ["transposed", "quarter"])
def test_a_grid_stored_with_its_view_axes_swapped_is_detected_and_warped(square_scene, turn):
    """A light field stored (V, U) instead of (U, V), or turned a quarter: a step along v
    moves points along y. The fit normalises on that entry (A[0, 1] = 1) instead of refusing
    it as "not a light field" (the rule before, which coded such a grid on the convention:
    measured 23.46 / 22.54 dB against 29.34 with its axes; the (U, V) grid 29.33)."""
    import lfstream
    from lfstream.metrics import mpsnr

    lf = square_scene.transpose(1, 0, 2, 3, 4) if turn == "transposed" else np.rot90(square_scene, 1, axes=(0, 1))
    lf = np.ascontiguousarray(lf)
    axes = H.estimate_view_axes(lf)
    sign = 1.0 if turn == "transposed" else -1.0
    # measured [[0.014, 1], [0.973, 0.024]] and [[-0.014, 1], [-0.973, 0.024]]
    assert np.abs(axes - np.array([[0.0, 1.0], [sign, 0.0]])).max() < 0.06
    auto = mpsnr(lf, lfstream.decode(lfstream.encode(lf))[0])
    standard = mpsnr(lf, lfstream.decode(lfstream.encode(lf, hint_options=H.HintOptions(geometry="standard")))[0])
    plain = mpsnr(square_scene, lfstream.decode(lfstream.encode(square_scene))[0])
    assert auto > standard + 4.0 and auto > plain - 0.2


def test_vignetting_does_not_hide_a_flipped_grid():
    """Outer views darkened unevenly (vignetting 0.3, noise) pulled the detection's flows so
    far that this flipped grid was coded on the convention (measured 33.58 dB against 35.55
    in its own order); the detection's flows now see luma divided by its local mean: 35.55."""
    import lfstream
    from lfstream.metrics import mpsnr

    lf = synth_clip(1, 7, (192, 256), seed=1, noise=2.0, vignetting=0.3, motion=0, camera_pan=0).lf[0]
    flipped = np.ascontiguousarray(lf[::-1])
    axes = H.estimate_view_axes(flipped)
    assert axes[0, 0] < -0.6 and abs(axes[1, 1] - 1.0) < 1e-6  # measured [[-0.822, -0.066], [0.083, 1]]
    auto = mpsnr(flipped, lfstream.decode(lfstream.encode(flipped))[0])
    standard = mpsnr(flipped, lfstream.decode(lfstream.encode(flipped, hint_options=H.HintOptions(geometry="standard")))[0])
    own = mpsnr(lf, lfstream.decode(lfstream.encode(lf))[0])
    assert auto > standard + 1.5 and auto > own - 0.2
    assert H.is_standard(H.estimate_view_axes(lf))  # and the grid in its own order stays the convention


@pytest.mark.parametrize("flip", [False, True])
def test_sweeping_beside_the_axes_detection_gives_the_map_of_detecting_first(square_scene, flip):
    """estimate_hint_map sweeps on the convention while the axes are detected beside it, and
    sweeps again where they differ (the flipped rows): the map, range, axes, kept luma and
    coarser map of detecting the axes first, bit for bit."""
    lf = np.ascontiguousarray(square_scene[::-1]) if flip else square_scene
    axes = H.estimate_view_axes(lf)
    assert H.is_standard(axes) != flip
    auto = H.estimate_hint_map(lf, keep_ring_luma=True, keep_coarse=True)
    first = H.estimate_hint_map(lf, axes=axes, keep_ring_luma=True, keep_coarse=True)
    assert np.array_equal(auto.axes, first.axes) and auto.search == first.search and auto.reach == first.reach
    for a, b in ((auto.disparity, first.disparity), (auto.coarse, first.coarse), (auto.ring_luma, first.ring_luma)):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_a_video_keeps_its_view_axes_in_delta_and_repeat_hints():
    clip = synth_clip(3, 7, (128, 192), seed=3, motion=0.0, camera_pan=0.0)
    frames = np.ascontiguousarray(clip.lf[:, ::-1])
    tracker = H.HintTracker()
    payloads = [tracker.encode(f, k) for k, f in enumerate(frames)]
    dec = H.HintDecoder()
    got = [dec.decode_with_axes(p, (128, 192), frame=k)[1] for k, p in enumerate(payloads)]
    assert payloads[0][1] == H.KIND_FULL | H.KIND_AXES and payloads[0][3] == H.CODER_CONTEXT  # a coded key map
    assert all(p[0] == H.HINT_FORMAT and p[1] & H.KIND_AXES for p in payloads)
    assert payloads[1][1] & ~H.KIND_AXES in (H.KIND_DELTA, H.KIND_REPEAT)
    assert all(np.array_equal(a, got[0]) for a in got) and got[0][0, 0] < 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, 9.0, -1e30])
def test_bad_view_axes_in_a_payload_are_bitstream_errors(bad):
    hm = H.HintMap(np.zeros((4, 4), np.float32), 4, (0.0, 1.0), np.float32([[-1, 0], [0, 1]]))
    payload = bytearray(H.encode_hint(hm))
    struct.pack_into("<f", payload, H._HEADER.size, bad)
    with pytest.raises(BitstreamError, match="frame 3"):
        H.decode_hint(bytes(payload), (16, 16), frame=3)
    with pytest.raises(BitstreamError, match="truncated"):
        H.decode_hint(bytes(payload[:H._HEADER.size + 7]), (16, 16), frame=3)


def test_the_axes_fits_kernels_agree_with_numpy(rng):
    from lfstream.codec.hint.kernels import axes_moments, axes_moved, axes_prune, axes_residuals

    n, m = 1500, 8
    flows = rng.normal(size=(n, m))
    weight = rng.random(n) + 0.1
    # weighted second moments of the first k samples (float64: rounding only, 1e-12 relative)
    moments = np.empty((m, m))
    axes_moments(flows, weight, 1200, moments)
    wf = flows[:1200] * weight[:1200, None]
    np.testing.assert_allclose(moments, wf.T @ wf, rtol=1e-12, atol=1e-12)
    # distance from the line along g, any length of g; a zero g is taken as the unit one
    g = rng.normal(size=m)
    r = np.empty(n)
    axes_residuals(3.0 * g, flows, n, r)
    unit = g / np.linalg.norm(g)
    np.testing.assert_allclose(r, np.linalg.norm(flows - np.outer(flows @ unit, unit), axis=1), rtol=1e-12)
    axes_residuals(np.zeros(m), flows, n, r)
    np.testing.assert_allclose(r, np.linalg.norm(flows, axis=1), rtol=1e-12)
    # pruning keeps the samples within 3x the median distance, in order, and their weights
    far = flows.copy()
    far[::50] *= 40.0  # outliers
    expected = np.linalg.norm(far - np.outer(far @ unit, unit), axis=1)
    keep = expected <= 3.0 * np.median(expected) + 1e-6
    f2, w2 = far.copy(), weight.copy()
    kept = axes_prune(g, f2, w2, n, r, 3.0, 32)
    assert kept == keep.sum() and kept < n
    np.testing.assert_array_equal(f2[:kept], far[keep])
    np.testing.assert_array_equal(w2[:kept], weight[keep])
    # too few would be kept: 0, and nothing moves
    f3, w3 = far.copy(), weight.copy()
    assert axes_prune(g, f3, w3, n, r, 3.0, n + 1) == 0
    np.testing.assert_array_equal(f3, far)
    np.testing.assert_array_equal(w3, weight)
    # the longest flow of each sample, each view's length weighted
    change = rng.random(m // 2)
    out = np.empty(n)
    axes_moved(flows, n, change, out)
    lengths = np.hypot(flows[:, 0::2], flows[:, 1::2]) * change
    np.testing.assert_allclose(out, lengths.max(axis=1), rtol=1e-12)


def test_the_view_axes_option_is_validated():
    with pytest.raises(Exception, match="geometry"):
        H.HintOptions(geometry="sideways").validate()


def test_the_camera_array_sample_is_warped_along_its_own_axes():
    import lfstream
    from lfstream.io import read_lf
    from lfstream.metrics import mpsnr
    from tests.conftest import shared

    lf = read_lf(shared("toys_array"))
    axes = H.estimate_view_axes(lf)
    # its view rows move the scene against the convention, by a longer step, the rig turned
    # by about 3 degrees (optical flow over the full 9x9 grid: -1.065, -0.053, -0.058)
    assert -1.12 < axes[0, 0] < -1.02 and -0.1 < axes[0, 1] < -0.02 and -0.1 < axes[1, 0] < -0.02
    # measured 17.53 dB with the axes, 11.87 with the convention
    assert mpsnr(lf, lfstream.decode(lfstream.encode(lf))[0]) > 16.5


def test_damaged_payloads_with_view_axes_decode_finite_or_fail_clearly():
    hm = H.HintMap(np.linspace(-2, 3, 64, dtype=np.float32).reshape(8, 8), 4, (-2.0, 3.0),
                   np.float32([[-1.07, -0.06], [-0.05, 1]]))
    payload = H.encode_hint(hm)
    assert payload[0] == H.HINT_FORMAT and payload[1] & H.KIND_AXES
    rng = np.random.default_rng(11)
    for _ in range(300):
        bad = bytearray(payload)
        for pos in rng.integers(0, len(bad), size=rng.integers(1, 4)):
            bad[pos] = int(rng.integers(0, 256))
        try:
            d, axes = H.HintDecoder().decode_with_axes(bytes(bad), (32, 32), frame=5)
        except BitstreamError as exc:
            assert "frame 5" in str(exc)
            continue
        assert np.isfinite(d).all() and (axes is None or (np.isfinite(axes).all() and np.abs(axes).max() <= 8))


def test_a_payload_declaring_a_huge_size_is_refused_before_allocating():
    # python-zstandard allocates the content size a frame declares, whatever max_output_size
    # says: a hint for an 8x8 map whose body declares 1 MiB must fail without decoding it
    hm = H.HintMap(np.zeros((8, 8), np.float32), 4, (0.0, 1.0))
    key = H.encode_hint(hm)
    dec = H.HintDecoder()
    dec.decode(key, (32, 32), frame=0)
    head = bytearray(key[:H._HEADER.size])
    head[1], head[3] = H.KIND_DELTA, H.CODER_ZSTD  # a delta to frame 0: a zstd body
    struct.pack_into("<I", head, H._HEADER.size - 4, 0)
    body = zstandard.ZstdCompressor(level=9).compress(bytes(1 << 20))
    with pytest.raises(BitstreamError, match="declares 1048576 bytes"):
        dec.decode(bytes(head) + body, (32, 32), frame=1)


def test_the_coarse_map_is_the_sweep_at_twice_the_scale():
    """HintMap.coarse, and the tracker's coarser key hint, are exactly what a sweep and a
    tracker with twice the hint scale give for the frame; the frames after it then follow at
    that scale, byte for byte with that tracker."""
    clip = synth_clip(2, 5, (136, 200), seed=12, noise=1.0, motion=0.5, camera_pan=0).lf
    fine = H.estimate_hint_map(clip[0], H.HintOptions(), keep_coarse=True)
    native = H.estimate_hint_map(clip[0], H.HintOptions(hint_scale=8))
    assert fine.scale == 4 and native.scale == 8 and fine.coarse.shape == (17, 25)
    assert np.array_equal(fine.coarse, native.disparity)
    tracker, reference = H.HintTracker(), H.HintTracker(H.HintOptions(hint_scale=8))
    tracker.encode(clip[0], 0)
    assert tracker.coarser_key_hint().scale == 8
    twin = H.HintTracker()
    twin.encode(clip[0], 0)
    assert twin.coarsen(b"coded") == b"coded"  # a payload the caller coded already is sent as it is
    assert tracker.coarsen() == reference.encode(clip[0], 0) == H.key_payload(twin.last)
    assert tracker.options.hint_scale == 8 and tracker.last.scale == 8
    assert tracker.encode(clip[1], 1) == reference.encode(clip[1], 1)
    assert tracker.coarser_key_hint() is None  # frame 1 is a delta, not a key hint
    with pytest.raises(LFValueError):
        tracker.coarsen()


@pytest.mark.parametrize("k", [1, 2, 3, 5, 6, 9, 64, 255])
def test_context_coded_maps_round_trip_exactly_at_every_level_step(rng, k):
    """Any map on a grid of step k (multiples of k, and 255), smooth or random, decodes to
    the same bytes; the level step the encoder finds is k (or a multiple it describes)."""
    top = 255 // k
    smooth = np.clip(np.cumsum(rng.integers(-2, 3, (37, 53)), axis=1) + top // 2, 0, top) * k
    noise = rng.integers(0, top + 1, (19, 23)) * k
    for i, q in enumerate((smooth, noise, np.full((5, 7), 255), np.zeros((1, 1)))):
        q = q.astype(np.int64)
        if 255 % k:
            q = np.where(rng.random(q.shape) < 0.05, 255, q)  # the quantiser's top value
        qh = H.QuantisedHint(q.astype(np.uint8), -1.0, 2.0, 4, None)
        payload = H.key_payload(qh)
        assert payload[3] == H.CODER_CONTEXT and payload[0] == H.HINT_FORMAT
        back = H._parse(payload, (4 * q.shape[0], 4 * q.shape[1]), 0, {})
        assert np.array_equal(back.q, qh.q) and (back.lo, back.hi, back.scale) == (-1.0, 2.0, 4)
        if i == 0:  # consecutive levels: the step sent is k itself (fewer levels to code)
            assert payload[H._HEADER.size] == k


def test_context_coder_beats_zstd_and_older_formats_are_refused(rng):
    """On a piecewise-smooth disparity map (what the sweep produces) the context coder needs
    fewer bytes than zstd of the map's planar prediction residual (measured on the shared
    samples' hints: 12-37 % fewer); a payload of a development build's formats (1 to 5) is
    refused with a line that names it."""
    y, x = np.mgrid[0:90, 0:130]
    d = 0.01 * x - 0.005 * y + np.where((x - 60) ** 2 + (y - 40) ** 2 < 600, 0.8, 0.0)
    d = (d + rng.normal(0, 0.01, d.shape)).astype(np.float32)
    hm = H.HintMap(d, 4, (float(d.min()), float(d.max())), reach=3.0)
    qh = H.quantise(hm, precision=0.05)
    planar = np.diff(np.diff(qh.q.astype(np.int16), axis=1, prepend=0), axis=0, prepend=0).astype(np.uint8)
    zstd = zstandard.ZstdCompressor(level=9).compress(planar.tobytes())
    coded = H.key_payload(qh)
    assert len(coded) < 0.85 * (H._HEADER.size + len(zstd)), (len(coded), len(zstd))
    assert np.array_equal(H._parse(coded, (360, 520), 0, {}).q, qh.q)
    for old in range(1, H.HINT_FORMAT):
        with pytest.raises(BitstreamError, match="frame 4: depth hint: payload format .* older lfstream"):
            H._parse(bytes([old]) + coded[1:], (360, 520), 4, {})


def test_corrupt_or_truncated_context_coded_maps_are_bitstream_errors(rng):
    """Every truncation and bit flip of a coded map is refused with a BitstreamError naming
    the frame, or decodes to some map of the right shape on the grid: never another exception."""
    q = (np.clip(np.cumsum(rng.integers(-2, 3, (31, 41)), axis=1) + 20, 0, 42) * 6).astype(np.uint8)
    payload = H.key_payload(H.QuantisedHint(q, 0.0, 1.0, 4, None))
    head = H._HEADER.size
    refused = 0
    for cut in range(head, len(payload)):  # every truncation of the body
        with pytest.raises(BitstreamError, match="frame 7: depth hint"):
            H._parse(payload[:cut], (124, 164), 7, {})
        refused += 1
    for _ in range(300):
        bad = bytearray(payload)
        i = int(rng.integers(head, len(bad)))
        bad[i] ^= 1 << int(rng.integers(0, 8))
        try:
            back = H._parse(bytes(bad), (124, 164), 7, {})
        except BitstreamError as exc:
            assert "frame 7" in str(exc)
            continue
        assert back.q.shape == q.shape
    assert refused == len(payload) - head
    # a coder the decoder does not know, or the context coder on a delta, is refused
    for coder, kind in ((2, H.KIND_FULL), (H.CODER_ZSTD, H.KIND_FULL), (H.CODER_CONTEXT, H.KIND_DELTA)):
        bad = bytearray(payload)
        bad[1], bad[3] = kind, coder
        with pytest.raises(BitstreamError, match="unknown coder"):
            H._parse(bytes(bad), (124, 164), 7, {})


def test_a_map_past_the_swept_range_still_gets_a_grid_that_covers_it():
    """A tiny noisy frame whose whole map lies past the end of the range swept (the last
    candidate and the sub-pixel step reach beyond it: found by the stability test's random
    search, 3x3x16x16 noise at quality 1) is sent on a grid that covers the map, and the
    stream decodes; the inverted range the key hint had before was refused by the decoder."""
    import lfstream

    lf = np.random.default_rng(984).integers(0, 256, (3, 3, 16, 16, 3), dtype=np.uint8)
    hm = H.estimate_hint_map(lf)
    assert float(hm.disparity.max()) > hm.search[1]  # the case: the map is past the range's end
    tracker = H.HintTracker()
    tracker.encode(lf, 0)
    qh = tracker.last
    assert qh.lo < qh.hi and qh.lo <= float(hm.disparity.min()) and float(hm.disparity.max()) <= qh.hi
    k = H.level_step(qh.hi - qh.lo, hm.reach, H.HintOptions().precision)  # levels between sent values
    np.testing.assert_allclose(qh.values(), hm.disparity, atol=(k / 2 + 0.01) * (qh.hi - qh.lo) / 255)
    rec = lfstream.decode(lfstream.encode(lf, quality=1, depth_hint=True))
    assert rec.shape == (1, *lf.shape) and rec.dtype == np.uint8



def test_kept_working_arrays_are_per_thread_bounded_and_leave_no_trace_between_frames():
    """The sweep's kept buffers (H._kept_array): reused by one thread, never shared with
    another, none above the bound; and a frame's hint is the same whatever the thread swept
    before it (a larger frame, another scene)."""
    import threading

    a = H._kept_array("test", (3, 4, 5))
    b = H._kept_array("test", (2, 5, 5))
    assert a.dtype == np.float32 and a.shape == (3, 4, 5) and b.shape == (2, 5, 5)
    assert np.shares_memory(a, b)  # the same buffer, reused
    other = []
    worker = threading.Thread(target=lambda: other.append(H._kept_array("test", (3, 4, 5))))
    worker.start()
    worker.join()
    assert not np.shares_memory(a, other[0])
    big = (H.KEPT_ARRAY_MAX_BYTES // 4 + 1,)
    assert not np.shares_memory(H._kept_array("test", big), H._kept_array("test", big))

    small = synth_clip(1, 5, (48, 64), seed=21, motion=0, camera_pan=0).lf[0]
    large = synth_clip(1, 7, (96, 128), seed=22, motion=0, camera_pan=0).lf[0]
    first = H.estimate_hint_map(small)
    H.estimate_hint_map(large)  # fills the kept buffers with another scene, larger
    again = H.estimate_hint_map(small)
    np.testing.assert_array_equal(again.disparity, first.disparity)
    assert again.search == first.search
