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
    VERSION,
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
    assert coded[4] == plain[4] == VERSION  # one format, with a residual layer or without
    out, base = decode(coded), decode(plain)
    gain = mpsnr(out[0], clip[0]) - mpsnr(base[0], clip[0])
    # measured 1.52 dB before the warp skipped the splat where it cannot matter, 1.46 dB after
    # (the prediction moved by a fraction of a level, so the AV1 residual codes differently;
    # noise 3: the prediction alone cannot carry it); without the layer the gain is 0
    assert gain > 1.0, gain
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


def test_residual_packets_round_trip_and_are_checked():
    header = StreamHeader(views=(3, 3), size=(16, 16), has_hint=False, has_residual=True)
    assert header.version == VERSION
    packets = [Packet(seq=k, timestamp_us=k, image=b"i" * 5, residual=b"r" * (k + 1)) for k in range(3)]
    data = pack_header(header) + b"".join(pack_packet(p, header.version) for p in packets)
    back, got = split_stream(data)
    assert back == header and got == packets
    with pytest.raises(LFValueError, match="format version 4"):
        pack_packet(packets[0], 3)  # the development builds' versions are not written
    # a residual layer in a stream whose header has none is damage
    plain = StreamHeader(views=(3, 3), size=(16, 16))
    with pytest.raises(BitstreamError, match="frame 0: a residual layer of 1 bytes in a stream whose header has none"):
        split_stream(pack_header(plain) + pack_packet(packets[0]))
    # a development build's stream (versions 1-3) is refused with one line that says so
    import zlib

    for version in (1, 2, 3):
        bad = bytearray(pack_header(plain))
        struct.pack_into("<H", bad, 4, version)
        bad[-4:] = struct.pack("<I", zlib.crc32(bytes(bad[:-4])))
        with pytest.raises(BitstreamError, match=f"format version {version}, made by an older lfstream; re-encode it"):
            read_header(__import__("io").BytesIO(bytes(bad)))


@pytest.mark.parametrize("mode", ["prediction", "views", "half-views"])
def test_damaged_residual_payloads_name_the_frame(clip, coded, mode):
    if mode != "prediction":
        coded = encode(clip[:1], quality=60, preset="balanced", residual=60, residual_mode=mode)
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
    assert report["residual"] == 40 and report["residual_bpp"] > 0 and out.read_bytes()[4] == VERSION
    assert main(["encode", str(src), "-o", str(tmp_path / "x.lfs"), "--residual", "40", "--bpp", "0.1"]) == 2
    assert "residual" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:  # argparse's range check: one line, status 2
        main(["encode", str(src), "-o", str(tmp_path / "y.lfs"), "--residual", "0"])
    assert info.value.code == 2


@pytest.mark.parametrize("quality,fmt_name", [(60, "VIEWS_KEYED_FORMAT"), (70, "VIEWS_FORMAT")])
def test_views_residual_carries_the_views_themselves(clip, quality, fmt_name):
    from lfstream.codec import residual as residual_module
    from lfstream.codec.centre import decode_centre
    from lfstream.codec.residual import residual_mode

    # one quality for the centre and the views: the centre is the sequence's key frame
    # (format 4); another centre quality: the centre coded apart (format 2)
    fmt = getattr(residual_module, fmt_name)
    lf = clip[:1]
    data = encode(lf, quality=quality, preset="balanced", residual=60, residual_mode="views")
    header, packets = split_stream(data)
    assert header.version == VERSION and header.meta["residual"]["mode"] == "views"
    p = packets[0]
    assert p.gain == b"" and p.residual[0] == fmt and residual_mode(p.residual) == "views"
    # prediction streams keep their header bytes: no "mode" key
    assert "mode" not in split_stream(encode(lf, quality=60, preset="balanced", residual=60))[0].meta["residual"]
    out = decode(data)[0]
    np.testing.assert_array_equal(out[2, 2], decode_centre(p.image, header.codec, header.size, 0))
    images = residual_images(p.residual, header.views, header.size, centre=p.image)
    for (a, b), img in zip(residual_views(header.views), images):
        diff = np.abs(out[a, b].astype(int) - img)
        assert diff.max() <= 2 and diff.mean() < 0.25, ((a, b), diff.max(), diff.mean())  # the fused kernel's rounding
    # the views replace whatever the decoder would predict: any depth mode, the same frame
    for depth in ("flat", "hint"):
        dec = Decoder(header, depth=depth)
        np.testing.assert_array_equal(dec.decode_packet(p).lf, out)
        assert dec.residual_skipped == 0
    assert encode(lf, quality=quality, preset="balanced", residual=60, residual_mode="views") == data  # deterministic
    if fmt == residual_module.VIEWS_FORMAT:
        return
    # a keyed sequence needs its centre: without it (or with another key frame) one clear error
    with pytest.raises(BitstreamError, match="frame 0: .*no AV1 centre view"):
        residual_images(p.residual, header.views, header.size, frame=0)
    other = split_stream(encode(lf, quality=30, preset="balanced", residual=30, residual_mode="views"))[1][0]
    with pytest.raises(BitstreamError, match="frame 0"):
        residual_images(p.residual, header.views, header.size, frame=0, centre=other.image + b"\0")


def test_keyed_views_sequence_costs_one_intra_frame():
    from lfstream.codec.centre.av1 import decode_av1, encode_av1
    from lfstream.codec.residual import VIEWS_KEYED_FORMAT, encode_residual, encode_views_keyed
    from lfstream.metrics import psnr

    lf = synth_clip(1, 5, (64, 96), seed=3).lf[0]
    centre, body = encode_views_keyed(lf, 40, 12)
    assert body[0] == VIEWS_KEYED_FORMAT
    alone = encode_av1(lf[2, 2], 40, 12)
    apart = len(alone) + len(encode_residual(lf, None, 40, 12))
    # measured 1-4 % smaller on toys_array at preset 8; on this small clip, where the second
    # key frame is a larger share of the whole, 3859 against 4570 bytes
    assert len(centre) + len(body) < 0.92 * apart, (len(centre) + len(body), apart)
    # the centre payload is an AV1 key frame that decodes alone, no worse than the centre
    # coded apart (measured 26.27 against 25.64 dB: the sequence's key frame gets more bits)
    assert psnr(decode_av1(centre, (64, 96)), lf[2, 2]) > psnr(decode_av1(alone, (64, 96)), lf[2, 2]) - 0.3
    # the views modes' slowest preset (VIEWS_SPEED with best) is deterministic too
    from lfstream.codec.encoder import VIEWS_SPEED

    assert encode_views_keyed(lf, 40, VIEWS_SPEED["best"]) == encode_views_keyed(lf, 40, VIEWS_SPEED["best"])


def test_views_residual_beats_the_prediction_where_no_warp_predicts(unpredictable):
    lf = unpredictable
    views = encode(lf, quality=40, preset="best", residual=40, residual_mode="views")
    pred = encode(lf, quality=40, preset="best", residual=40)
    q_views, q_pred = mpsnr(decode(views)[0], lf), mpsnr(decode(pred)[0], lf)
    # measured: 5.0 KB at 33.0 dB against 17.0 KB at 26.0 dB
    assert len(views) < len(pred) and q_views > q_pred - 0.3, (len(views), len(pred), q_views, q_pred)


def test_rate_control_codes_the_views_where_that_wins(unpredictable):
    from lfstream.codec.rate import choose_configuration

    frames = unpredictable[None]
    target = 0.3
    choice = choose_configuration(frames, target, 30.0)
    assert choice.residual_mode == "views" and choice.residual == choice.quality and not choice.depth_hint
    others = [c for c in choice.candidates if c["residual_mode"] != "views" and abs(c["bpp"] - target) <= 0.15 * target]
    # measured: 34.6 dB against the best prediction candidate's 24.4
    assert others and choice.mpsnr_first_frame > max(c["mpsnr_first_frame"] for c in others) + 1.0, choice.candidates
    assert abs(choice.bpp - target) / target <= 0.15
    assert mpsnr(decode(choice.stream())[0], frames[0]) == pytest.approx(choice.mpsnr_first_frame, abs=1e-6)
    assert all(not p.hint for p in choice.packets)
    # the centre is the views sequence's key frame (one intra frame), at the views' preset
    from lfstream.codec.encoder import VIEWS_SPEED
    from lfstream.codec.residual import VIEWS_KEYED_FORMAT

    assert choice.packets[0].residual[0] == VIEWS_KEYED_FORMAT
    assert choice.header.meta["residual"]["svt_preset"] == choice.header.meta["centre"]["svt_preset"] == VIEWS_SPEED["best"]
    # a stream fits its focal planes to the hint: there the views candidate carries one
    from lfstream.codec.rate.search import _views_candidate

    q, header, packets = _views_candidate(frames, None, "best", 30.0, target * frames[0].size / 3 / 8, hint=True)
    assert header.has_hint and packets[0].hint and 1 <= q <= choice.quality
    # where views are missing, rate control does not offer it (a prediction reconstructs them)
    present = np.ones(frames.shape[1:3], bool)
    present[0, 0] = False
    assert all(c["residual_mode"] != "views" for c in
               choose_configuration(frames, target, 30.0, present, preset="best").candidates)


def test_residual_mode_is_checked(clip, tmp_path, capsys):
    from lfstream.stream import StreamConfig

    with pytest.raises(LFValueError, match="residual_mode"):
        encode(clip[:1], residual=50, residual_mode="corners")
    with pytest.raises(LFValueError, match="residual quality"):
        encode(clip[:1], residual_mode="views")
    with pytest.raises(LFValueError, match="rate control"):
        encode(clip[:1], bpp=0.1, residual_mode="views")
    with pytest.raises(LFValueError, match="residual_mode"):
        StreamConfig(residual_mode="views").validate()
    present = np.ones(clip.shape[1:3], bool)
    present[0, 1] = False
    with pytest.raises(LFValueError, match="frame 0: residual_mode 'views' codes every view and 1 are missing"):
        encode(clip[:1], residual=50, residual_mode="views", present=present)
    src = tmp_path / "clip.npy"
    np.save(src, clip[:1])
    assert main(["encode", str(src), "-o", str(tmp_path / "a.lfs"), "--residual-mode", "views"]) == 2
    assert "--residual-mode" in capsys.readouterr().err and not (tmp_path / "a.lfs").exists()
    assert main(["encode", str(src), "-o", str(tmp_path / "b.lfs"), "--residual", "30", "--residual-mode", "views",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["residual_mode"] == "views" and report["residual"] == 30


def test_half_views_code_the_views_at_half_size(unpredictable):
    from lfstream.codec.residual import HALF_VIEWS_FORMAT, coded_size

    lf = unpredictable
    full = encode(lf, quality=30, preset="best", residual=30, residual_mode="views")
    half = encode(lf, quality=30, preset="best", residual=30, residual_mode="half-views")
    header, packets = split_stream(half)
    assert packets[0].residual[0] == HALF_VIEWS_FORMAT and header.meta["residual"]["mode"] == "half-views"
    assert coded_size((63, 95), "half-views") == (32, 48) and coded_size((63, 95), "views") == (63, 95)
    images = residual_images(packets[0].residual, header.views, header.size)
    assert all(img.shape == (32, 48, 3) for img in images)
    out, out_full = decode(half)[0], decode(full)[0]
    # fewer bits, a blurrier but faithful frame (measured 2.7 KB at 24.7 dB, full size 4.1 KB at
    # 30.7; the flat prediction of this scene is ~17 dB)
    assert len(half) < 0.8 * len(full)
    assert max(mpsnr(out_full, lf) - 9.0, 20.0) < mpsnr(out, lf) < mpsnr(out_full, lf)
    with pytest.raises(LFValueError, match="half size"):
        encode_residual(lf, lf, 30, half=True)


def test_threaded_residual_decode_matches_one_thread(monkeypatch):
    """dav1d's worker threads (frame threading across the views) give the single-threaded
    decode's planes to the bit, keyed and not, and a payload damaged in its last packets is
    decoded or refused, never left pending (the decoder drained before it is freed)."""
    from lfstream.codec import residual as res

    lf8 = synth_clip(1, 5, (64, 96), seed=5, noise=2.0).lf[0]
    plain = encode_residual(lf8, None, 40, 12)
    centre, keyed = res.encode_views_keyed(lf8, 40, 12)
    monkeypatch.setattr(res, "_DECODER_THREADS", 1)
    ref_plain = res.decode_residual(plain, (5, 5), (64, 96))
    ref_keyed = res.decode_residual(keyed, (5, 5), (64, 96), centre=centre)
    monkeypatch.setattr(res, "_DECODER_THREADS", 4)
    monkeypatch.setattr(res, "_THREADED_MIN_BYTES", 0)  # these small payloads too
    assert res._decoder_threads(res.VIEWS_FORMAT, len(plain)) == 4
    np.testing.assert_array_equal(res.decode_residual(plain, (5, 5), (64, 96)), ref_plain)
    np.testing.assert_array_equal(res.decode_residual(keyed, (5, 5), (64, 96), centre=centre), ref_keyed)
    rng = np.random.default_rng(3)
    for _ in range(30):
        buf = bytearray(plain)
        for i in rng.integers(len(buf) * 3 // 4, len(buf), 3):
            buf[i] ^= 1 << int(rng.integers(0, 8))
        try:
            out = res.decode_residual(bytes(buf), (5, 5), (64, 96), frame=4)
            assert out.shape == ref_plain.shape
        except BitstreamError as exc:
            assert "frame 4" in str(exc)


def test_residual_streams_decode_the_same_from_the_worker_threads(coded):
    """The decoder decodes a packet's residual on a worker thread beside the warp; called
    from those workers themselves (both busy at once) it decodes inline instead of waiting
    on their queue, and every result is the same."""
    from lfstream.codec.workers import in_background, on_worker_thread

    expected = decode(coded)
    jobs = [in_background(lambda: (on_worker_thread(), decode(coded))) for _ in range(4)]
    for job in jobs:
        on_worker, out = job.result(timeout=60)
        assert on_worker and np.array_equal(out, expected)
    assert not on_worker_thread()


@pytest.mark.parametrize("size", [(64, 96), (34, 50), (120, 540)])
def test_decoded_planes_are_copied_as_pyav_lays_them_out(size):
    """The residual's planes are copied out of each decoded frame plane by plane (rows padded
    to the decoder's line size); they equal PyAV's ``to_ndarray`` to the bit, sizes whose
    chroma rows are padded included."""
    import av

    from lfstream.codec.residual import _copy_i420

    h, w = size
    planes = np.random.default_rng(h * w).integers(0, 256, (h * 3 // 2, w), dtype=np.uint8)
    frame = av.VideoFrame.from_ndarray(planes, format="yuv420p")
    out = np.zeros_like(planes)
    _copy_i420(frame, out)
    np.testing.assert_array_equal(out, frame.to_ndarray(format="yuv420p"))
    np.testing.assert_array_equal(out, planes)


def test_residual_decoder_threads_follow_the_payload():
    """dav1d's worker threads only where they pay: never for a prediction's residual (it
    decodes beside the warp), for the views only from _THREADED_MIN_BYTES bytes."""
    from lfstream.codec import residual as res

    at = res._THREADED_MIN_BYTES
    assert res._decoder_threads(res.RESIDUAL_FORMAT, 10 * at) == 1
    for fmt in (res.VIEWS_FORMAT, res.HALF_VIEWS_FORMAT, res.VIEWS_KEYED_FORMAT):
        assert res._decoder_threads(fmt, at - 1) == 1
        assert res._decoder_threads(fmt, at) == res._DECODER_THREADS


def test_the_warp_leaves_a_long_residual_decode_a_core(coded, monkeypatch):
    """The decoder hands the warp its residual's decoding (``beside``) where the residual
    holds at least BESIDE_MIN_BITS bits a pixel, and not below; the frames are the same."""
    from lfstream.codec import decoder as decoder_module

    header, packets = split_stream(coded)
    seen = []
    warp = decoder_module.warp_views

    def spy(*args, beside=None, **kwargs):
        seen.append(beside is not None)
        return warp(*args, beside=beside, **kwargs)

    monkeypatch.setattr(decoder_module, "warp_views", spy)
    outs = []
    for bits in (0.0, float("inf")):
        monkeypatch.setattr(decoder_module, "BESIDE_MIN_BITS", bits)
        outs.append(Decoder(header).decode_packet(packets[0]).lf)
    assert seen == [True, False]
    np.testing.assert_array_equal(outs[0], outs[1])


def test_a_residual_stream_decodes_into_the_video_array_as_frame_by_frame(coded):
    """``decode`` writes each frame's prediction into its video array and adds the residual
    there: the same bytes as the frames decoded one by one."""
    import io

    from lfstream.codec.api import iter_decode

    apart = [f.lf for f in iter_decode(io.BytesIO(coded))]
    np.testing.assert_array_equal(decode(coded), np.stack(apart))


@pytest.mark.parametrize("speed", [11, 12, 13])
def test_the_fastest_presets_at_quality_100_write_sequences_that_decode(speed):
    """SVT-AV1 presets 11-13 at CRF 1-4 wrote sequences of real views that dav1d refused
    (seahorse's views, keyed views and prediction residuals at qualities 95-100): those
    presets' lowest CRF is raised (lfstream.codec.centre.av1.svt_crf)."""
    import lfstream
    from lfstream.codec.centre.av1 import SVT_FAST_MIN_CRF, svt_crf
    from lfstream.codec.residual import decode_residual, encode_residual, encode_views_keyed
    from tests.conftest import shared

    lf = np.ascontiguousarray(lfstream.read_lf(shared("seahorse5x5", "camImagesFlat"))[1:4, 1:4])
    prediction = np.ascontiguousarray(np.repeat(np.repeat(lf[1:2, 1:2], 3, 0), 3, 1))
    for q in (95, 98, 100):
        for residual in (encode_residual(lf, None, q, speed), encode_residual(lf, prediction, q, speed)):
            assert decode_residual(residual, (3, 3), lf.shape[2:4]).shape[0] == 8
        key, rest = encode_views_keyed(lf, q, speed)
        assert decode_residual(rest, (3, 3), lf.shape[2:4], centre=key).shape[0] == 8
    assert svt_crf(100, speed) == SVT_FAST_MIN_CRF and svt_crf(100, 10) == 1 and svt_crf(50, speed) == svt_crf(50, 4)
