"""The centre view's JPEG: optimised Huffman tables (fewer bytes, the same pixels)."""

import cv2
import numpy as np
import pytest

from lfstream.codec.jpeg import deblock_jpeg, decode_jpeg, encode_jpeg, jpeg_quality_scale
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
    header, packets = split_stream(lfstream.encode(lf, quality=40))
    raw = decode_jpeg(packets[0].image, (64, 96))
    on = Decoder(header).decode_centres(packets)[0]
    off = Decoder(header, deblock=False).decode_centres(packets)[0]
    np.testing.assert_array_equal(off, raw)
    np.testing.assert_array_equal(on, deblock_jpeg(raw, jpeg_quality_scale(packets[0].image)))
    assert not np.array_equal(on, off)


def test_cli_decode_no_deblock_gives_the_raw_jpeg_centre(tmp_path):
    import lfstream
    from lfstream.cli import main
    from lfstream.codec.bitstream import split_stream

    lf = synth_clip(1, 3, (48, 64), seed=6).lf[0]
    data = lfstream.encode(lf, quality=30)
    (tmp_path / "a.lfs").write_bytes(data)
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "raw.npy"), "--no-deblock"]) == 0
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "filtered.npy")]) == 0
    raw, filtered = np.load(tmp_path / "raw.npy"), np.load(tmp_path / "filtered.npy")
    jpeg = split_stream(data)[1][0].image
    np.testing.assert_array_equal(raw[0, 1, 1], decode_jpeg(jpeg, (48, 64)))
    np.testing.assert_array_equal(filtered[0, 1, 1], deblock_jpeg(decode_jpeg(jpeg, (48, 64)), jpeg_quality_scale(jpeg)))


def test_roundtrip_with_deblock_is_the_decoders_filtered_view():
    """``jpeg_roundtrip(..., deblock=True)`` (a post-filter network's training input) is the
    decoded JPEG filtered at that JPEG's own strength, as the decoder shows it."""
    from lfstream.codec.jpeg import jpeg_roundtrip

    img = synth_clip(1, 1, (64, 96), seed=12, noise=2.0, motion=0).lf[0, 0, 0]
    data = encode_jpeg(img, 40)
    plain = decode_jpeg(data, img.shape[:2])
    assert (jpeg_roundtrip(img, 40) == plain).all()
    filtered = jpeg_roundtrip(img, 40, deblock=True)
    assert (filtered == deblock_jpeg(plain, jpeg_quality_scale(data))).all()
    assert (filtered != plain).any()
