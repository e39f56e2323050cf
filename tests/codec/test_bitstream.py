"""The .lfs bitstream: round trips, limits, damage handling and a fuzz run."""

import io
import json
import struct
import zlib

import numpy as np
import pytest

from lfstream.codec import decode, encode
from lfstream.codec.bitstream import (
    Limits,
    Packet,
    StreamHeader,
    iter_packets,
    pack_header,
    pack_packet,
    read_header,
    split_stream,
)
from lfstream.errors import BitstreamError, LFStreamError
from lfstream.synth import synth_clip


@pytest.fixture(scope="module")
def clip():
    return synth_clip(4, 5, (40, 48), seed=5).lf


@pytest.fixture(scope="module")
def stream(clip):
    # the JPEG stream (version 1): named, since the default codes a 5x5 grid's centre as AV1
    return encode(clip, quality=60, preset="fast")


def test_header_and_packets_round_trip():
    header = StreamHeader(views=(7, 5), size=(375, 540), fps=29.97, quality=42, has_hint=True, meta={"a": 1})
    data = pack_header(header)
    packets = [Packet(seq=k, timestamp_us=33366 * k, image=bytes([k + 1]) * (10 + k), hint=b"h" * k) for k in range(3)]
    data += b"".join(pack_packet(p) for p in packets)
    back, got = split_stream(data)
    assert back == header and got == packets


def test_encode_is_deterministic_and_decodes(clip, stream):
    assert encode(clip, quality=60, preset="fast") == stream
    out = decode(stream)
    assert out.shape == clip.shape and out.dtype == np.uint8
    # the hint is on by default: the corner views differ from the centre view ...
    assert not (out[:, 0, 0] == out[:, 2, 2]).all()
    # ... and with flat disparity every view is the decoded centre view
    flat = decode(stream, depth="flat")
    assert (flat[:, 0, 0] == flat[:, 2, 2]).all() and (flat[:, 2, 2] == out[:, 2, 2]).all()
    # the centre view is exactly the JPEG (q60) of the input's centre view, post-filtered
    # with the filter the encoder named in it
    from lfstream.codec import decode_jpeg, encode_jpeg
    from lfstream.codec.centre.jpeg import PostFilterChoice, post_filter_jpeg, with_post_filter

    for t, packet in enumerate(split_stream(stream)[1]):
        assert with_post_filter(packet.image, PostFilterChoice()) == encode_jpeg(clip[t, 2, 2], 60)
        np.testing.assert_array_equal(out[t, 2, 2], post_filter_jpeg(decode_jpeg(packet.image, (40, 48)), packet.image))


def test_truncated_stream_yields_complete_frames(stream, clip):
    header, packets = split_stream(stream)
    cut = len(stream) - packets[-1].nbytes // 2  # inside the last packet
    fh = io.BytesIO(stream[:cut])
    h = read_header(fh)
    got = []
    with pytest.raises(BitstreamError) as info:
        for p in iter_packets(fh, h):
            got.append(p)
    assert [p.seq for p in got] == [0, 1, 2] and info.value.frame == 3 and "frame 3" in str(info.value)
    with pytest.raises(BitstreamError) as info:
        decode(stream[:cut])
    assert info.value.partial.shape == (3,) + clip.shape[1:]


def test_decode_fills_one_array_with_the_frames_it_gives_apart(stream, monkeypatch):
    """``decode`` writes each frame into one video array (no stack of separate frames):
    the same bytes as the frames decoded one by one, the frames contiguous in one buffer;
    where the counted frames would take too much memory it decodes them apart and stacks
    them, with the same bytes."""
    from lfstream.codec import api as decoder_module

    apart = np.stack([f.lf for f in decoder_module.iter_decode(io.BytesIO(stream))])
    whole = decode(stream)
    np.testing.assert_array_equal(whole, apart)
    assert whole.flags.c_contiguous and whole.base is not None  # the counted array itself, not a stack
    stacked = []
    monkeypatch.setattr(decoder_module, "stack_frames", lambda frames: stacked.append(len(frames)) or np.stack(frames))
    decode(stream)
    assert stacked == []
    monkeypatch.setattr(decoder_module, "VIDEO_ARRAY_MEMORY_SHARE", 0.0)
    np.testing.assert_array_equal(decode(stream), apart)
    assert stacked == [len(apart)]


def test_decode_file_is_decode_of_its_bytes(stream, tmp_path):
    """``decode_file`` gives ``decode``'s frames and the stream's frame rate, at most
    ``max_frames`` of them, and names the file where the stream is damaged."""
    from lfstream.codec import decode_file

    path = tmp_path / "clip.lfs"
    path.write_bytes(stream)
    lf, fps = decode_file(path)
    np.testing.assert_array_equal(lf, decode(stream))
    assert fps == split_stream(stream)[0].fps
    np.testing.assert_array_equal(decode_file(path, max_frames=2)[0], lf[:2])
    cut = tmp_path / "cut.lfs"
    cut.write_bytes(stream[:-7])
    with pytest.raises(BitstreamError, match="cut.lfs"):
        decode_file(cut)


def test_a_damaged_packet_after_the_count_leaves_the_frames_before_it(stream, clip):
    """A packet whose checksum holds but whose picture does not decode: counted, then the
    decode stops there; the frames before it are the partial result."""
    from lfstream.codec.bitstream import pack_packet

    header, packets = split_stream(stream)
    bad = Packet(seq=2, timestamp_us=packets[2].timestamp_us, image=b"\xff\xd8 not a jpeg", hint=packets[2].hint,
                 gain=packets[2].gain, meta=packets[2].meta)
    data = pack_header(header) + b"".join(pack_packet(p, header.version) for p in [*packets[:2], bad, packets[3]])
    with pytest.raises(LFStreamError) as info:
        decode(data)
    np.testing.assert_array_equal(info.value.partial, decode(stream)[:2])


def test_hostile_lengths_fail_before_allocating(stream):
    header_len = len(pack_header(split_stream(stream)[0]))
    data = bytearray(stream)
    # absurd image length in the first packet, CRC not even reached
    struct.pack_into("<I", data, header_len + 4 + 4 + 8, 0xFFFFFFF0)  # image_len
    with pytest.raises(BitstreamError, match="image length"):
        decode(bytes(data))
    # a header promising a 64x64 grid of 16384^2 views is refused by the frame-size limit
    huge = bytearray(pack_header(StreamHeader(views=(4, 4), size=(64, 64))))
    struct.pack_into("<BBHH", huge, 8, 64, 64, 16384, 16384)
    huge[-4:] = struct.pack("<I", zlib.crc32(bytes(huge[:-4])))
    with pytest.raises(BitstreamError, match="exceeds the limit"):
        read_header(io.BytesIO(bytes(huge)))
    with pytest.raises(BitstreamError, match="limit"):
        read_header(io.BytesIO(pack_header(StreamHeader(views=(8, 8), size=(64, 64)))), Limits(max_frame_bytes=1000))


def test_bad_streams_name_the_problem(stream):
    cases = {
        "empty": b"",
        "magic": b"GIF89a" + stream[6:],
        "header crc": stream[:10] + bytes([stream[10] ^ 1]) + stream[11:],
        "garbage after": stream + b"\x00garbage",
        "no frames": stream[: len(pack_header(split_stream(stream)[0]))],
        "not bytes": "a string",
    }
    for _what, data in cases.items():
        with pytest.raises(LFStreamError):
            decode(data)  # type: ignore[arg-type]


def test_reordered_packets_are_detected(stream):
    header, packets = split_stream(stream)
    swapped = pack_header(header) + pack_packet(packets[1]) + pack_packet(packets[0])
    with pytest.raises(BitstreamError, match="sequence"):
        decode(swapped)


def test_fuzz_mutations_never_crash_or_hang(stream):
    """Bit flips, truncations, absurd lengths and appended garbage (300 cases here; a long
    run is tools/fuzz_bitstream.py): every outcome is a decoded stream of the right shape or
    an LFStreamError - never another exception."""
    from tools.fuzz_bitstream import fuzz

    hinted = encode(synth_clip(2, 3, (32, 32), seed=2, vignetting=0.6).lf, depth_hint=True)
    av1 = encode(synth_clip(2, 3, (32, 32), seed=3).lf, preset="balanced")  # version 2: an AV1 centre view
    residual = encode(synth_clip(1, 3, (32, 32), seed=4).lf, residual=50)  # version 3: a residual layer
    # the views as one AV1 sequence keyed by the centre payload (residual format 4)
    keyed = encode(synth_clip(1, 3, (32, 32), seed=5).lf, preset="balanced", quality=50, residual=50,
                   residual_mode="views")
    counts = fuzz([stream, hinted, av1, residual, keyed], 300, seed=2024)
    assert counts["decoded"] + counts["rejected"] == 300 and counts["rejected"] > 200  # CRCs catch nearly all


def test_zstd_payloads_are_bounded_by_what_they_declare():
    import zstandard

    from lfstream.codec.bitstream import decompress_bounded

    data = zstandard.ZstdCompressor(level=3).compress(bytes(4096))
    assert decompress_bounded(data, 4096) == bytes(4096)
    with pytest.raises(zstandard.ZstdError, match="declares 4096 bytes"):
        decompress_bounded(data, 4095)
    with pytest.raises(zstandard.ZstdError):
        decompress_bounded(b"not zstd at all", 100)


def test_header_metadata_is_coded_with_the_dictionary_and_plain_zstd_still_reads():
    """The header's JSON metadata goes out with the built-in zstd dictionary (a few dozen
    bytes instead of ~200); a header written before it (meta_coding 0, plain zstd) reads the
    same; an unknown coding is refused."""
    import zstandard

    from lfstream.codec.bitstream import _HEADER_FIXED, META_PLAIN, META_WITH_DICTIONARY, pack_header, read_header

    meta = {"encoder": "lfstream-jpeg-centre", "gain_grid": 4, "quality": 37, "version": "0.1.0",
            "hint": {"box_radius": 2, "hint_scale": 4, "max_disparity": None, "median": 3, "precision": 0.2,
                     "step": 0.25, "work_scale": 2}}
    header = StreamHeader(views=(7, 7), size=(375, 540), quality=37, has_hint=True, meta=meta)
    data = pack_header(header)
    fields = list(_HEADER_FIXED.unpack_from(data))
    assert fields[10] == META_WITH_DICTIONARY and fields[11] < 60  # measured 21 bytes; plain zstd 168
    assert read_header(io.BytesIO(data)).meta == meta
    plain = zstandard.ZstdCompressor(level=10).compress(json.dumps(meta, sort_keys=True).encode())
    assert len(plain) > 2 * fields[11]
    fields[10], fields[11] = META_PLAIN, len(plain)
    body = _HEADER_FIXED.pack(*fields) + plain
    old = body + struct.pack("<I", zlib.crc32(body))
    assert read_header(io.BytesIO(old)).meta == meta
    fields[10] = 7
    body = _HEADER_FIXED.pack(*fields) + plain
    with pytest.raises(BitstreamError, match="unknown metadata coding 7"):
        read_header(io.BytesIO(body + struct.pack("<I", zlib.crc32(body))))
