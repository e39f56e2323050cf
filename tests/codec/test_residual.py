"""The residual layer: what the prediction misses, coded per view; version-3 streams; rate
control that chooses it."""

import json
import struct
from dataclasses import replace

import numpy as np
import pytest

from lfstream.cli import main
from lfstream.codec import decode, encode
from lfstream.codec.bitstream import (
    VERSION_RESIDUAL,
    Packet,
    StreamHeader,
    pack_header,
    pack_packet,
    read_header,
    split_stream,
)
from lfstream.codec.decoder import Decoder
from lfstream.codec.residual import (
    OFFSET,
    apply_residual,
    encode_residual,
    residual_images,
    residual_views,
)
from lfstream.errors import BitstreamError, LFStreamError, LFValueError
from lfstream.metrics import bpp, mpsnr
from lfstream.synth import synth_clip


@pytest.fixture(scope="module")
def clip():
    # per-view noise is what no warp predicts: the residual's job
    return synth_clip(2, 5, (64, 96), seed=11, noise=3.0).lf


@pytest.fixture(scope="module")
def coded(clip):
    return encode(clip, quality=60, preset="balanced", residual=60)


def test_residual_views_are_serpentine_without_the_centre():
    order = residual_views((3, 3))
    assert order == [(0, 0), (0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1), (2, 2)]
    order = residual_views((7, 5))
    assert len(order) == len(set(order)) == 34 and (3, 2) not in order
    # consecutive frames are neighbouring views (one step along a row or a column)
    assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) <= 2 for a, b in zip(order, order[1:]))


def test_residual_raises_quality_and_costs_bits(clip, coded):
    plain = encode(clip, quality=60, preset="balanced")
    assert coded[4] == VERSION_RESIDUAL and plain[4] == 2  # a version-3 stream only with a residual
    out, base = decode(coded), decode(plain)
    gain = mpsnr(out[0], clip[0]) - mpsnr(base[0], clip[0])
    assert gain > 1.5, gain  # measured 4.6 dB here (noise 3: the prediction alone cannot carry it)
    assert len(coded) > len(plain)
    # the centre view is untouched by the residual
    np.testing.assert_array_equal(out[:, 2, 2], base[:, 2, 2])
    # determinism: same input and options, same bytes
    assert encode(clip, quality=60, preset="balanced", residual=60) == coded
    # more residual quality, more bits, better views
    low = encode(clip, quality=60, preset="balanced", residual=20)
    assert len(low) < len(coded) and mpsnr(decode(low)[0], clip[0]) < mpsnr(out[0], clip[0])


def test_fused_residual_matches_the_plain_path(clip, coded):
    header, packets = split_stream(coded)
    dec = Decoder(header, depth="hint", hance="off")
    plain = replace(packets[0], residual=b"")
    prediction = Decoder(header, depth="hint", hance="off").decode_packet(plain).lf
    fused = dec.decode_packet(packets[0]).lf
    ref = prediction.astype(np.int16)
    for (a, b), img in zip(residual_views(header.views), residual_images(packets[0].residual, header.views, header.size)):
        ref[a, b] += img.astype(np.int16) - OFFSET
    ref = np.clip(ref, 0, 255)
    diff = np.abs(fused.astype(np.int16) - ref)
    # the kernel's YCbCr matrix is OpenCV's (exact); its chroma interpolation rounds once where
    # OpenCV's SIMD resize truncates in between: one chroma level on ~9 % of samples of noise,
    # up to two RGB levels
    assert diff.max() <= 2 and diff.mean() < 0.25, (diff.max(), diff.mean())  # measured 2 and 0.12


def test_residual_is_added_only_to_its_reference_prediction(clip, coded):
    header, packets = split_stream(coded)
    assert header.has_residual and header.meta["residual"]["quality"] == 60
    flat = Decoder(header, depth="flat")
    frames = flat.decode_batch(packets)
    assert flat.residual_skipped == len(packets) and not flat.applies_residual
    assert (frames[0].lf[0, 0] == frames[0].lf[2, 2]).all()  # the flat prediction, nothing added
    # JPEG-Hance "auto" stays off on a residual stream (the residual was computed without it)
    low_q = encode(clip[:1], quality=10, residual=30)
    assert Decoder(read_header(__import__("io").BytesIO(low_q))).applies_residual


def test_version_3_packets_round_trip_and_are_checked():
    header = StreamHeader(views=(3, 3), size=(16, 16), has_hint=False, has_residual=True)
    assert header.version == VERSION_RESIDUAL
    packets = [Packet(seq=k, timestamp_us=k, image=b"i" * 5, residual=b"r" * (k + 1)) for k in range(3)]
    data = pack_header(header) + b"".join(pack_packet(p, header.version) for p in packets)
    back, got = split_stream(data)
    assert back == header and got == packets
    with pytest.raises(LFValueError, match="version-3"):
        pack_packet(packets[0], 1)  # a residual cannot go into a version-1 packet
    # a version-2 header claiming a residual layer, and a version-3 one without it
    for version, flags in ((2, 2), (3, 0)):
        bad = bytearray(pack_header(StreamHeader(views=(3, 3), size=(16, 16))))
        struct.pack_into("<HH", bad, 4, version, flags)
        import zlib

        bad[-4:] = struct.pack("<I", zlib.crc32(bytes(bad[:-4])))
        with pytest.raises(BitstreamError, match="residual flag"):
            read_header(__import__("io").BytesIO(bytes(bad)))


def test_damaged_residual_payloads_name_the_frame(clip, coded):
    header, packets = split_stream(coded)
    good = packets[0].residual
    cases = {
        "truncated head": good[:2],
        "wrong format": bytes([9]) + good[1:],
        "wrong view count": good[:2] + struct.pack("<H", 3) + good[4:],
        "cut inside a packet": good[: len(good) // 2],
        "length past the end": good[:4] + struct.pack("<I", 1 << 30) + good[8:],
        "garbage AV1": good[:8] + bytes(len(good) - 8),
    }
    rng = np.random.default_rng(7)
    for k in range(20):  # random byte damage past the head: an error or a decoded frame, nothing else
        buf = bytearray(good)
        for i in rng.integers(4, len(buf), 4):
            buf[i] = int(rng.integers(0, 256))
        cases[f"random {k}"] = bytes(buf)
    rejected = 0
    for what, payload in cases.items():
        stream = pack_header(header) + pack_packet(replace(packets[0], residual=payload), header.version)
        try:
            out = decode(stream)
            assert out.shape == (1,) + clip.shape[1:], what
        except LFStreamError as exc:
            assert isinstance(exc, BitstreamError) and "frame 0" in str(exc), (what, exc)
            rejected += 1
    assert rejected >= 6  # every structural case above is refused


def test_encode_residual_checks_its_inputs(clip):
    lf = clip[0]
    with pytest.raises(LFValueError, match="residual"):
        encode_residual(lf, lf, 0)
    with pytest.raises(LFValueError, match="uint8"):
        encode_residual(lf, lf.astype(np.float32), 50)
    with pytest.raises(LFValueError, match="residual"):
        encode(clip, residual=101)
    with pytest.raises(LFValueError, match="rate control"):
        encode(clip, bpp=0.1, residual=50)
    # a residual of the prediction itself is mid-grey: adding it changes nothing
    data = encode_residual(lf, lf, 90, speed=12)
    again = lf.copy()
    apply_residual(again, data)
    assert np.abs(again.astype(int) - lf).max() <= 1


def test_rate_control_chooses_the_residual_where_it_wins(clip):
    from lfstream.codec.rate import choose_configuration

    frames = clip[:1]
    target = 0.6  # far above what the prediction alone can use on this noisy scene
    choice = choose_configuration(frames, target, 30.0, preset="balanced")
    with_res = [c for c in choice.candidates if c["residual"] is not None]
    without = [c for c in choice.candidates if c["residual"] is None]
    assert with_res, choice.candidates
    assert choice.residual is not None
    assert abs(choice.bpp - target) / target <= 0.15
    assert choice.mpsnr_first_frame > max(c["mpsnr_first_frame"] for c in without) + 1.0
    data = choice.stream()
    assert bpp(len(data), frames.shape) == pytest.approx(choice.bpp)
    assert mpsnr(decode(data)[0], frames[0]) == pytest.approx(choice.mpsnr_first_frame, abs=1e-6)


def test_cli_encode_residual(tmp_path, clip, capsys):
    src = tmp_path / "clip.npy"
    np.save(src, clip)
    out = tmp_path / "clip.lfs"
    assert main(["encode", str(src), "-o", str(out), "--residual", "40", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["residual"] == 40 and report["residual_bpp"] > 0 and out.read_bytes()[4] == VERSION_RESIDUAL
    assert main(["encode", str(src), "-o", str(tmp_path / "x.lfs"), "--residual", "40", "--bpp", "0.1"]) == 2
    assert "residual" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:  # argparse's range check: one line, status 2
        main(["encode", str(src), "-o", str(tmp_path / "y.lfs"), "--residual", "0"])
    assert info.value.code == 2
