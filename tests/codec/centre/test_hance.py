"""The JPEG-Hance strength map (lfstream.codec.centre.hance, its JPEG segment in lfstream.codec.centre.jpeg):
the segment's coding and damage, the strengths and the blend, the encoder's measurement and
the decoder's use of it."""

import io

import numpy as np
import pytest

import lfstream
from lfstream.codec.bitstream import CODEC_JPEG, StreamWriter, split_stream
from lfstream.codec.centre.hance import measure_hance_map, tile_edges
from lfstream.codec.centre.jpeg import (
    HANCE_LEVELS,
    PostFilterChoice,
    blend_restored,
    decode_jpeg,
    encode_jpeg,
    hance_map,
    hance_strength,
    named_post_filter,
    with_hance_map,
    with_post_filter,
)
from lfstream.codec.encoder import Encoder
from lfstream.errors import BitstreamError, LFValueError
from lfstream.metrics import mpsnr
from lfstream.synth import synth_clip


@pytest.fixture(scope="module")
def jpeg() -> bytes:
    img = np.random.default_rng(0).integers(0, 256, (40, 50, 3), dtype=np.uint8)
    return with_post_filter(encode_jpeg(img, 50), PostFilterChoice(2))


@pytest.mark.parametrize("shape", [(1, 1), (2, 3), (5, 7), (16, 16), (64, 64)])
def test_a_map_round_trips_beside_the_post_filter_and_leaves_the_pixels_alone(jpeg, shape):
    levels = np.random.default_rng(sum(shape)).integers(0, HANCE_LEVELS + 1, shape).astype(np.uint8)
    data = with_hance_map(jpeg, levels)
    assert np.array_equal(hance_map(data), levels) and named_post_filter(data) == PostFilterChoice(2)
    assert len(data) - len(jpeg) == 10 + (levels.size + 2) // 3  # three levels a byte
    assert np.array_equal(decode_jpeg(data, (40, 50)), decode_jpeg(jpeg, (40, 50)))
    assert with_hance_map(data, None) == jpeg and hance_map(jpeg) is None
    # naming another post-filter keeps the map; a new map replaces the old one
    renamed = with_post_filter(data, PostFilterChoice(1))
    assert named_post_filter(renamed) == PostFilterChoice(1) and np.array_equal(hance_map(renamed), levels)
    assert np.array_equal(hance_map(with_hance_map(data, levels[:1, :1])), levels[:1, :1])
    # without a post-filter segment (the default filter) the map sits right after SOI
    plain = with_post_filter(data, PostFilterChoice())
    assert named_post_filter(plain) == PostFilterChoice() and np.array_equal(hance_map(plain), levels)


def test_damaged_maps_are_bitstream_errors_and_bad_levels_are_refused(jpeg):
    data = bytearray(with_hance_map(jpeg, np.full((4, 4), 2, np.uint8)))
    at = data.index(b"LFHS") - 4
    for offset, value in ((8, 0), (9, 65), (3, 0x30), (10, 200)):  # rows 0, cols 65, a wrong length, a bad byte
        bad = bytearray(data)
        bad[at + offset] = value
        with pytest.raises(BitstreamError, match="JPEG-Hance map"):
            hance_map(bytes(bad), frame=3)
    with pytest.raises(BitstreamError, match="frame 3"):
        hance_map(bytes(data[: at + 9]), frame=3)
    for levels in (np.full((2, 2), 5), np.full((2, 2), -1), np.zeros((65, 1)), np.zeros((2, 2, 2)), np.zeros((0, 3))):
        with pytest.raises(LFValueError, match="JPEG-Hance map"):
            with_hance_map(jpeg, levels)


def test_strengths_are_the_tiles_bilinearly_and_the_blend_is_exact_at_the_ends():
    levels = np.array([[0, 4], [2, 3]], np.uint8)
    s = hance_strength(levels, (40, 60))
    assert s.dtype == np.float32 and s.shape == (40, 60) and 0 <= s.min() and s.max() <= 1
    # the tiles' values at their centres' quarter of the view (clamped bilinear), smooth between
    assert s[0, 0] == 0 and s[0, -1] == 1 and s[-1, 0] == 0.5 and s[-1, -1] == 0.75
    assert np.abs(np.diff(s, axis=1)).max() < 0.05 and np.abs(np.diff(s, axis=0)).max() < 0.05
    assert np.array_equal(hance_strength(np.full((3, 3), HANCE_LEVELS), (7, 9)), np.ones((7, 9), np.float32))
    rng = np.random.default_rng(2)
    a, b = rng.integers(0, 256, (2, 7, 9, 3), dtype=np.uint8)
    assert np.array_equal(blend_restored(a, b, 1.0), b) and np.array_equal(blend_restored(a, b, 0.0), a)
    half = blend_restored(a, b, np.full((7, 9), 0.5, np.float32))
    assert np.abs(half.astype(np.int16) * 2 - a.astype(np.int16) - b).max() <= 1


def test_the_measurement_keeps_the_level_whose_warp_is_closest_per_tile():
    """On views where the 'restored' centre is the truth in the left half and biased in the
    right, the map is the full strength on the left, none on the right."""
    truth = synth_clip(1, 3, (48, 64), seed=3, motion=0, camera_pan=0, noise=0.0).lf[0, 1, 1]
    views = np.ascontiguousarray(np.broadcast_to(truth, (3, 3, 48, 64, 3)))  # a flat scene: the warp is a copy
    rng = np.random.default_rng(0)
    blurred = np.clip(truth.astype(np.int16) + rng.integers(-20, 21, truth.shape), 0, 255).astype(np.uint8)
    restored = truth.copy()
    restored[:, 32:] = np.clip(truth[:, 32:].astype(np.int16) + np.where(truth[:, 32:] < 128, 60, -60), 0, 255)
    d = np.zeros((48, 64), np.float32)
    levels = measure_hance_map(views, blurred, restored, d, tiles=4)
    assert levels.shape == (4, 4) and levels.dtype == np.uint8
    assert (levels[:, :2] == HANCE_LEVELS).all() and (levels[:, 2:] == 0).all()
    assert list(tile_edges(10, 3)) == [0, 3, 7, 10]
    with pytest.raises(LFValueError, match="tiles"):
        measure_hance_map(views, blurred, restored, d, tiles=0)
    # level 0's warp given (the encoder's reference decode): the same map; a wrong one counts
    from lfstream.codec.warp.cpu import warp_views

    plain = warp_views(blurred, d, (3, 3))
    assert np.array_equal(measure_hance_map(views, blurred, restored, d, tiles=4, warped=plain), levels)
    assert not np.array_equal(measure_hance_map(views, blurred, restored, d, tiles=4, warped=views), levels)
    with pytest.raises(LFValueError, match="warped"):
        measure_hance_map(views, blurred, restored, d, tiles=4, warped=plain[:2])


@pytest.fixture(scope="module")
def clip_lf():
    return synth_clip(3, 5, (64, 96), seed=11, motion=0.5, camera_pan=0.2).lf


def _rewritten(data: bytes, levels) -> bytes:
    """The stream with each packet's JPEG carrying ``levels`` (``None``: no map)."""
    from dataclasses import replace

    header, packets = split_stream(data)
    buf = io.BytesIO()
    writer = StreamWriter(buf, header)
    for p in packets:
        writer.write(replace(p, image=with_hance_map(p.image, levels)))
    return buf.getvalue()


def test_the_decoder_blends_by_the_map_full_and_none_are_the_plain_decodes(clip_lf):
    data = lfstream.encode(clip_lf, quality=40, preset="fast")
    on, off = lfstream.decode(data, hance="on"), lfstream.decode(data, hance="off")
    assert not np.array_equal(on, off)
    assert np.array_equal(lfstream.decode(_rewritten(data, np.full((4, 4), HANCE_LEVELS, np.uint8)), hance="on"), on)
    assert np.array_equal(lfstream.decode(_rewritten(data, np.zeros((4, 4), np.uint8)), hance="on"), off)
    # a map is a comment to a decoder without the network
    assert np.array_equal(lfstream.decode(_rewritten(data, np.full((2, 3), 2, np.uint8)), hance="off"), off)


def test_the_encoder_sends_maps_that_do_not_lose_to_either_end(clip_lf):
    plain = lfstream.encode(clip_lf, quality=40, preset="fast")
    mapped = lfstream.encode(clip_lf, quality=40, preset="fast", hance_map=True)
    assert mapped == lfstream.encode(clip_lf, quality=40, preset="fast", hance_map=True)  # deterministic
    header, packets = split_stream(mapped)
    maps = [hance_map(p.image) for p in packets]
    assert all(m is not None and m.shape == (16, 16) for m in maps) and all(np.array_equal(m, maps[0]) for m in maps)
    assert np.array_equal(lfstream.decode(mapped, hance="off"), lfstream.decode(plain, hance="off"))
    off = lfstream.decode(plain, hance="off")
    on = lfstream.decode(plain, hance="on")
    with_map = lfstream.decode(mapped, hance="on")

    def quality(rec):
        return float(np.mean([np.mean(np.minimum(mpsnr(clip_lf[t], rec[t]), 100)) for t in range(len(rec))]))

    # chosen per tile on the first frame (the map's blend is bilinear, the choice per tile: 0.05 dB)
    assert quality(with_map) >= max(quality(off), quality(on)) - 0.05


def test_a_decoder_that_follows_packets_decodes_the_next_as_a_full_decoder_does(clip_lf):
    """``Decoder.follow`` (how the encoder's map keeps up with its stream between the frames
    it measures) reads a packet's hint and gains only: a decoder that followed frames 0..k-1
    decodes frame k as one that decoded them all (delta hints and delta gains included),
    and a stream with maps re-measured every other frame is the same either way (bytes)."""
    from lfstream.codec.decoder import Decoder
    from lfstream.codec.hint import HintOptions

    lf = synth_clip(4, 7, (48, 64), seed=8, motion=0.5, camera_pan=0.2, vignetting=0.3).lf
    data = lfstream.encode(lf, quality=40, preset="fast")
    header, packets = split_stream(data)
    assert all(p.hint for p in packets) and all(p.gain for p in packets)
    full = Decoder(header, hance="off")
    frames = [full.decode_packet(p).lf for p in packets]
    for k in range(1, len(packets)):
        follower = Decoder(header, hance="off")
        for p in packets[:k]:
            follower.follow(p)
        assert np.array_equal(follower.decode_packet(packets[k]).lf, frames[k]), k
    every_other = lfstream.encode(lf, quality=40, preset="fast", hance_map=True, hint_options=HintOptions(key_interval=2))
    maps = [hance_map(p.image) for p in split_stream(every_other)[1]]
    assert np.array_equal(maps[0], maps[1]) and np.array_equal(maps[2], maps[3])


def test_hance_auto_runs_the_network_on_streams_with_maps_only(clip_lf):
    """A stream with the encoder's strength maps names their network in its header, and
    ``hance="auto"`` decodes it as ``"on"`` on any device (the encoder measured where the
    network helps); a stream without maps decodes as before (``"off"`` on the CPU for the
    fast preset at this quality), also when a map is pasted into its JPEGs."""
    mapped = lfstream.encode(clip_lf, quality=40, preset="fast", hance_map=True)
    plain = lfstream.encode(clip_lf, quality=40, preset="fast")
    assert split_stream(mapped)[0].meta["hance_map"] == "fast" and "hance_map" not in split_stream(plain)[0].meta
    assert np.array_equal(lfstream.decode(mapped), lfstream.decode(mapped, hance="on"))
    assert not np.array_equal(lfstream.decode(mapped), lfstream.decode(mapped, hance="off"))
    assert np.array_equal(lfstream.decode(plain), lfstream.decode(plain, hance="off"))
    pasted = _rewritten(plain, np.full((4, 4), 2, np.uint8))
    assert np.array_equal(lfstream.decode(pasted), lfstream.decode(plain, hance="off"))


def test_the_default_encode_marks_its_jpeg_frames_and_the_option_is_checked(clip_lf):
    lf = synth_clip(1, 7, (48, 64), seed=5).lf[0]
    header, packets = split_stream(lfstream.encode(lf, hance_map=True))
    assert header.codec == CODEC_JPEG and hance_map(packets[0].image) is not None  # the default's JPEG centre
    assert split_stream(lfstream.encode(lf))[1][0].hint == packets[0].hint  # the same frame otherwise
    for kwargs in ({"preset": "balanced"}, {"preset": "fast", "residual": 40}):
        with pytest.raises(LFValueError, match="hance_map"):
            Encoder(hance_map=True, **kwargs)
    with pytest.raises(LFValueError, match="hance_map"):
        lfstream.encode(lf, bpp=0.05, hance_map=True)


def test_the_strength_terms_kernel_equals_numpy_over_the_views_present(rng):
    from lfstream.codec.centre.hance_kernels import strength_error_terms

    plain, restored, ref = rng.integers(0, 256, (3, 3, 4, 9, 11, 3), dtype=np.uint8)
    present = rng.random((3, 4)) < 0.6
    cross, square = np.full((2, 9, 11), -1, np.int64)
    strength_error_terms(plain, restored, ref, present, cross, square)
    p, r, t = (a[present].astype(np.int64) for a in (plain, restored, ref))
    np.testing.assert_array_equal(cross, ((p - t) * (r - p)).sum(axis=(0, 3)))
    np.testing.assert_array_equal(square, np.square(r - p).sum(axis=(0, 3)))


def test_the_measured_levels_are_the_blend_and_warp_per_level_within_rounding(clip_lf):
    """The quadratic in the strength (two warps) against the search it replaces (a blend and
    a warp per level, each rounded to 8 bits): the same level on nine tiles in ten, and
    every tile's level within 2 % of the best level's error."""
    from lfstream.codec.bitstream import iter_packets, read_header
    from lfstream.codec.centre.jpeg import blend_restored
    from lfstream.codec.decoder import Decoder
    from lfstream.codec.warp.cpu import warp_views

    lf = clip_lf[0]
    data = lfstream.encode(lf, quality=30, preset="fast")
    fh = io.BytesIO(data)
    header = read_header(fh)
    dec = Decoder(header, hance="off")
    frame = dec.decode_packet(next(iter_packets(fh, header)))
    rng = np.random.default_rng(5)  # a 'restored' centre that helps some tiles and hurts others
    truth = lf[2, 2].astype(np.int16)
    towards = frame.centre + (truth - frame.centre) * rng.uniform(-0.5, 1.5, (1, 96, 1))
    restored = np.clip(np.rint(towards), 0, 255).astype(np.uint8)
    args = (frame.disparity, frame.axes, frame.gains)
    levels = measure_hance_map(lf, frame.centre, restored, *args, tiles=8, occlusion=dec.occlusion, warped=frame.lf)
    rows, cols = tile_edges(64, 8), tile_edges(96, 8)
    errors = []
    for level in range(HANCE_LEVELS + 1):
        warped = warp_views(blend_restored(frame.centre, restored, level / HANCE_LEVELS), frame.disparity, (5, 5),
                            occlusion=dec.occlusion, gains=frame.gains, axes=frame.axes)
        err = np.square(warped.astype(np.int64) - lf).sum(axis=(0, 1, 4))
        errors.append(np.add.reduceat(np.add.reduceat(err, rows[:-1], axis=0), cols[:-1], axis=1))
    errors = np.stack(errors)
    chosen = np.take_along_axis(errors, levels[None].astype(np.int64), axis=0)[0]
    assert len(np.unique(levels)) >= 3  # the case measures a choice, not one end
    # a level moves only between near ties (here 1 tile of 64, 1.3 % over the best)
    assert (levels == errors.argmin(axis=0)).mean() >= 0.9
    assert (chosen <= errors.min(axis=0) * 1.02 + 1).all()


def test_the_default_encode_of_views_it_codes_as_a_sequence_sends_no_map():
    """toys_array: the default codes the views themselves (an AV1 sequence, no JPEG centre),
    so hance_map changes nothing."""
    from lfstream.codec.bitstream import CODEC_AV1
    from tests.conftest import shared

    lf = lfstream.read_lf(shared("toys_array"))
    data = lfstream.encode(lf, hance_map=True)
    header, _ = split_stream(data)
    assert header.codec == CODEC_AV1 and header.has_residual
    assert data == lfstream.encode(lf)
