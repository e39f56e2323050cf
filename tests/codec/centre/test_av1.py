"""The centre view's coding: JPEG and AV1 key frames, the presets that pick them, and the
streams that carry them."""

import json

import numpy as np
import pytest

import lfstream
from lfstream.cli import main
from lfstream.codec.bitstream import (
    CODEC_AV1,
    CODEC_JPEG,
    VERSION,
    StreamHeader,
    pack_header,
    read_header,
    split_stream,
)
from lfstream.codec.centre import CentreCoding
from lfstream.codec.centre.av1 import av1_crf, decode_av1, encode_av1
from lfstream.codec.encoder import PRESETS
from lfstream.errors import BitstreamError, LFValueError
from lfstream.metrics import mpsnr, psnr
from lfstream.synth import synth_clip


@pytest.fixture(scope="module")
def scene():
    return synth_clip(1, 5, (96, 128), seed=4, noise=1.0).lf[0]


def test_av1_round_trip_is_faithful_deterministic_and_crops_odd_sizes(scene):
    img = np.ascontiguousarray(scene[2, 2, :95, :127])  # odd sizes: padded, then cropped
    data = encode_av1(img, 60, speed=12)
    assert data == encode_av1(img, 60, speed=12)  # same input, same bytes
    back = decode_av1(data, img.shape[:2])
    assert back.shape == img.shape and back.dtype == np.uint8
    assert psnr(img, back) > 33.0  # 4:2:0 of a textured synthetic view at quality 60
    sizes = [len(encode_av1(img, q)) for q in (10, 50, 90)]
    assert sizes[0] < sizes[1] < sizes[2]


def test_av1_centre_decodes_the_same_on_one_thread_or_several(scene, monkeypatch):
    """Small centre views are decoded on one dav1d thread (AV1_THREADED_MIN_PIXELS), large
    ones threaded: the same pixels either way."""
    from lfstream.codec.centre import av1 as intra

    img = np.ascontiguousarray(scene[2, 2])
    data = encode_av1(img, 60)
    one = decode_av1(data, img.shape[:2])
    monkeypatch.setattr(intra, "AV1_THREADED_MIN_PIXELS", 0)
    np.testing.assert_array_equal(decode_av1(data, img.shape[:2]), one)


def test_colour_conversion_keeps_chroma_detail():
    """4:2:0 by 2x2 means and bilinear up-sampling: within 1 dB of JPEG q100's own 4:2:0
    round trip on a textured synthetic view (OpenCV's I420 conversion lost ~5 dB there)."""
    from lfstream.codec.centre.av1 import i420_to_rgb, rgb_to_i420
    from lfstream.codec.centre.jpeg import jpeg_roundtrip

    img = synth_clip(1, 3, (96, 128), seed=21, noise=2.0).lf[0, 1, 1]
    back = i420_to_rgb(rgb_to_i420(img))
    assert back.shape == img.shape and back.dtype == np.uint8
    assert psnr(img, back) >= psnr(img, jpeg_roundtrip(img, 100)) - 1.0
    grey = np.repeat(img.mean(axis=2, keepdims=True).astype(np.uint8), 3, axis=2)
    assert np.abs(i420_to_rgb(rgb_to_i420(grey)).astype(int) - grey).max() <= 2  # no chroma: exact up to rounding


def test_quality_maps_onto_the_whole_crf_range():
    assert av1_crf(100) == 1 and av1_crf(1) == 63 and 28 <= av1_crf(50) <= 34
    with pytest.raises(LFValueError):
        av1_crf(0)
    with pytest.raises(LFValueError):
        CentreCoding("png")
    with pytest.raises(LFValueError):
        CentreCoding("av1", speed=99)


def test_svt_av1_is_capped_at_avx2_on_x86_and_left_alone_elsewhere(monkeypatch):
    """Every SVT-AV1 encoder (centre view, residual, baseline) gets the same cap; the option
    is accepted (the encode above and the baseline tests open encoders with it)."""
    import platform

    from lfstream.codec.baseline import CODECS
    from lfstream.codec.centre.av1 import svt_options

    monkeypatch.setattr(platform, "machine", lambda: "x86_64")
    assert svt_options() == {"svtav1-params": "asm=avx2"}
    assert CODECS["av1"].options(30, 9, True)["svtav1-params"] == "asm=avx2"
    monkeypatch.setattr(platform, "machine", lambda: "aarch64")
    assert svt_options() == {} and "svtav1-params" not in CODECS["av1"].options(30, 9, True)


def test_damaged_av1_payload_is_a_bitstream_error(scene):
    data = encode_av1(scene[2, 2], 50)
    with pytest.raises(BitstreamError):
        decode_av1(b"\x00garbage" * 4, scene.shape[2:4], frame=3)
    with pytest.raises(BitstreamError, match="header says"):
        decode_av1(data, (scene.shape[2] - 10, scene.shape[3]))


def test_presets_code_their_centre_views_in_the_one_format_and_decode(scene):
    fast = lfstream.encode(scene, preset="fast")  # the seed's JPEG
    assert fast[4:6] == VERSION.to_bytes(2, "little") and split_stream(fast)[0].codec == CODEC_JPEG
    # the default on a 5x5 grid codes the centre as AV1 (rate.DEFAULT_PRESET_BY_VIEWS)
    assert lfstream.encode(scene) == lfstream.encode(scene, preset="balanced")
    for name in ("balanced", "best"):
        data = lfstream.encode(scene, preset=name)
        header, packets = split_stream(data)
        assert header.version == VERSION and header.codec == CODEC_AV1 and header.meta["preset"] == name
        assert header.meta["centre"]["svt_preset"] == PRESETS[name].speed
        rec = lfstream.decode(data)[0]
        assert rec.shape == scene.shape
        assert mpsnr(scene, rec) > 28.0
        assert data == lfstream.encode(scene, preset=name)  # deterministic


def test_unknown_codecs_are_refused():
    av1 = pack_header(StreamHeader(views=(3, 3), size=(16, 16), codec=CODEC_AV1))
    assert read_header(__import__("io").BytesIO(av1)).codec == CODEC_AV1
    forged = bytearray(av1)
    forged[18] = 9  # the codec byte (CRC fixed below)
    import struct
    import zlib

    forged[-4:] = struct.pack("<I", zlib.crc32(bytes(forged[:-4])))
    with pytest.raises(BitstreamError, match="unknown codec id 9"):
        read_header(__import__("io").BytesIO(bytes(forged)))
    with pytest.raises(BitstreamError, match="unknown codec"):
        pack_header(StreamHeader(views=(3, 3), size=(16, 16), codec=9))


def test_av1_centre_gives_equal_quality_for_fewer_bytes(scene):
    """The reason for the balanced preset: some JPEG quality reaches the AV1 stream's MPSNR
    only with at least 10 % more bytes (synthetic 5x5x96x128, noise 1)."""
    av1 = lfstream.encode(scene, quality=50, preset="balanced")
    target = mpsnr(scene, lfstream.decode(av1)[0])
    fast = [(len(d), mpsnr(scene, lfstream.decode(d)[0])) for d in (lfstream.encode(scene, quality=q, preset="fast") for q in
                                                                     range(30, 101, 5))]
    enough = [n for n, m in fast if m >= target]
    assert enough, "no JPEG quality reaches the AV1 stream's MPSNR"
    assert min(enough) >= 1.1 * len(av1), (min(enough), len(av1))


def test_rate_control_considers_every_preset_and_reproduces_its_stream(scene):
    from lfstream.codec.rate import RATE_TOLERANCE, choose_configuration, choose_rate

    target = 0.1
    choice = choose_configuration(scene[None], target, 30.0)  # no preset named: every preset
    assert {c["preset"] for c in choice.candidates} == set(PRESETS)
    assert {c["hint_scale"] for c in choice.candidates} == {4, 8, None}
    assert abs(choice.bpp - target) / target <= RATE_TOLERANCE
    # the chosen configuration, encoded plainly, gives the same bytes (the residual layer included)
    again = lfstream.encode(scene, quality=choice.quality, depth_hint=choice.depth_hint, preset=choice.preset,
                            hint_options=choice.hint_options, residual=choice.residual)
    assert choice.stream() == again
    # the API's bpp is rate control's default (the model), its stream the same bytes
    assert lfstream.encode(scene, bpp=target) == choose_rate(scene[None], target, 30.0).stream()


def test_cli_encode_takes_a_preset(scene, tmp_path, capsys):
    np.save(tmp_path / "lf.npy", scene)
    assert main(["encode", str(tmp_path / "lf.npy"), "-o", str(tmp_path / "a.lfs"), "--preset", "balanced", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["preset"] == "balanced"
    assert split_stream((tmp_path / "a.lfs").read_bytes())[0].codec == CODEC_AV1
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "a.npy")]) == 0
    assert np.load(tmp_path / "a.npy").shape[-5:] == scene.shape
    with pytest.raises(SystemExit) as exc:
        main(["encode", str(tmp_path / "lf.npy"), "-o", str(tmp_path / "b.lfs"), "--preset", "slowest"])
    assert exc.value.code == 2


@pytest.mark.parametrize("size", [(1, 17), (13, 1), (2, 2), (24, 40), (40, 29)])
def test_views_too_small_for_av1_are_a_clear_error_and_the_default_still_codes_them(size):
    """SVT-AV1 writes past its heap on frames under 32 px a side (it refuses only those under
    4x4): AV1 presets and residuals name the limit (an LFValueError raised before any
    encoder opens); the default and rate control keep to JPEG."""
    from lfstream.errors import LFValueError

    lf = np.random.default_rng(0).integers(0, 256, (3, 3, *size, 3), dtype=np.uint8)
    for kwargs in ({"preset": "balanced"}, {"preset": "fast", "residual": 50, "residual_mode": "views"}):
        with pytest.raises(LFValueError, match="at least 31x31"):
            lfstream.encode(lf, **kwargs)
    for data in (lfstream.encode(lf), lfstream.encode(lf, bpp=0.5)):
        assert lfstream.decode(data)[0].shape == lf.shape


def test_the_av1_limit_holds_at_the_encoder_door_and_at_a_half_views_residual_size():
    from lfstream.codec.centre.av1 import av1_fits, svtav1_encoder
    from lfstream.errors import LFValueError

    assert av1_fits((31, 31)) and av1_fits((32, 400)) and not av1_fits((30, 400)) and not av1_fits((400, 29))
    with pytest.raises(LFValueError, match="at least 31x31"):
        svtav1_encoder((24, 64), 50, 12)  # the one door to SVT-AV1 checks too
    # a half-views residual codes views at half size: 40x64 views are too small
    with pytest.raises(LFValueError, match="half-views"):
        lfstream.encode(np.zeros((3, 3, 40, 64, 3), np.uint8), residual=50, residual_mode="half-views")


def test_svt_av1_prints_nothing_unless_asked():
    """SVT-AV1 prints its configuration (~20 lines an encoder) at its default log level;
    lfstream starts its encoders at errors only (SVT_LOG=1), unless the user set SVT_LOG.
    Fresh processes: SVT reads the variable once, at its first encoder."""
    import os
    import subprocess
    import sys

    code = ("import numpy as np, lfstream\n"
            "from lfstream.synth import synth_clip\n"
            "lfstream.encode(synth_clip(1, 3, (64, 96), seed=3).lf[0], preset='balanced')\n")
    env = {k: v for k, v in os.environ.items() if k != "SVT_LOG"}
    quiet = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert quiet.returncode == 0 and "Svt[" not in quiet.stderr, quiet.stderr[-500:]
    loud = subprocess.run([sys.executable, "-c", code], env={**env, "SVT_LOG": "3"}, capture_output=True, text=True,
                          timeout=120)
    assert loud.returncode == 0 and "Svt[info]" in loud.stderr  # the user's setting wins
