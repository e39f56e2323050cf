"""The lfstream codec (seed chapter 3): JPEG centre view + depth-based reconstruction.

Encoder, per frame: the centre view, JPEG-compressed (quality 50 by default); the other
views are discarded. With ``depth_hint=True`` the encoder also estimates the centre
view's disparity from all views (:mod:`lfstream.depth`) and sends it, quantised and
zstd-compressed. Packets and the stream header are described in :mod:`lfstream.bitstream`.

Decoder, per frame: JPEG decode, then a disparity map for the centre view — from the hint
(``depth="hint"``), zero (``depth="flat"``: every view is the centre view) or Depth-Net's
per-view maps (``depth="net"``) — and the backward warp of the centre view into every
view with occlusion handling (:mod:`lfstream.warp`). JPEG-Hance (:mod:`lfstream.restore`)
restores the decoded centre view first where it helps (``hance="auto"``: JPEG quality up
to :data:`HANCE_MAX_QUALITY`). The networks are pluggable stages with the shipped ``fast``
weights; ``hance="off"`` and ``depth="flat"``/``"hint"`` are the non-learned fallbacks.

Determinism: the same input and options give the same bytes (OpenCV's JPEG encoder,
fixed zstd levels, sorted JSON metadata).
"""

from __future__ import annotations

import io
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

import cv2
import numpy as np

from lfstream.bitstream import (
    Limits,
    Packet,
    StreamHeader,
    StreamWriter,
    iter_packets,
    read_header,
)
from lfstream.depth import HintOptions, decode_hint, encode_hint, estimate_disparity
from lfstream.errors import BitstreamError, LFFileError, LFStreamError, LFValueError
from lfstream.lightfield import centre_view, check_finite, check_lf, to_uint8
from lfstream.shading import apply_gains, decode_gains, encode_gains, measure_gains, shading_present
from lfstream.warp import warp_views, warp_views_per_view

DEPTH_MODES = ("auto", "hint", "flat", "net")
ENCODER_NAME = "lfstream-jpeg-centre"


def encode_jpeg(img: np.ndarray, quality: int) -> bytes:
    """Baseline JPEG of a uint8 RGB image (4:2:0, OpenCV/libjpeg), deterministic."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR),
                           [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)])
    if not ok:  # pragma: no cover - OpenCV fails only on invalid input, checked by callers
        raise LFValueError("JPEG encoding failed")
    return buf.tobytes()


def decode_jpeg(data: bytes, size: tuple[int, int], frame: int | None = None) -> np.ndarray:
    """JPEG bytes to uint8 RGB ``(H, W, 3)``; checks the size the stream header promised."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise BitstreamError("centre view is not a decodable JPEG", frame)
    if img.shape[:2] != tuple(size):
        raise BitstreamError(f"centre view is {img.shape[0]}x{img.shape[1]}, header says {size[0]}x{size[1]}", frame)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def jpeg_roundtrip(img: np.ndarray, quality: int) -> np.ndarray:
    """What the decoder sees of a uint8 RGB image sent at ``quality`` (training and benchmarks)."""
    return decode_jpeg(encode_jpeg(img, quality), img.shape[:2])


@dataclass
class Encoder:
    """Encodes LF frames into packets.

    Attributes:
        quality: JPEG quality of the centre view (1..100).
        depth_hint: also send the encoder's disparity estimate.
        hint_options: plane-sweep and coding options of the hint.
    """

    quality: int = 50
    depth_hint: bool = False
    hint_options: HintOptions = field(default_factory=HintOptions)
    gain_grid: int = 4  # per-view brightness gains on a grid x grid mesh; 0 sends none

    def __post_init__(self) -> None:
        if not isinstance(self.quality, (int, np.integer)) or not 1 <= self.quality <= 100:
            raise LFValueError(f"quality: an integer in 1..100, got {self.quality!r}")
        if not isinstance(self.gain_grid, (int, np.integer)) or not 0 <= self.gain_grid <= 64:
            raise LFValueError(f"gain_grid: an integer in 0..64, got {self.gain_grid!r}")
        self.hint_options.validate()

    def header(self, views: tuple[int, int], size: tuple[int, int], fps: float) -> StreamHeader:
        from lfstream import __version__

        meta = {"encoder": ENCODER_NAME, "version": __version__, "quality": int(self.quality), "gain_grid": self.gain_grid}
        if self.depth_hint:
            meta["hint"] = {"max_disparity": self.hint_options.max_disparity, "steps": self.hint_options.steps,
                            "hint_scale": self.hint_options.hint_scale}
        return StreamHeader(views=views, size=size, fps=fps, quality=int(self.quality), has_hint=self.depth_hint, meta=meta)

    def encode_frame(self, lf: np.ndarray, seq: int, timestamp_us: int, present: np.ndarray | None = None) -> Packet:
        """One ``(U, V, H, W, 3)`` frame (uint8, or float in [0, 1]) to a packet.

        ``present`` marks the views that exist (a light field read with missing views); the
        centre view must be among them. The decoder reconstructs every view.
        """
        check_lf(lf, allow_video=False)
        if present is not None:
            present = np.asarray(present, bool)
            if present.shape != lf.shape[:2]:
                raise LFValueError(f"frame {seq}: present mask {present.shape} does not match the views {lf.shape[:2]}")
            if not present[lf.shape[0] // 2, lf.shape[1] // 2]:
                raise LFValueError(f"frame {seq}: the centre view is missing; it is the view the codec sends")
        if lf.shape[-1] != 3:
            raise LFValueError(f"frame {seq}: expected 3 colour channels, got {lf.shape[-1]}")
        check_finite(lf, f"frame {seq}")
        frame = to_uint8(np.asarray(lf))
        image = encode_jpeg(centre_view(frame), self.quality)
        hint = b""
        if self.depth_hint:
            hint = encode_hint(estimate_disparity(frame, self.hint_options, present), self.hint_options)
        gain = b""
        if self.gain_grid > 0 and frame.shape[0] * frame.shape[1] > 1:
            gains = measure_gains(frame, self.gain_grid, present=present)
            gain = encode_gains(gains) if shading_present(gains) else b""
        return Packet(seq=seq, timestamp_us=timestamp_us, image=image, hint=hint, gain=gain)


@dataclass
class DecodedFrame:
    """A decoded frame with the intermediate results users ask for."""

    seq: int
    timestamp_us: int
    lf: np.ndarray  # (U, V, H, W, 3) uint8
    centre: np.ndarray  # (H, W, 3) uint8, the decoded centre view
    disparity: np.ndarray  # (H, W) float32 centre-view disparity the warp used


HANCE_MODES = ("auto", "on", "off")
# "auto" runs JPEG-Hance only up to this JPEG quality per preset: above it the measured mean
# PSNR gain on the real samples' centre views (seahorse, HCI dino/cotton) is below 0.1 dB or
# negative (bench/networks.py: fast +0.32/+0.18/-0.14 dB at q10/30/50; paper +0.52 at q70,
# -1.35 at q90).
HANCE_MAX_QUALITY = {"fast": 30, "paper": 70}


def check_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"`` (when torch sees a GPU); a clear error otherwise."""
    import torch

    if device not in ("cpu", "cuda") and not str(device).startswith("cuda:"):
        raise LFValueError(f"device: 'cpu' or 'cuda', got {device!r}")
    if str(device).startswith("cuda") and not torch.cuda.is_available():
        raise LFValueError(f"device={device!r}: torch sees no CUDA GPU on this machine; use --device cpu")
    return str(device)


@dataclass
class Decoder:
    """Decodes packets of one stream: JPEG decode -> JPEG-Hance -> disparity -> warp.

    Attributes:
        header: the stream's header.
        depth: ``"auto"`` (the hint where the stream has one, else flat), ``"hint"``,
            ``"flat"`` or ``"net"`` (Depth-Net; its fast preset refines the depth hint).
        occlusion: occlusion-aware per-view disparity in the warp (hint mode).
        hance: ``"auto"`` (JPEG-Hance where it helps: stream quality <= HANCE_MAX_QUALITY[preset]),
            ``"on"`` or ``"off"``.
        device: where the networks run (``"cpu"`` or ``"cuda"``).
        preset: network preset whose shipped weights are used.
    """

    header: StreamHeader
    depth: str = "auto"
    occlusion: bool = True
    hance: str = "auto"
    device: str = "cpu"
    preset: str = "fast"

    def __post_init__(self) -> None:
        if self.depth not in DEPTH_MODES:
            raise LFValueError(f"depth: one of {', '.join(DEPTH_MODES)}, got {self.depth!r}")
        if self.hance not in HANCE_MODES:
            raise LFValueError(f"hance: one of {', '.join(HANCE_MODES)}, got {self.hance!r}")
        self.device = check_device(self.device)
        if self.depth == "hint" and not self.header.has_hint:
            raise LFValueError("depth='hint': this stream carries no depth hint (encode with depth_hint=True)")
        from lfstream.weights import load_model

        use_hance = self.hance == "on" or (self.hance == "auto"
                                           and self.header.quality <= HANCE_MAX_QUALITY.get(self.preset, 0))
        self._hance = load_model("jpeg_hance", self.preset, self.device) if use_hance else None
        self._depth_net = None
        if self.depth == "net":
            self._depth_net = load_model("depth_net", self.preset, self.device)
            if self._depth_net.config.hint and not self.header.has_hint:
                raise LFValueError("depth='net': the shipped Depth-Net refines the encoder's depth hint and this "
                                   "stream carries none (encode with --depth-hint, or decode with --depth flat)")

    @property
    def uses_hance(self) -> bool:
        return self._hance is not None

    def decode_packet(self, packet: Packet) -> DecodedFrame:
        return self.decode_batch([packet])[0]

    @property
    def estimates_depth(self) -> bool:
        """Whether frames get a disparity of their own (hint or Depth-Net), not flat."""
        return self.depth in ("hint", "net") or (self.depth == "auto" and self.header.has_hint)

    def decode_centres(self, packets: list[Packet]) -> np.ndarray:
        """JPEG decode and (where enabled) JPEG-Hance of the packets' centre views, batched.

        Shape:
            - output: ``(B, H, W, 3)`` uint8
        """
        centres = np.stack([decode_jpeg(p.image, self.header.size, p.seq) for p in packets])
        if self._hance is not None:
            from lfstream.restore import restore_images

            centres = restore_images(centres, self._hance, self.device)
        return centres

    def reconstruct(self, packet: Packet, centre: np.ndarray, disparity: np.ndarray) -> DecodedFrame:
        """Warps a decoded centre view by a given centre-view disparity (occlusion-aware) and
        applies the packet's shading gains; also serves callers that reuse a disparity."""
        lf = warp_views(centre, disparity, self.header.views, occlusion=self.occlusion)
        return self._finish(packet, centre, disparity, lf)

    def _finish(self, packet: Packet, centre: np.ndarray, disparity: np.ndarray, lf: np.ndarray) -> DecodedFrame:
        if packet.gain:
            lf = apply_gains(lf, decode_gains(packet.gain, self.header.views, packet.seq))
        return DecodedFrame(packet.seq, packet.timestamp_us, lf, centre, disparity)

    def decode_batch(self, packets: list[Packet], centres: np.ndarray | None = None) -> list[DecodedFrame]:
        """Decodes several packets; the networks run once over the batch. ``centres``: the
        output of :meth:`decode_centres` for these packets, when the caller already has it."""
        if not packets:
            return []
        h, w = self.header.size
        if centres is None:
            centres = self.decode_centres(packets)
        hints: list[np.ndarray | None] = []
        for p, centre in zip(packets, centres):
            use_hint = self.depth in ("hint", "net") or (self.depth == "auto" and p.hint)
            if use_hint and not p.hint:
                raise BitstreamError("packet has no depth hint", p.seq)
            hints.append(decode_hint(p.hint, (h, w), guide=centre, frame=p.seq) if use_hint else None)
        if self._depth_net is None:
            return [self.reconstruct(p, centre, hint if hint is not None else np.zeros((h, w), np.float32))
                    for p, centre, hint in zip(packets, centres, hints)]
        from lfstream.depth_net import predict_view_disparities

        stacked = np.stack(hints) if self._depth_net.config.hint else None
        view_maps = predict_view_disparities(centres, self._depth_net, self.header.views, stacked, self.device)
        u0, v0 = self.header.views[0] // 2, self.header.views[1] // 2
        return [self._finish(p, centre, maps[u0, v0], warp_views_per_view(centre, maps))
                for p, centre, maps in zip(packets, centres, view_maps)]


# ----------------------------------------------------------------------------------------
# Whole-stream API


def _frames_of(lf: np.ndarray) -> np.ndarray:
    check_lf(lf)
    return lf if lf.ndim == 6 else lf[None]


def encode(
    lf: np.ndarray,
    quality: int = 50,
    depth_hint: bool = False,
    fps: float = 30.0,
    hint_options: HintOptions | None = None,
    gain_grid: int = 4,
    present: np.ndarray | None = None,
) -> bytes:
    """Encodes one frame ``(U, V, H, W, 3)`` or a video ``(T, U, V, H, W, 3)`` to ``.lfs`` bytes.

    ``present``: the ``(U, V)`` mask of views that exist, for light fields read with missing
    views (the centre view must exist); the decoder reconstructs all views.

    Raises:
        LFStreamError: bad shape, dtype, non-finite values or parameters.
    """
    try:
        frames = _frames_of(np.asarray(lf) if not hasattr(lf, "numpy") else lf.cpu().numpy())
    except (TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, LFStreamError):
            raise
        raise LFValueError(f"lf: not an array ({exc})") from exc
    enc = Encoder(quality=quality, depth_hint=depth_hint, hint_options=hint_options or HintOptions(), gain_grid=gain_grid)
    buf = io.BytesIO()
    writer = StreamWriter(buf, enc.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps))
    for t, frame in enumerate(frames):
        writer.write(enc.encode_frame(frame, t, int(round(t * 1e6 / fps)), present))
    return buf.getvalue()


def iter_decode(fh, depth: str = "auto", occlusion: bool = True, limits: Limits = Limits(),
                max_frames: int | None = None, hance: str = "auto", device: str = "cpu",
                batch: int = 1) -> Iterator[DecodedFrame]:
    """Decodes a stream frame by frame (networks batched over ``batch`` frames); every
    complete frame before a damaged packet is yielded, then :class:`BitstreamError` names
    the damaged frame."""
    if not isinstance(batch, int) or not 1 <= batch <= 256:
        raise LFValueError(f"batch: an integer in 1..256, got {batch!r}")
    header = read_header(fh, limits)
    dec = Decoder(header, depth=depth, occlusion=occlusion, hance=hance, device=device)
    pending: list[Packet] = []
    try:
        for k, packet in enumerate(iter_packets(fh, header, limits)):
            if max_frames is not None and k >= max_frames:
                break
            pending.append(packet)
            if len(pending) >= batch:
                yield from dec.decode_batch(pending)
                pending = []
    except BitstreamError:
        # frames read before a damaged packet are still delivered, then the error
        if pending:
            yield from dec.decode_batch(pending)
        raise
    if pending:
        yield from dec.decode_batch(pending)


def decode(data: bytes, depth: str = "auto", occlusion: bool = True, limits: Limits = Limits(),
           hance: str = "auto", device: str = "cpu") -> np.ndarray:
    """Decodes ``.lfs`` bytes to ``(T, U, V, H, W, 3)`` uint8.

    Raises:
        LFStreamError: corrupt, truncated or hostile input (the error names the frame; the
            frames decoded before the damage are in its ``partial`` attribute).
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise LFValueError(f"data: expected bytes, got {type(data).__name__}")
    frames: list[np.ndarray] = []
    try:
        for f in iter_decode(io.BytesIO(bytes(data)), depth, occlusion, limits, hance=hance, device=device):
            frames.append(f.lf)
    except BitstreamError as exc:
        exc.partial = np.stack(frames) if frames else None  # type: ignore[attr-defined]
        raise
    if not frames:
        raise BitstreamError("stream holds no frames")
    return np.stack(frames)


def decode_file(path: str | os.PathLike, depth: str = "auto", max_frames: int | None = None,
                hance: str = "auto", device: str = "cpu") -> tuple[np.ndarray, float]:
    """Decodes an ``.lfs`` file; returns ``(lf, fps)``."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            header = read_header(fh)
            fh.seek(0)
            frames = [f.lf for f in iter_decode(fh, depth=depth, max_frames=max_frames, hance=hance, device=device)]
    except OSError as exc:
        raise LFFileError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except BitstreamError as exc:
        raise BitstreamError(f"{path}: {exc}") from exc
    if not frames:
        raise BitstreamError(f"{path}: stream holds no frames")
    return np.stack(frames), header.fps


def encode_file(frames: Iterable[np.ndarray], path: str | os.PathLike, views: tuple[int, int], size: tuple[int, int],
                encoder: Encoder, fps: float = 30.0, present: np.ndarray | None = None) -> dict:
    """Encodes frames into a file written atomically; returns byte counts and timing."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    stats = {"frames": 0, "bytes": 0, "image_bytes": 0, "hint_bytes": 0, "encode_s": 0.0}
    try:
        with open(tmp, "wb") as fh:
            writer = StreamWriter(fh, encoder.header(views, size, fps))
            for t, frame in enumerate(frames):
                t0 = time.perf_counter()
                packet = encoder.encode_frame(frame, t, int(round(t * 1e6 / fps)), present)
                stats["encode_s"] += time.perf_counter() - t0
                writer.write(packet)
                stats["frames"] += 1
                stats["image_bytes"] += len(packet.image)
                stats["hint_bytes"] += len(packet.hint)
            stats["bytes"] = writer.bytes_written
        os.replace(tmp, path)
    except OSError as exc:
        raise LFFileError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    finally:
        tmp.unlink(missing_ok=True)
    return stats


__all__ = [
    "DEPTH_MODES",
    "HANCE_MODES",
    "HANCE_MAX_QUALITY",
    "check_device",
    "Encoder",
    "Decoder",
    "DecodedFrame",
    "encode",
    "decode",
    "iter_decode",
    "decode_file",
    "encode_file",
    "encode_jpeg",
    "decode_jpeg",
    "jpeg_roundtrip",
]
