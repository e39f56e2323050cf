"""Gain maps in a video (lfstream.codec.gains): key maps, deltas with a dead band, lost
references."""

import numpy as np
import pytest

import lfstream
from lfstream.codec.bitstream import split_stream
from lfstream.codec.decoder import Decoder
from lfstream.codec.encoder import Encoder
from lfstream.codec.gains import (
    KIND_DELTA,
    KIND_FULL,
    GainDecoder,
    GainReferenceError,
    GainTracker,
    encode_gains,
    measure_gains,
)
from lfstream.errors import BitstreamError, LFValueError
from lfstream.metrics import mpsnr
from lfstream.synth import synth_clip

VIEWS = (5, 5)


def mean_psnr(ref, test):
    return float(np.minimum(mpsnr(ref, test), 100.0))  # the centre view of a warp is exact


@pytest.fixture(scope="module")
def shaded_gains():
    """Gain maps of a vignetted clip with motion: shading plus content that moves."""
    clip = synth_clip(6, 5, (64, 96), seed=8, vignetting=0.6, motion=1.0, camera_pan=0.3).lf
    return [measure_gains(f) for f in clip]


def test_key_maps_are_the_single_frame_payload_and_deltas_are_smaller(shaded_gains):
    tracker = GainTracker(key_interval=4)
    payloads = [tracker.encode(g, k) for k, g in enumerate(shaded_gains)]
    assert payloads[0] == encode_gains(shaded_gains[0])  # the first frame: the single-frame payload
    assert payloads[4] == encode_gains(shaded_gains[4])  # a key map every 4 frames
    assert [p[0] for p in payloads] == [KIND_FULL, KIND_DELTA, KIND_DELTA, KIND_DELTA, KIND_FULL,
                                        KIND_DELTA]
    assert max(len(p) for k, p in enumerate(payloads) if k % 4) < 0.6 * min(len(payloads[0]), len(payloads[4]))


def test_decoded_deltas_stay_within_the_dead_band(shaded_gains):
    tracker, dec = GainTracker(key_interval=30, deadband=1), GainDecoder()
    for k, g in enumerate(shaded_gains):
        back = dec.decode(tracker.encode(g, k), VIEWS, frame=k)
        # a step is 1/64 octave: the sent value is within the dead band plus rounding
        err = np.abs(np.log2(back) - np.log2(np.clip(g, 0.25, 3.9))).max()
        assert err <= (1 + 0.5) / 64 + 1e-6, (k, err)
    # a dead band of 0 sends every change: the decoded maps equal the single-frame coding
    tracker, dec = GainTracker(deadband=0), GainDecoder()
    for k, g in enumerate(shaded_gains):
        np.testing.assert_array_equal(dec.decode(tracker.encode(g, k), VIEWS, frame=k),
                                      GainDecoder().decode(encode_gains(g), VIEWS))


def test_gaps_and_vanishing_shading_send_key_maps(shaded_gains):
    tracker = GainTracker()
    assert tracker.encode(shaded_gains[0], 0)[0] == KIND_FULL
    assert tracker.encode(shaded_gains[1], 2)[0] == KIND_FULL  # frame 1 was never encoded
    assert tracker.encode(None, 3) == b""  # no shading: nothing sent
    assert tracker.encode(shaded_gains[2], 4)[0] == KIND_FULL
    with pytest.raises(LFValueError, match="key_interval"):
        GainTracker(key_interval=0)


def test_a_lost_reference_is_a_clear_error_and_redecoding_a_frame_works(shaded_gains):
    tracker = GainTracker(key_interval=3)
    payloads = [tracker.encode(g, k) for k, g in enumerate(shaded_gains[:4])]
    dec = GainDecoder()
    first = dec.decode(payloads[0], VIEWS, frame=0)
    with pytest.raises(GainReferenceError, match="frame 1") as info:
        dec.decode(payloads[2], VIEWS, frame=2)  # frame 1 never arrived
    assert info.value.frame == 2 and isinstance(info.value, BitstreamError)
    assert dec.decode(payloads[3], VIEWS, frame=3).shape == first.shape  # the key map recovers
    # the stream's static-skip audit decodes a packet twice: the same maps both times
    dec = GainDecoder()
    dec.decode(payloads[0], VIEWS, frame=0)
    once = dec.decode(payloads[1], VIEWS, frame=1)
    np.testing.assert_array_equal(dec.decode(payloads[1], VIEWS, frame=1), once)


@pytest.mark.parametrize("cut", [0, 5, 8, 11])
def test_truncated_delta_payloads_are_bitstream_errors(shaded_gains, cut):
    tracker = GainTracker()
    tracker.encode(shaded_gains[0], 0)
    delta = tracker.encode(shaded_gains[1], 1)
    with pytest.raises(BitstreamError, match="frame 1"):
        GainDecoder().decode(delta[:cut], VIEWS, frame=1)


def test_a_video_sends_deltas_and_a_lost_one_falls_back():
    clip = synth_clip(4, 5, (64, 96), seed=9, vignetting=0.6, motion=1.0, camera_pan=0.3).lf
    header, packets = split_stream(lfstream.encode(clip, quality=80, preset="fast"))
    assert [p.gain[0] for p in packets] == [KIND_FULL] + [KIND_DELTA] * 3
    dec = Decoder(header)
    full = [dec.decode_packet(p).lf for p in packets]
    assert dec.gain_fallbacks == 0
    # against full maps every frame (a dead band of 0): the dead band costs little quality
    exact = Encoder(quality=80)
    exact._gains = GainTracker(deadband=0)
    dec0 = Decoder(header)
    for k, f in enumerate(clip):
        ref = dec0.decode_packet(exact.encode_frame(f, k, k)).lf
        assert abs(mean_psnr(f, full[k]) - mean_psnr(f, ref)) < 0.1, k
    dec = Decoder(header)
    dec.decode_packet(packets[0])
    lossy = dec.decode_packet(packets[2])  # frame 1 lost: frame 0's maps stand in
    assert dec.gain_fallbacks == 1
    assert abs(mean_psnr(clip[2], lossy.lf) - mean_psnr(clip[2], full[2])) < 0.5


def test_mutated_payloads_decode_or_raise_bitstream_errors(shaded_gains):
    """Payload bytes past the packet CRC's protection (a writer's bug, a hostile file with a
    recomputed CRC): every mutation decodes to finite positive gains or raises a
    BitstreamError, never another exception."""
    tracker = GainTracker()
    payloads = [tracker.encode(g, k) for k, g in enumerate(shaded_gains[:2])]
    rng = np.random.default_rng(7)
    outcomes = {"decoded": 0, "rejected": 0}
    for _ in range(300):
        data = bytearray(payloads[int(rng.integers(2))])
        if rng.random() < 0.5:
            for _ in range(int(rng.integers(1, 4))):
                data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        else:
            data = data[: int(rng.integers(len(data)))]
        dec = GainDecoder()
        dec.decode(payloads[0], VIEWS, frame=0)
        try:
            g = dec.decode(bytes(data), VIEWS, frame=1)
        except BitstreamError:
            outcomes["rejected"] += 1
            continue
        assert np.isfinite(g).all() and (g > 0).all()
        outcomes["decoded"] += 1
    assert outcomes["rejected"] > 100 and outcomes["decoded"] + outcomes["rejected"] == 300


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_parallax_compensated_cells_measure_shading_not_content(seed):
    # a scene with no shading and large disparities (+-4 px per view step, 5x5 views): every
    # true gain is 1, so what a cell measures beyond that is content moved by parallax
    clip = synth_clip(1, 5, (120, 160), seed=seed, layers=3, motion=0, camera_pan=0, disparity_range=(-4.0, 4.0),
                      vignetting=0.0, noise=0.0)
    lf, d = clip.lf[0], clip.disparity[0, 2, 2].astype(np.float32)
    plain = np.abs(np.log2(measure_gains(lf, 4)))
    compensated = np.abs(np.log2(measure_gains(lf, 4, disparity=d)))
    # measured: p90 0.100 -> 0.034, 0.060 -> 0.038, 0.110 -> 0.048 (log2 units)
    assert np.percentile(compensated, 90) < 0.06
    assert np.percentile(compensated, 90) < np.percentile(plain, 90) / 1.4
    # the centre view's cells are its own: gain 1 exactly, with or without the disparity
    np.testing.assert_array_equal(compensated[2, 2], 0.0)
    # a zero disparity samples what the plain measurement samples
    np.testing.assert_array_equal(measure_gains(lf, 4, disparity=np.zeros((30, 40), np.float32)), measure_gains(lf, 4))


def reference_gains(lf, grid, channels, disparity, axes):
    """measure_gains as plain numpy and one OpenCV area resize per view (what the fused
    gather replaced): every view read at the rounded, clamped positions ``y - d * off``."""
    import cv2

    from lfstream.lightfield import view_offsets

    u, v, h, w, c = lf.shape
    step = max(1, min(h, w) // (8 * grid))
    ys, xs = np.arange(0, h, step), np.arange(0, w, step)
    gh, gw = max(1, min(grid, len(ys))), max(1, min(int(round(grid * w / h)), len(xs)))
    d = np.zeros((1, 1), np.float32) if disparity is None else np.asarray(disparity, np.float32)
    d_s = d[np.minimum((ys * d.shape[0]) // h, d.shape[0] - 1)[:, None], np.minimum((xs * d.shape[1]) // w,
                                                                                     d.shape[1] - 1)[None, :]]
    off = view_offsets((u, v), axes)
    scale = np.float32(1 / 255.0) if lf.dtype == np.uint8 else np.float32(1.0)
    cells = np.empty((u, v, gh, gw, c), np.float32)
    for a in range(u):
        for b in range(v):
            sy = np.clip(np.rint(ys.astype(np.float32)[:, None] - d_s * off[a, b, 0]), 0, h - 1).astype(np.intp)
            sx = np.clip(np.rint(xs.astype(np.float32)[None, :] - d_s * off[a, b, 1]), 0, w - 1).astype(np.intp)
            view = lf[a, b][sy, sx].astype(np.float32) * scale
            cells[a, b] = cv2.resize(view, (gw, gh), interpolation=cv2.INTER_AREA).reshape(gh, gw, c)
    if channels == 1:
        cells = cells.mean(-1, keepdims=True)
    return ((cells + 0.02) / (cells[u // 2, v // 2] + 0.02)).astype(np.float32)


@pytest.mark.parametrize("views,size,grid,channels,axes,dtype", [
    (7, (75, 101), 4, 3, None, np.uint8),  # a ragged size: cells of fractional width
    (5, (96, 128), 3, 1, np.float32([[-1.05, 0.03], [0.02, 1.0]]), np.uint8),  # axes off the convention
    (13, (40, 60), 6, 3, None, np.uint8),  # many views, small cells
    (3, (64, 96), 4, 3, None, np.float32),
    (3, (64, 96), 4, 1, None, np.float64),  # read as it is: no float32 copy of the light field
])
def test_the_fused_gain_samples_equal_a_per_view_numpy_reference(views, size, grid, channels, axes, dtype):
    """The parallel gather and one stacked area resize give the reference's gains to the bit,
    with and without the disparity (samples out of the view clamped to its border)."""
    clip = synth_clip(1, views, size, seed=4, vignetting=0.4, motion=0, camera_pan=0, disparity_range=(-3.0, 3.0))
    lf = clip.lf[0] if dtype == np.uint8 else clip.lf[0].astype(dtype) / dtype(255)
    d = np.ascontiguousarray(clip.disparity[0, views // 2, views // 2, ::4, ::4], np.float32)  # as a hint is sent
    for disparity in (None, d, 4 * d):  # 4 * d: most samples of the outer views clamped
        want = reference_gains(lf, grid, channels, disparity, axes)
        got = measure_gains(lf, grid, channels, disparity=disparity, axes=axes)
        assert got.dtype == np.float32 and np.array_equal(got, want)


def test_coded_key_maps_are_exact_and_smaller_than_zstd_and_older_kinds_are_refused(shaded_gains):
    """A key map (context coded) decodes to exactly the quantised gains and is smaller than
    zstd of the same values; a payload of a development build's kinds (1 to 3) is refused
    with a line that names it."""
    import zstandard

    from lfstream.codec.gains import _HEADER, OLDER_KINDS, dequantise_gains, quantise_gains

    for g in shaded_gains[:3]:
        q = quantise_gains(g)
        u, v, gh, gw, ch = q.shape
        zstd = zstandard.ZstdCompressor(level=19).compress(q.tobytes())
        new = encode_gains(g)
        assert new[0] == KIND_FULL and len(new) < _HEADER.size + len(zstd), (len(new), len(zstd))
        np.testing.assert_array_equal(GainDecoder().decode(new, VIEWS), dequantise_gains(q))
        for kind in OLDER_KINDS:
            with pytest.raises(BitstreamError, match="older lfstream; re-encode"):
                GainDecoder().decode(_HEADER.pack(kind, gh, gw, ch, u, v) + zstd, VIEWS)


def test_damaged_coded_key_maps_fail_clearly(shaded_gains):
    payload = encode_gains(shaded_gains[0])
    rng = np.random.default_rng(5)
    for cut in range(6, len(payload)):  # every truncation of the body
        with pytest.raises(BitstreamError, match="frame 3: gain maps"):
            GainDecoder().decode(payload[:cut], VIEWS, frame=3)
    for _ in range(200):
        bad = bytearray(payload)
        bad[int(rng.integers(6, len(bad)))] ^= 1 << int(rng.integers(0, 8))
        try:
            back = GainDecoder().decode(bytes(bad), VIEWS, frame=3)
        except BitstreamError as exc:
            assert "frame 3" in str(exc)
            continue
        assert back.shape == shaded_gains[0].shape and np.isfinite(back).all()


def reference_apply_gains(lf: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """apply_gains's definition, view by view in numpy: OpenCV's INTER_LINEAR taps
    (``resize_taps``), its horizontal then vertical float32 passes, and ``cv2.multiply``'s
    float32 product rounded half to even and saturated."""
    from lfstream.codec.gains import resize_taps

    u, v, h, w, c = lf.shape
    rows, row_w = resize_taps(h, gains.shape[2])
    cols, col_w = resize_taps(w, gains.shape[3])
    out = np.empty(lf.shape, np.uint8)
    for a in range(u):
        for b in range(v):
            g = gains[a, b]
            across = g[:, cols[:, 0]] * col_w[:, 0, None] + g[:, cols[:, 1]] * col_w[:, 1, None]  # (gh, W, Cg)
            full = across[rows[:, 0]] * row_w[:, 0, None, None] + across[rows[:, 1]] * row_w[:, 1, None, None]
            full = np.broadcast_to(full, (h, w, c))
            out[a, b] = np.clip(np.rint(lf[a, b].astype(np.float32) * full), 0, 255).astype(np.uint8)
    return out


@pytest.mark.parametrize("views,size,grid,channels", [
    ((7, 7), (75, 101), (4, 4), 3),  # ragged: fractional cells
    ((5, 3), (64, 96), (3, 5), 1),  # a grey map for three channels
    ((3, 3), (40, 60), (1, 1), 3),  # one cell: a constant gain
    ((1, 5), (33, 17), (4, 6), 3),  # more map columns than image... almost: steep taps
])
def test_apply_gains_equals_its_reference_and_opencv_within_a_level(views, size, grid, channels):
    """The parallel kernel gives the numpy reference's bytes to the bit, for one view
    broadcast to all (the flat decode) and for distinct views, with gains that round to ties
    (multiples of 1/8); views whose map is 1 are copied; OpenCV's own resize and multiply
    (which may use IPP's CPU-specific code for the resize) agree within one level."""
    import cv2

    from lfstream.codec.gains import apply_gains, upsample_gain

    rng = np.random.default_rng(sum(size) + channels)
    (u, v), (h, w) = views, size
    lf = rng.integers(0, 256, (u, v, h, w, 3), dtype=np.uint8)
    for ties in (False, True):
        gains = (1 + 0.8 * (rng.random((u, v, *grid, channels)) - 0.5)).astype(np.float32)
        if ties:
            gains = (np.round(gains * 8) / 8).astype(np.float32)
        gains[u // 2, v // 2] = 1.0
        for src in (np.broadcast_to(lf[0, 0], lf.shape), lf):
            want = reference_apply_gains(np.ascontiguousarray(src), gains)
            got = apply_gains(src, gains)
            assert got.dtype == np.uint8 and np.array_equal(got, want)
            assert np.array_equal(got[u // 2, v // 2], src[u // 2, v // 2])
            opencv = np.stack([np.stack([cv2.multiply(src[a, b], np.broadcast_to(upsample_gain(gains[a, b], (h, w)),
                                                                                   (h, w, 3)).copy(), dtype=cv2.CV_8U)
                                         for b in range(v)]) for a in range(u)])
            assert np.abs(opencv.astype(np.int16) - got).max() <= 1
    want = reference_apply_gains(lf, gains)
    for out in (np.zeros_like(lf), np.zeros((u, v, h, w, 4), np.uint8)[..., :3]):  # the latter strided
        assert apply_gains(lf, gains, out=out) is out and np.array_equal(out, want)


@pytest.mark.parametrize("shape", [(3, 3, 2, 2), (3, 2, 2, 2, 3), (3, 3, 2, 2, 2), (3, 3, 0, 2, 3)])
def test_apply_gains_refuses_maps_that_do_not_match_the_views(shape):
    from lfstream.codec.gains import apply_gains
    from lfstream.codec.warp.cpu import warp_views
    from lfstream.errors import LFShapeError

    lf = np.zeros((3, 3, 8, 10, 3), np.uint8)
    with pytest.raises(LFShapeError, match="gains"):
        apply_gains(lf, np.ones(shape, np.float32))
    with pytest.raises(LFShapeError, match="gains"):  # the warp's check is the same one
        warp_views(lf[1, 1], 0.5, (3, 3), gains=np.ones(shape, np.float32))
