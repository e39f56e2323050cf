"""The centre view's JPEG: optimised Huffman tables (fewer bytes, the same pixels)."""

import cv2
import numpy as np
import pytest

from lfstream.codec.centre.jpeg import deblock_jpeg, decode_jpeg, encode_jpeg, jpeg_quality_scale, post_filter_jpeg
from lfstream.synth import synth_clip


def test_optimised_tables_code_the_same_pixels_in_fewer_bytes():
    img = synth_clip(1, 3, (96, 128), seed=3).lf[0, 1, 1]
    img = np.ascontiguousarray(img)
    img[:, :48] = 128  # a flat area: where the standard tables waste the most
    for q in (30, 50, 90):
        ours = encode_jpeg(img, q)
        ok, plain = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [int(cv2.IMWRITE_JPEG_QUALITY), q])
        assert ok
        plain_rgb = cv2.cvtColor(cv2.imdecode(plain, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert np.array_equal(decode_jpeg(ours, img.shape[:2]), plain_rgb), q
        assert len(ours) < 0.97 * len(plain), (q, len(ours), len(plain))
        assert encode_jpeg(img.copy(), q) == ours  # deterministic


@pytest.mark.parametrize("quality", [20, 35, 50, 65, 80, 95])
def test_quality_scale_is_read_from_the_quantisation_table(rng, quality):
    img = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    expected = 5000.0 / quality if quality < 50 else 200.0 - 2 * quality
    assert jpeg_quality_scale(encode_jpeg(img, quality)) == pytest.approx(expected, rel=0.03)
    assert jpeg_quality_scale(b"\xff\xd8 not a table") is None


@pytest.mark.parametrize("quality", [10, 30, 50, 80, 95])
def test_deblocking_raises_psnr_and_ssim_of_jpeg_views(quality):
    """On the synthetic renderer's textured views (not the shared samples it was tuned on):
    the post-filter brings a JPEG-decoded view closer to the original at every quality."""
    from lfstream.metrics import psnr, ssim
    from lfstream.synth import synth_clip

    for seed in (4, 9):
        view = synth_clip(1, 3, (120, 160), seed=seed, noise=1.0, motion=0, camera_pan=0).lf[0, 1, 1]
        data = encode_jpeg(view, quality)
        raw = decode_jpeg(data, view.shape[:2])
        filtered = deblock_jpeg(raw, jpeg_quality_scale(data))
        assert filtered.shape == raw.shape and filtered.dtype == np.uint8
        assert float(psnr(view, filtered)) > float(psnr(view, raw)), (seed, quality)
        assert float(ssim(view, filtered)) >= float(ssim(view, raw)) - 1e-4, (seed, quality)
    assert deblock_jpeg(raw, 0.0) is raw  # nothing to undo at quality 100


def test_the_decoder_filters_jpeg_centres_unless_told_not_to():
    import lfstream
    from lfstream.codec.bitstream import split_stream
    from lfstream.codec.decoder import Decoder
    from lfstream.synth import synth_clip

    lf = synth_clip(1, 3, (64, 96), seed=5).lf[0]
    header, packets = split_stream(lfstream.encode(lf, quality=40, preset="fast"))
    raw = decode_jpeg(packets[0].image, (64, 96))
    on = Decoder(header).decode_centres(packets)[0]
    off = Decoder(header, deblock=False).decode_centres(packets)[0]
    np.testing.assert_array_equal(off, raw)
    np.testing.assert_array_equal(on, post_filter_jpeg(raw, packets[0].image))
    assert not np.array_equal(on, off)


def test_cli_decode_no_deblock_gives_the_raw_jpeg_centre(tmp_path):
    import lfstream
    from lfstream.cli import main
    from lfstream.codec.bitstream import split_stream

    lf = synth_clip(1, 3, (48, 64), seed=6).lf[0]
    data = lfstream.encode(lf, quality=30, preset="fast")
    (tmp_path / "a.lfs").write_bytes(data)
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "raw.npy"), "--no-deblock"]) == 0
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "filtered.npy")]) == 0
    raw, filtered = np.load(tmp_path / "raw.npy"), np.load(tmp_path / "filtered.npy")
    jpeg = split_stream(data)[1][0].image
    assert raw.shape == (3, 3, 48, 64, 3)  # one frame decodes to one light field, as it was encoded
    np.testing.assert_array_equal(raw[1, 1], decode_jpeg(jpeg, (48, 64)))
    np.testing.assert_array_equal(filtered[1, 1], post_filter_jpeg(decode_jpeg(jpeg, (48, 64)), jpeg))


def test_roundtrip_with_deblock_is_the_decoders_filtered_view():
    """``jpeg_roundtrip(..., deblock=True)`` (a post-filter network's training input) is the
    decoded JPEG through the filter the encoder chooses for it, at that JPEG's own strength,
    as the decoder shows it."""
    from lfstream.codec.centre.jpeg import POST_FILTERS, choose_post_filter, jpeg_roundtrip

    img = synth_clip(1, 1, (64, 96), seed=12, noise=2.0, motion=0).lf[0, 0, 0]
    data = encode_jpeg(img, 40)
    plain = decode_jpeg(data, img.shape[:2])
    assert (jpeg_roundtrip(img, 40) == plain).all()
    filtered = jpeg_roundtrip(img, 40, deblock=True)
    choice = choose_post_filter(img, data)
    assert choice.index != 0  # the noisy render takes the wider filter: the choice matters here
    assert (filtered == deblock_jpeg(plain, jpeg_quality_scale(data), POST_FILTERS[choice.index])).all()
    assert (filtered != deblock_jpeg(plain, jpeg_quality_scale(data))).any()


def test_a_post_filter_segment_names_the_filter_and_keeps_the_pixels():
    """The encoder's choice rides in a JPEG comment right after SOI: the pixels, and any
    JPEG decoder, are unaffected; the default choice is the plain JPEG, byte for byte."""
    from lfstream.codec.centre.jpeg import POST_FILTERS, PostFilterChoice, named_post_filter, with_post_filter
    from lfstream.errors import BitstreamError, LFValueError

    img = synth_clip(1, 1, (48, 64), seed=2, noise=2.0, motion=0).lf[0, 0, 0]
    data = encode_jpeg(img, 50)
    raw = decode_jpeg(data, (48, 64))
    assert named_post_filter(data) == PostFilterChoice()
    for choice in [PostFilterChoice(i) for i in range(1, len(POST_FILTERS))] + [PostFilterChoice(0, 3)]:
        marked = with_post_filter(data, choice)
        assert named_post_filter(marked) == choice and len(marked) == len(data) + 10
        assert np.array_equal(decode_jpeg(marked, (48, 64)), raw)
        assert with_post_filter(with_post_filter(marked, PostFilterChoice(1, 1)), choice) == marked  # replaces
        assert with_post_filter(marked, PostFilterChoice()) == data
        expected = deblock_jpeg(raw, jpeg_quality_scale(data), POST_FILTERS[choice.index])
        expected[(expected <= choice.black_floor).all(-1)] = 0
        assert np.array_equal(post_filter_jpeg(raw, marked), expected)
    for bad in (PostFilterChoice(len(POST_FILTERS)), PostFilterChoice(0, 17)):
        with pytest.raises(LFValueError, match="post-filter choice"):
            with_post_filter(data, bad)
    marked = with_post_filter(data, PostFilterChoice(1))
    with pytest.raises(BitstreamError, match="frame 7.*post-filter 200"):
        named_post_filter(marked[:10] + bytes([200]) + marked[11:], 7)


def test_a_stream_naming_an_unknown_post_filter_fails_naming_the_frame(tmp_path):
    from dataclasses import replace

    import lfstream
    from lfstream.cli import main
    from lfstream.codec.bitstream import pack_header, pack_packet, split_stream
    from lfstream.codec.centre.jpeg import PostFilterChoice, with_post_filter
    from lfstream.errors import BitstreamError

    lf = synth_clip(2, 3, (48, 64), seed=6).lf
    header, packets = split_stream(lfstream.encode(lf))
    marked = with_post_filter(packets[1].image, PostFilterChoice(1))
    bad = replace(packets[1], image=marked[:10] + b"\x09" + marked[11:])
    data = pack_header(header) + pack_packet(packets[0], header.version) + pack_packet(bad, header.version)
    with pytest.raises(BitstreamError, match="frame 1"):
        lfstream.decode(data)
    (tmp_path / "bad.lfs").write_bytes(data)
    assert main(["decode", str(tmp_path / "bad.lfs"), "-o", str(tmp_path / "out.npy")]) == 2


def _brute_force_choice(img: np.ndarray, data: bytes) -> int:
    """The filter rule of :func:`choose_post_filter` measured on the whole view."""
    from lfstream.codec.centre.jpeg import CHOICE_MAX_PSNR_LOSS, CHOICE_MIN_SSIM_GAIN, POST_FILTERS
    from lfstream.metrics import psnr, ssim

    raw = decode_jpeg(data, img.shape[:2])
    scores = [(float(ssim(img, f)), float(psnr(img, f)))
              for f in (deblock_jpeg(raw, jpeg_quality_scale(data), pf) for pf in POST_FILTERS)]
    best = max(range(len(scores)),
               key=lambda i: scores[i][0] if scores[i][1] >= scores[0][1] - CHOICE_MAX_PSNR_LOSS else -1.0)
    return best if scores[best][0] >= scores[0][0] + CHOICE_MIN_SSIM_GAIN else 0


@pytest.mark.parametrize("seed, noise, quality", [(21, 2.0, 50), (5, 0.0, 50), (8, 1.0, 80)])
def test_the_choice_on_the_sample_is_the_whole_views_choice(seed, noise, quality):
    """Measured on six bands of rows (each filtered with its context, so exactly what the
    whole view shows there), the choice agrees with the same rule on the whole view; and
    a chosen filter is at least as good as the default in SSIM on the whole view."""
    from lfstream.codec.centre.jpeg import POST_FILTERS, choose_post_filter
    from lfstream.metrics import ssim

    img = np.ascontiguousarray(synth_clip(1, 3, (192, 256), seed=seed, noise=noise, vignetting=0.3, motion=0,
                                          camera_pan=0).lf[0, 1, 1])
    data = encode_jpeg(img, quality)
    chosen = choose_post_filter(img, data)
    assert chosen.black_floor == 0 and chosen.index == _brute_force_choice(img, data)
    assert choose_post_filter(img, data, bands=1, band_rows=img.shape[0]) == chosen
    raw = decode_jpeg(data, img.shape[:2])
    scale = jpeg_quality_scale(data)
    assert float(ssim(img, deblock_jpeg(raw, scale, POST_FILTERS[chosen.index]))) >= \
        float(ssim(img, deblock_jpeg(raw, scale)))


@pytest.mark.parametrize("quality, floor", [(40, 1), (50, 0), (70, 1)])
def test_black_that_jpeg_lifts_is_named_and_restored(quality, floor):
    """A view on a black background (seahorse's kind): at qualities whose luma DC step does
    not divide 1024 (40, 70) the black decodes at 1 and SSIM collapses in it; the encoder
    names floor 1 and the decoder's view is black again (SSIM up by more than 0.05); at 50
    it decodes at 0 and nothing is named."""
    from lfstream.codec.centre.jpeg import choose_post_filter, with_post_filter
    from lfstream.metrics import ssim

    img = np.zeros((128, 160, 3), np.uint8)
    yy, xx = np.mgrid[:128, :160]
    img[32:96, 48:112] = (np.stack([xx, yy, xx + yy], -1)[32:96, 48:112] % 200 + 40).astype(np.uint8)
    data = encode_jpeg(img, quality)
    choice = choose_post_filter(img, data)
    assert choice.black_floor == floor
    raw = decode_jpeg(data, img.shape[:2])
    plain = post_filter_jpeg(raw, data)
    named = post_filter_jpeg(raw, with_post_filter(data, choice))
    far = (yy < 16) | (yy >= 112) | (xx < 32) | (xx >= 128)  # beyond the content's MCUs and ringing
    assert (named[far] == 0).all() and ((plain[far] == 0).all() != bool(floor))
    if floor:
        assert float(ssim(img, named)) > float(ssim(img, plain)) + 0.05


def test_the_encoder_names_a_better_filter_for_a_noisy_view_and_can_be_told_not_to():
    """A noisy smooth render (the bench's synthetic scene) gets the wider filter: the decoded
    light field's MSSIM rises by more than 0.005 at the same bits (+10 bytes); with
    ``post_filter=False`` the stream is the plain JPEG's."""
    import io

    import lfstream
    from lfstream.codec.bitstream import StreamWriter, split_stream
    from lfstream.codec.centre.jpeg import named_post_filter
    from lfstream.codec.encoder import Encoder
    from lfstream.metrics import mssim

    lf = synth_clip(1, 5, (192, 256), seed=21, noise=2.0, vignetting=0.3, motion=0, camera_pan=0).lf[0]
    chosen = lfstream.encode(lf, preset="fast")  # a JPEG centre (the default codes a 5x5 grid's as AV1)
    enc = Encoder(post_filter=False)
    buf = io.BytesIO()
    StreamWriter(buf, enc.header((5, 5), (192, 256), 30.0)).write(enc.encode_frame(lf, 0, 0))
    plain = buf.getvalue()
    assert lfstream.encode(lf, post_filter=False, preset="fast") == plain
    assert named_post_filter(split_stream(chosen)[1][0].image).index != 0
    assert named_post_filter(split_stream(plain)[1][0].image).index == 0
    assert len(chosen) == len(plain) + 10
    assert float(mssim(lf, lfstream.decode(chosen)[0])) > float(mssim(lf, lfstream.decode(plain)[0])) + 0.005


def test_the_choice_is_measured_on_key_frames_only(monkeypatch):
    import lfstream.codec.centre.jpeg as jpeg

    calls = []
    monkeypatch.setattr(jpeg, "choose_post_filter",
                        lambda original, data: calls.append(1) or jpeg.PostFilterChoice(len(calls) % 3))
    img = synth_clip(1, 1, (32, 48), seed=1, motion=0).lf[0, 0, 0]
    data = encode_jpeg(img, 50)
    chooser = jpeg.PostFilterChooser(interval=3)
    named = [jpeg.named_post_filter(chooser.mark(img, data)).index for _ in range(7)]
    assert len(calls) == 3 and named == [1, 1, 1, 2, 2, 2, 0]


def test_the_jfif_segment_is_left_out_and_no_pixel_changes(rng):
    """encode_jpeg drops libjpeg's optional JFIF APP0 segment (18 bytes): the same pixels as
    the JPEG OpenCV writes with it, and the post-filter's comment still goes right after SOI."""
    from lfstream.codec.centre.jpeg import POST_FILTERS, PostFilterChoice, named_post_filter, with_post_filter

    img = (rng.random((48, 72, 3)) * 255).astype(np.uint8)
    ours = encode_jpeg(img, 50)
    ok, full = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR),
                            [int(cv2.IMWRITE_JPEG_QUALITY), 50, int(cv2.IMWRITE_JPEG_OPTIMIZE), 1])
    full = full.tobytes()
    assert full[2:4] == b"\xff\xe0" and ours[2:4] != b"\xff\xe0" and len(ours) == len(full) - 18
    assert np.array_equal(decode_jpeg(ours, (48, 72)), decode_jpeg(full, (48, 72)))
    marked = with_post_filter(ours, PostFilterChoice(len(POST_FILTERS) - 1, 3))
    assert named_post_filter(marked) == PostFilterChoice(len(POST_FILTERS) - 1, 3)
    assert np.array_equal(decode_jpeg(marked, (48, 72)), decode_jpeg(ours, (48, 72)))


def test_wide_post_filters_run_without_ipp_on_this_thread_only_and_give_the_same_bytes():
    """The 7 x 7 post-filter runs OpenCV's own bilateral code (faster than IPP's here, the
    same bytes: both are compared on a textured view at the JPEG scales in use); the IPP
    switch is restored afterwards and never seen by another thread."""
    import threading

    from lfstream.codec.centre.jpeg import IPP_BILATERAL_MAX_DIAMETER, POST_FILTERS

    rng = np.random.default_rng(3)
    img = cv2.GaussianBlur(rng.integers(0, 256, (75, 101, 3), dtype=np.uint8), (3, 3), 0)
    wide = [pf for pf in POST_FILTERS if pf.diameter > IPP_BILATERAL_MAX_DIAMETER]
    assert wide  # the 7 x 7 filter
    seen = []

    def watch():
        seen.append(cv2.ipp.useIPP())

    was = cv2.ipp.useIPP()
    for pf in wide:
        for scale in (0.5, 1.0, 2.0, 4.0):
            got = deblock_jpeg(img, scale, pf)
            assert cv2.ipp.useIPP() == was
            thread = threading.Thread(target=watch)
            thread.start()
            thread.join()
            cv2.ipp.setUseIPP(True)
            try:
                with_ipp = cv2.bilateralFilter(img, pf.diameter, pf.range_factor * scale, pf.spatial_sigma)
            finally:
                cv2.ipp.setUseIPP(was)
            np.testing.assert_array_equal(got, with_ipp)
    assert seen and all(s == cv2.ipp.useIPP() for s in seen)


@pytest.mark.parametrize("shape", [(75, 101), (64, 9), (5, 40), (1, 33)])
@pytest.mark.parametrize("stripe_pixels", [1, 200, 1 << 16])
def test_the_wide_post_filter_in_pieces_of_rows_gives_one_calls_bytes(monkeypatch, shape, stripe_pixels):
    """The 7 x 7 filter runs as pieces of rows sized to OpenCV's thread stripes, each with its
    neighbours' context rows: exactly one call's output, whatever the pieces (a piece a row
    high included)."""
    from lfstream.codec.centre import jpeg

    rng = np.random.default_rng(7)
    img = cv2.GaussianBlur(rng.integers(0, 256, (*shape, 3), dtype=np.uint8), (3, 3), 0)
    monkeypatch.setattr(jpeg, "_CV_STRIPE_PIXELS", stripe_pixels)
    with jpeg._without_ipp():
        for sigma in (0.9, 3.6, 20.0):
            one = cv2.bilateralFilter(img, 7, sigma, 3.0)
            np.testing.assert_array_equal(jpeg._bilateral_in_pieces(img, 7, sigma, 3.0), one)
