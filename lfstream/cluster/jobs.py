"""The units of batch work: frame groups, and the pure functions that encode or decode one.

A job is self-contained and deterministic, so it gives the same bytes in this process or
on any worker of a cluster. Encoding: the first frame of every group is a key frame (its
depth hint is sent whole), so groups encode independently and their packets, renumbered
in order, make one ``.lfs`` stream. Decoding: groups start at packets whose hint is whole
(or at streams without a hint), so each group decodes on its own exactly as a sequential
decoder would.
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, pack_packet, read_header, read_packet
from lfstream.codec.hint import KIND_FULL
from lfstream.errors import LFValueError


@dataclass(frozen=True)
class EncodeOptions:
    """What ``batch(mode="encode")`` does to every frame (as ``lfstream encode``)."""

    quality: int = 50
    depth_hint: bool = True
    # the centre view's coding (lfstream.codec.encoder.PRESETS): fast = JPEG, balanced / best = AV1;
    # None: the default's choice for each input, on its first frame (lfstream.codec.rate.choose_default)
    preset: str | None = None
    residual: int | None = None  # quality of the residual layer (lfstream.codec.residual); None: none
    residual_mode: str = "prediction"  # what the residual codes (lfstream.codec.residual.RESIDUAL_MODES)
    # the hint's options (lfstream.codec.hint.HintOptions); None: the defaults, and where the
    # default's choice runs, the resolution it chose for the input (for_input)
    hint_options: object | None = None
    # JPEG-Hance strength maps with JPEG centre views (lfstream.codec.encoder.Encoder.hance_map);
    # where the default's choice codes the views themselves, none (as lfstream encode --hance-map)
    hance_map: bool = False

    def __post_init__(self) -> None:
        from lfstream.codec.encoder import PRESETS
        from lfstream.codec.residual import check_residual_mode, check_residual_quality

        if self.preset is not None and self.preset not in PRESETS:
            raise LFValueError(f"preset: one of {', '.join(PRESETS)}, got {self.preset!r}")
        if self.residual is not None:
            check_residual_quality(self.residual)
        check_residual_mode(self.residual_mode)
        if self.hance_map:  # the encoder's own refusal of a coding the maps do not go with
            from lfstream.codec.encoder import DEFAULT_PRESET, Encoder

            Encoder(preset=self.preset or DEFAULT_PRESET, residual=self.residual, residual_mode=self.residual_mode,
                    hance_map=True)

    def coding(self):
        """These options as the stream encoder's
        (:class:`lfstream.codec.stream_encoder.CodingOptions`)."""
        from lfstream.codec.stream_encoder import CodingOptions

        return CodingOptions(quality=self.quality, depth_hint=self.depth_hint, preset=self.preset,
                             residual=self.residual, residual_mode=self.residual_mode,
                             hint_options=self.hint_options, hance_map=self.hance_map)

    def for_input(self, first: np.ndarray, present: np.ndarray | None = None) -> EncodeOptions:
        """These options with the preset (and, where the default codes the views, the residual)
        fixed for an input whose first frame is ``first``: what ``lfstream encode`` chooses
        (:meth:`lfstream.codec.stream_encoder.StreamEncoder.fixed_options`, the hint's
        resolution included)."""
        from dataclasses import replace

        from lfstream.codec.stream_encoder import StreamEncoder

        fixed = StreamEncoder(self.coding(), present=present).fixed_options(first)
        return replace(self, preset=fixed.preset, depth_hint=fixed.depth_hint, residual=fixed.residual,
                       residual_mode=fixed.residual_mode, hint_options=fixed.hint_options, hance_map=fixed.hance_map)

    def encoder(self):
        """A fresh :class:`~lfstream.codec.encoder.Encoder` with these options."""
        from lfstream.codec.stream_encoder import StreamEncoder

        if self.preset is None:
            raise LFValueError("EncodeOptions: the preset is chosen per input (for_input) before encoding")
        return StreamEncoder(self.coding()).named_encoder()


@dataclass(frozen=True)
class DecodeOptions:
    """What ``batch(mode="decode")`` does to every packet (as ``lfstream decode``)."""

    depth: str = "auto"
    hance: str = "auto"
    device: str = "cpu"
    networks: str = "fast"  # the networks' shipped weights (Decoder.preset)


@dataclass
class GroupResult:
    """What one job returns: packed packets (encode) or decoded frames (decode)."""

    start: int
    packets: list[bytes] = field(default_factory=list)
    frames: np.ndarray | None = None
    seconds: float = 0.0


def encode_group(frames: np.ndarray, start: int, fps: float, options: EncodeOptions,
                 present: np.ndarray | None = None) -> GroupResult:
    """Encodes frames ``start, start + 1, ...`` with a fresh encoder (the group's first frame
    is a key frame); returns the packets packed, in order."""
    import time

    from lfstream.codec.stream_encoder import StreamEncoder

    t0 = time.perf_counter()
    if options.preset is None:
        raise LFValueError("EncodeOptions: the preset is chosen per input (for_input) before encoding")
    stream = StreamEncoder(options.coding(), fps, present, start=start)
    packets = [stream.encode_frame(f) for f in frames]
    packets = [pack_packet(p, stream.encoder.stream_version) for p in packets]
    return GroupResult(start, packets=packets, seconds=time.perf_counter() - t0)


def decode_group(header_bytes: bytes, packets: list[bytes], start: int, options: DecodeOptions) -> GroupResult:
    """Decodes packets that start at a self-contained one; returns ``(n, U, V, H, W, 3)``."""
    import time

    from lfstream.codec.decoder import Decoder

    t0 = time.perf_counter()
    header = read_header(io.BytesIO(header_bytes))
    dec = Decoder(header, depth=options.depth, hance=options.hance, device=options.device, preset=options.networks)
    parsed = [read_packet(io.BytesIO(p), header) for p in packets]
    frames = np.stack([f.lf for f in dec.decode_batch(parsed)])
    return GroupResult(start, frames=frames, seconds=time.perf_counter() - t0)


def frame_groups(frames: Iterable[np.ndarray], group: int) -> Iterator[tuple[int, np.ndarray]]:
    """The frames in groups of ``group`` (the last may be shorter), each stacked into one
    array with the index of its first frame, as the frames come (one group in memory)."""
    start, pending = 0, []
    for frame in frames:
        pending.append(frame)
        if len(pending) == group:
            yield start, np.stack(pending)
            start, pending = start + group, []
    if pending:
        yield start, np.stack(pending)


def decode_groups(packets: list[Packet], group: int) -> list[tuple[int, int]]:
    """Packet ranges of at least ``group`` packets (where possible), each starting at a
    packet that decodes on its own: no hint, or a whole (key) hint."""
    def starts_clean(p: Packet) -> bool:
        return not p.hint or p.hint[0] == 1 or (len(p.hint) > 1 and p.hint[1] == KIND_FULL)

    cuts = [0]
    for k in range(1, len(packets)):
        if k - cuts[-1] >= group and starts_clean(packets[k]):
            cuts.append(k)
    return [(a, b) for a, b in zip(cuts, cuts[1:] + [len(packets)])]


def split_stream_bytes(data: bytes) -> tuple[StreamHeader, bytes, list[Packet], list[bytes]]:
    """The header (parsed and as bytes) and every packet (parsed and as bytes) of a stream;
    raises :class:`~lfstream.errors.BitstreamError` at damage."""
    from lfstream.codec.bitstream import iter_packets

    fh = io.BytesIO(data)
    header = read_header(fh)
    header_bytes = data[: fh.tell()]
    packets, raw = [], []
    pos = fh.tell()
    for p in iter_packets(fh, header):
        packets.append(p)
        raw.append(data[pos: fh.tell()])
        pos = fh.tell()
    return header, header_bytes, packets, raw


__all__ = ["EncodeOptions", "DecodeOptions", "GroupResult", "encode_group", "decode_group", "frame_groups",
           "decode_groups", "split_stream_bytes"]
