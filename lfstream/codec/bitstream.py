"""The ``.lfs`` bitstream: a file header, then one packet per light-field frame.

One format, version 4 (all integers little-endian). Streams of the versions before it (1 to
3, made by development builds of lfstream) are refused with one line that says so: re-encode
them.

File header::

    magic        4 bytes  b"\\x89LFS"
    version      u16      4
    flags        u16      bit 0: packets may carry a depth hint; bit 1: a residual layer
    views        u8, u8   U, V
    size         u16, u16 H, W
    fps_milli    u32      frame rate x 1000
    codec        u8       centre view: 1 = JPEG, 2 = AV1 key frame
    quality      u8       centre-view quality 1..100 (JPEG quality; AV1: CRF 63..1)
    meta_coding  u16      0: zstd; 1: zstd with the built-in dictionary (:data:`META_DICTIONARY`)
    meta_len     u32      length of the metadata block
    meta         bytes    zstd-compressed UTF-8 JSON (encoder name, version, options)
    header_crc   u32      CRC32 of every byte above

Packet (the unit every transport carries)::

    sync         4 bytes  b"LFPK"
    seq          u32      frame sequence number, from 0
    timestamp_us u64      presentation time in microseconds
    image_len    u32      length of the coded centre view
    hint_len     u32      length of the depth hint (0: none)
    gain_len     u32      length of the per-view gain maps (0: none)
    meta_len     u32      length of the per-frame metadata (0: none)
    residual_len u32      length of the residual layer (0: none; always 0 without the header's flag)
    image        bytes
    hint         bytes    zstd-compressed quantised disparity (see :mod:`lfstream.codec.hint`)
    gain         bytes    per-view brightness gains (see :mod:`lfstream.codec.gains`)
    meta         bytes    zstd-compressed JSON
    residual     bytes    the residual views (see :mod:`lfstream.codec.residual`)
    crc          u32      CRC32 of the packet from ``sync`` to the end of the last payload

A parser checks every length and dimension against :class:`Limits` before it allocates
anything, checks CRCs, and names the frame in its errors. Reading a damaged file yields
every complete packet before the damage and then raises :class:`BitstreamError`.
"""

from __future__ import annotations

import io
import json
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import BinaryIO

import numpy as np
import zstandard

from lfstream.errors import BitstreamError, LFValueError
from lfstream.lightfield import MAX_VIEW_SIDE, MAX_VIEWS_PER_AXIS

MAGIC = b"\x89LFS"
SYNC = b"LFPK"
#: The one format version this module reads and writes.
VERSION = 4
#: Versions written by development builds before it: refused with a line that says so.
OLDER_VERSIONS = (1, 2, 3)
CODEC_JPEG = 1
CODEC_AV1 = 2
CODEC_NAMES = {CODEC_JPEG: "jpeg", CODEC_AV1: "av1"}
FLAG_HINT = 1
FLAG_RESIDUAL = 2

_HEADER_FIXED = struct.Struct("<4sHHBBHHIBBHI")  # up to and including meta_len
_PACKET_FIXED = struct.Struct("<4sIQIIIII")  # up to and including residual_len
_CRC = struct.Struct("<I")


@dataclass(frozen=True)
class Limits:
    """Upper bounds a parser enforces before allocating; raise them deliberately for huge LFs."""

    max_views_per_axis: int = MAX_VIEWS_PER_AXIS
    max_view_side: int = MAX_VIEW_SIDE
    max_frame_bytes: int = 2 << 30  # decoded U*V*H*W*3
    max_meta_bytes: int = 1 << 20
    max_payload_factor: float = 4.0  # image/hint payload <= factor * H * W * 3 + 1 MiB


@dataclass(frozen=True)
class StreamHeader:
    """Stream-wide parameters."""

    views: tuple[int, int]
    size: tuple[int, int]
    fps: float = 30.0
    quality: int = 50
    has_hint: bool = False
    codec: int = CODEC_JPEG
    meta: dict = field(default_factory=dict)
    has_residual: bool = False

    @property
    def version(self) -> int:
        """The stream's format version (:data:`VERSION`)."""
        return VERSION

    def max_payload(self, limits: Limits) -> int:
        h, w = self.size
        return int(limits.max_payload_factor * h * w * 3) + (1 << 20)

    def max_residual(self, limits: Limits) -> int:
        """A residual codes every view but the centre: its bound scales with the views."""
        u, v = self.views
        return min(int(limits.max_payload_factor * u * v * self.size[0] * self.size[1] * 3),
                   limits.max_frame_bytes) + (1 << 20)


def with_present(header: StreamHeader, present: np.ndarray | None) -> StreamHeader:
    """``header`` recording which views existed in the source (``meta["present"]``: rows of
    0/1), where some were missing; unchanged where all were (or no mask is given)."""
    if present is None:
        return header
    mask = np.asarray(present, bool)
    if mask.shape != tuple(header.views):
        raise LFValueError(f"present: expected a {header.views[0]}x{header.views[1]} mask, got {mask.shape}")
    if mask.all():
        return header
    return replace(header, meta={**header.meta, "present": mask.astype(int).tolist()})


def header_present(header: StreamHeader) -> np.ndarray | None:
    """The ``(U, V)`` mask of views the source had (:func:`with_present`); ``None``: all."""
    rows = header.meta.get("present")
    if rows is None:
        return None
    try:
        mask = np.asarray(rows, bool)
    except (TypeError, ValueError):
        mask = None
    if mask is None or mask.shape != tuple(header.views) or not mask[header.views[0] // 2, header.views[1] // 2]:
        raise BitstreamError("header: a malformed present-view mask")
    return mask


@dataclass(frozen=True)
class Packet:
    """One encoded frame."""

    seq: int
    timestamp_us: int
    image: bytes
    hint: bytes = b""
    gain: bytes = b""
    meta: bytes = b""
    residual: bytes = b""

    def size(self, version: int = VERSION) -> int:
        """Bytes this packet takes in a stream (of ``version``: the one there is)."""
        _check_version(version)
        return (_PACKET_FIXED.size + len(self.image) + len(self.hint) + len(self.gain) + len(self.meta)
                + len(self.residual) + _CRC.size)

    @property
    def nbytes(self) -> int:
        """Bytes this packet takes in a stream."""
        return self.size()


def _check_version(version: int) -> None:
    if version != VERSION:
        raise LFValueError(f"version: lfstream writes format version {VERSION}, got {version!r}")


def stream_version(codec: int, residual: bool = False) -> int:
    """The format version of a stream whose centre view is coded by ``codec`` (with or
    without a residual layer): :data:`VERSION`, once the codec is known."""
    if codec not in CODEC_NAMES:
        raise BitstreamError(f"header: unknown codec id {codec}")
    return VERSION


#: The header's metadata is a few hundred bytes of JSON that zstd alone barely shrinks
#: (215 -> 170 bytes): a fixed dictionary of what encoders write (raw content, never to
#: change: streams refer to it by ``meta_coding`` 1) codes it in 15-60, which matters for a
#: single-frame light field at a low rate (seahorse at quality 10: 1783 bytes in all).
META_DICTIONARY = zstandard.ZstdCompressionDict(b"".join([
    b'{"encoder": "lfstream-jpeg-centre", "gain_grid": 4, "quality": 50, "version": "0.1.0"}',
    b'{"encoder": "lfstream-jpeg-centre", "gain_grid": 4, "hint": {"box_radius": 2, "hint_scale": 4, '
    b'"max_disparity": null, "median": 3, "precision": 0.2, "step": 0.25, "work_scale": 2}, "quality": 50, '
    b'"residual": {"codec": "av1", "quality": 50, "svt_preset": 12}, "version": "0.1.0"}',
    b'{"centre": {"codec": "av1", "crf": 40, "quality": 38, "svt_preset": 4}, "encoder": "lfstream-jpeg-centre", '
    b'"gain_grid": 4, "preset": "best", "quality": 38, "residual": {"codec": "av1", "mode": "views", "quality": 38, '
    b'"svt_preset": 4}, "version": "0.1.0"}',
    b'{"centre": {"codec": "av1", "crf": 32, "quality": 50, "svt_preset": 8}, "encoder": "lfstream-jpeg-centre", '
    b'"gain_grid": 4, "hint": {"box_radius": 2, "hint_scale": 8, "max_disparity": null, "median": 3, '
    b'"precision": 0.2, "step": 0.25, "work_scale": 2}, "preset": "balanced", "quality": 50, "version": "0.1.0"}',
]), dict_type=zstandard.DICT_TYPE_RAWCONTENT)
META_PLAIN, META_WITH_DICTIONARY = 0, 1


def _compress_json(obj: dict, dictionary: bool = False) -> bytes:
    if not obj:
        return b""
    # fixed level and sorted keys: the same input gives the same bytes
    options = {"dict_data": META_DICTIONARY, "write_dict_id": False} if dictionary else {}
    return zstandard.ZstdCompressor(level=10, **options).compress(json.dumps(obj, sort_keys=True).encode())


def decompress_bounded(data: bytes, limit: int, dictionary: zstandard.ZstdCompressionDict | None = None) -> bytes:
    """zstd-decompresses one frame of at most ``limit`` bytes.

    ``max_output_size`` alone does not bound it: python-zstandard allocates whatever
    content size the frame header declares (a damaged or hostile 2^60 is a MemoryError, a
    few GB an allocation), so the declared size is checked first.

    Raises:
        zstandard.ZstdError: a bad frame, or one that declares or yields more than ``limit``.
    """
    size = zstandard.get_frame_parameters(data).content_size
    if size not in (zstandard.CONTENTSIZE_UNKNOWN, zstandard.CONTENTSIZE_ERROR) and size > limit:
        raise zstandard.ZstdError(f"the frame declares {size} bytes, more than the {limit} expected")
    decompressor = zstandard.ZstdDecompressor(dict_data=dictionary) if dictionary is not None \
        else zstandard.ZstdDecompressor()
    return decompressor.decompress(data, max_output_size=limit)


def _decompress_json(data: bytes, limit: int, what: str, frame: int | None = None, dictionary: bool = False) -> dict:
    if not data:
        return {}
    try:
        raw = decompress_bounded(data, limit, META_DICTIONARY if dictionary else None)
        obj = json.loads(raw.decode("utf-8"))
    except (zstandard.ZstdError, UnicodeDecodeError, ValueError) as exc:
        raise BitstreamError(f"{what}: corrupt metadata ({exc})", frame) from exc
    if not isinstance(obj, dict):
        raise BitstreamError(f"{what}: metadata is not an object", frame)
    return obj


def check_header_values(header: StreamHeader, limits: Limits = Limits()) -> None:
    """Raises :class:`BitstreamError` if a header describes something the limits refuse."""
    u, v = header.views
    h, w = header.size
    if not (1 <= u <= limits.max_views_per_axis and 1 <= v <= limits.max_views_per_axis):
        raise BitstreamError(f"header: view grid {u}x{v} outside 1..{limits.max_views_per_axis}")
    if not (1 <= h <= limits.max_view_side and 1 <= w <= limits.max_view_side):
        raise BitstreamError(f"header: view size {h}x{w} outside 1..{limits.max_view_side}")
    if u * v * h * w * 3 > limits.max_frame_bytes:
        raise BitstreamError(f"header: a decoded frame of {u}x{v}x{h}x{w}x3 bytes exceeds the limit of {limits.max_frame_bytes}")
    if not (1 <= header.quality <= 100):
        raise BitstreamError(f"header: centre-view quality {header.quality} outside 1..100")
    stream_version(header.codec)  # raises for an unknown codec
    if not (0 < header.fps <= 10000):
        raise BitstreamError(f"header: frame rate {header.fps} outside (0, 10000]")


def pack_header(header: StreamHeader) -> bytes:
    check_header_values(header)
    meta = _compress_json(header.meta, dictionary=True)
    fixed = _HEADER_FIXED.pack(
        MAGIC, header.version, (FLAG_HINT if header.has_hint else 0) | (FLAG_RESIDUAL if header.has_residual else 0),
        header.views[0], header.views[1], header.size[0], header.size[1], int(round(header.fps * 1000)), header.codec,
        header.quality, META_WITH_DICTIONARY if meta else META_PLAIN, len(meta),
    )
    body = fixed + meta
    return body + _CRC.pack(zlib.crc32(body))


def pack_packet(packet: Packet, version: int = VERSION) -> bytes:
    """A packet's bytes in a stream (of ``version``: the one there is)."""
    _check_version(version)
    if packet.seq < 0 or packet.seq >= 1 << 32 or packet.timestamp_us < 0:
        raise LFValueError(f"packet: sequence number or timestamp out of range ({packet.seq}, {packet.timestamp_us})")
    lengths = (len(packet.image), len(packet.hint), len(packet.gain), len(packet.meta), len(packet.residual))
    fixed = _PACKET_FIXED.pack(SYNC, packet.seq, packet.timestamp_us, *lengths)
    body = fixed + packet.image + packet.hint + packet.gain + packet.meta + packet.residual
    return body + _CRC.pack(zlib.crc32(body))


def _read_exact(fh: BinaryIO, n: int) -> bytes:
    data = fh.read(n)
    return data if data is not None else b""


def read_header(fh: BinaryIO, limits: Limits = Limits()) -> StreamHeader:
    """Reads and validates the file header."""
    fixed = _read_exact(fh, _HEADER_FIXED.size)
    if len(fixed) < _HEADER_FIXED.size:
        raise BitstreamError(f"header: truncated ({len(fixed)} of {_HEADER_FIXED.size} bytes)")
    magic, version, flags, u, v, h, w, fps_milli, codec, quality, meta_coding, meta_len = _HEADER_FIXED.unpack(fixed)
    if magic != MAGIC:
        raise BitstreamError("header: not an lfstream .lfs stream (bad magic)")
    if version in OLDER_VERSIONS:
        raise BitstreamError(f"header: format version {version}, made by an older lfstream; re-encode it "
                             f"(this reader reads version {VERSION})")
    if version != VERSION:
        raise BitstreamError(f"header: unsupported format version {version} (this reader reads version {VERSION})")
    if codec not in CODEC_NAMES:
        raise BitstreamError(f"header: unknown codec id {codec}")
    if meta_len > limits.max_meta_bytes:
        raise BitstreamError(f"header: metadata length {meta_len} exceeds {limits.max_meta_bytes}")
    if meta_coding not in (META_PLAIN, META_WITH_DICTIONARY):
        raise BitstreamError(f"header: unknown metadata coding {meta_coding}")
    meta = _read_exact(fh, meta_len)
    crc = _read_exact(fh, _CRC.size)
    if len(meta) < meta_len or len(crc) < _CRC.size:
        raise BitstreamError("header: truncated")
    if _CRC.unpack(crc)[0] != zlib.crc32(fixed + meta):
        raise BitstreamError("header: CRC mismatch")
    header = StreamHeader(views=(u, v), size=(h, w), fps=fps_milli / 1000.0, quality=quality,
                          has_hint=bool(flags & FLAG_HINT), codec=codec, has_residual=bool(flags & FLAG_RESIDUAL),
                          meta=_decompress_json(meta, limits.max_meta_bytes, "header",
                                                dictionary=meta_coding == META_WITH_DICTIONARY))
    check_header_values(header, limits)
    header_present(header)  # a malformed mask fails here, with the header
    return header


def read_packet(fh: BinaryIO, header: StreamHeader, limits: Limits = Limits(), expect_seq: int | None = None) -> Packet | None:
    """Reads one packet; ``None`` at a clean end of stream.

    Raises:
        BitstreamError: truncated packet, bad sync, lengths over the limits, CRC mismatch.
    """
    frame = expect_seq
    layout = _PACKET_FIXED
    fixed = _read_exact(fh, layout.size)
    if not fixed:
        return None
    if len(fixed) < layout.size:
        raise BitstreamError(f"truncated packet header ({len(fixed)} of {layout.size} bytes)", frame)
    sync, seq, ts, image_len, hint_len, gain_len, meta_len, residual_len = layout.unpack(fixed)
    if sync != SYNC:
        raise BitstreamError("bad packet sync marker (corrupt or not a packet boundary)", frame)
    frame = seq if expect_seq is None else expect_seq
    cap = header.max_payload(limits)
    if image_len == 0 or image_len > cap:
        raise BitstreamError(f"image length {image_len} outside 1..{cap}", frame)
    if hint_len > cap or gain_len > cap:
        raise BitstreamError(f"hint or gain length ({hint_len}, {gain_len}) exceeds {cap}", frame)
    if meta_len > limits.max_meta_bytes:
        raise BitstreamError(f"metadata length {meta_len} exceeds {limits.max_meta_bytes}", frame)
    if residual_len and not header.has_residual:
        raise BitstreamError(f"a residual layer of {residual_len} bytes in a stream whose header has none", frame)
    if residual_len > header.max_residual(limits):
        raise BitstreamError(f"residual length {residual_len} exceeds {header.max_residual(limits)}", frame)
    total = image_len + hint_len + gain_len + meta_len + residual_len
    body = _read_exact(fh, total)
    crc = _read_exact(fh, _CRC.size)
    if len(body) < total or len(crc) < _CRC.size:
        raise BitstreamError(f"truncated packet ({len(body)} of {total} payload bytes)", frame)
    if _CRC.unpack(crc)[0] != zlib.crc32(fixed + body):
        raise BitstreamError("CRC mismatch", frame)
    a, b, c = image_len, image_len + hint_len, image_len + hint_len + gain_len
    d = c + meta_len
    return Packet(seq=seq, timestamp_us=ts, image=body[:a], hint=body[a:b], gain=body[b:c], meta=body[c:d],
                  residual=body[d:])


def iter_packets(fh: BinaryIO, header: StreamHeader, limits: Limits = Limits()) -> Iterator[Packet]:
    """Yields packets in order until the end; raises at the first damaged packet (after
    yielding every complete one before it). A sequence number that does not follow the
    previous one is damage too: a file is written in order."""
    expected = 0
    while True:
        packet = read_packet(fh, header, limits, expect_seq=expected)
        if packet is None:
            return
        if packet.seq != expected:
            raise BitstreamError(f"sequence number {packet.seq} where {expected} was expected", expected)
        yield packet
        expected += 1


def count_packets(fh: BinaryIO, header: StreamHeader, limits: Limits = Limits(),
                  most: int | None = None) -> tuple[int, BitstreamError | None]:
    """How many complete packets follow the header (read, checksums and all, up to the
    first damaged one: the frames a decode gives), and the damage that ended the count
    (``None`` where the stream ends cleanly); ``most``: stop counting there."""
    count = 0
    try:
        for _ in iter_packets(fh, header, limits):
            count += 1
            if most is not None and count >= most:
                break
    except BitstreamError as exc:
        return count, exc
    return count, None


class StreamWriter:
    """Writes a header and packets to a binary file-like object."""

    def __init__(self, fh: BinaryIO, header: StreamHeader):
        self._fh = fh
        self.header = header
        self.bytes_written = 0
        self._write(pack_header(header))

    def _write(self, data: bytes) -> None:
        self._fh.write(data)
        self.bytes_written += len(data)

    def write(self, packet: Packet) -> int:
        data = pack_packet(packet, self.header.version)
        self._write(data)
        return len(data)


def split_stream(data: bytes, limits: Limits = Limits()) -> tuple[StreamHeader, list[Packet]]:
    """Parses a whole in-memory stream; raises at damage (see :func:`iter_packets`)."""
    fh = io.BytesIO(data)
    header = read_header(fh, limits)
    return header, list(iter_packets(fh, header, limits))


__all__ = [
    "count_packets",
    "MAGIC",
    "VERSION",
    "OLDER_VERSIONS",
    "CODEC_JPEG",
    "CODEC_AV1",
    "CODEC_NAMES",
    "stream_version",
    "Limits",
    "StreamHeader",
    "Packet",
    "pack_header",
    "pack_packet",
    "read_header",
    "read_packet",
    "iter_packets",
    "StreamWriter",
    "split_stream",
    "check_header_values",
]
