"""The encoder (seed chapter 3): per frame, the centre view as a JPEG (or, in the
``balanced`` and ``best`` presets, an AV1 key frame: :mod:`lfstream.codec.centre.av1`); with the
depth hint also the centre view's disparity (:mod:`lfstream.codec.hint`); per-view shading
gains where the views differ in brightness (:mod:`lfstream.codec.gains`); optionally the
residual layer, what the decoder's prediction misses in every other view
(:mod:`lfstream.codec.residual`).

Determinism: the same input and options give the same bytes (OpenCV's JPEG encoder,
fixed zstd levels, sorted JSON metadata).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, StreamWriter, stream_version
from lfstream.codec.centre import CentreCoding, encode_centre
from lfstream.codec.centre.av1 import AV1_MIN_VIEW, av1_fits
from lfstream.codec.centre.jpeg import QUALITY_RANGE, PostFilterChooser
from lfstream.codec.gains import GainTracker, measure_gains, shading_present
from lfstream.codec.hint import HintOptions, HintTracker
from lfstream.codec.workers import beside, completed
from lfstream.errors import LFValueError
from lfstream.io._fs import atomic_open
from lfstream.lightfield import centre_view, check_finite, check_lf, check_unit_range, to_uint8

ENCODER_NAME = "lfstream-jpeg-centre"

#: Named speed/size trade-offs of the centre view's coding (bench/rd.py measures them):
#: ``fast`` is the seed's JPEG; ``balanced`` an AV1 key frame at SVT-AV1
#: preset 12;
#: ``best`` SVT-AV1 preset 8.
PRESETS: dict[str, CentreCoding] = {
    "fast": CentreCoding("jpeg"),
    "balanced": CentreCoding("av1", speed=12),
    "best": CentreCoding("av1", speed=8),
}
DEFAULT_PRESET = "fast"
#: SVT-AV1 preset of the residual layer per preset: ``best`` spends the time (measured on
#: lytro_bikes: preset 8 gives 0.4-0.8 dB more than 12 at equal bytes, for 2x the time).
RESIDUAL_SPEED = {"fast": 12, "balanced": 12, "best": 8}
#: SVT-AV1 preset of a residual that codes the views themselves (modes ``views`` and
#: ``half-views``): there the AV1 sequence *is* the stream, so ``best`` takes SVT-AV1's
#: slowest preset lfstream allows. Measured on toys_array (9x9x240x320, views with the
#: centre as key frame, qualities 20-65): preset 4 codes 16-24 % fewer bytes than preset 8 at
#: -0.25…+0.37 dB, for about twice the time. ``balanced`` takes
#: preset 8 (the default's choice where warping cannot predict, :func:`lfstream.codec.rate.choose_default`):
#: preset 10 is faster but falls below x265 medium at its size on toys_array.
VIEWS_SPEED = {"fast": 12, "balanced": 8, "best": 4}


def preset_coding(preset: str) -> CentreCoding:
    """The centre coding of a named preset."""
    if preset not in PRESETS:
        raise LFValueError(f"preset: one of {', '.join(PRESETS)}, got {preset!r}")
    return PRESETS[preset]


@dataclass
class Encoder:
    """Encodes LF frames into packets.

    Attributes:
        quality: JPEG quality of the centre view (1..100).
        depth_hint: also send the encoder's disparity estimate.
        hint_options: plane-sweep and coding options of the hint.
        preset: the centre view's coding (:data:`PRESETS`: ``fast`` JPEG, ``balanced`` and
            ``best`` AV1).
        residual: quality (1..100) of the residual layer, ``None`` for none. The encoder
            then runs the decoder's prediction on every frame.
        residual_mode: what the residual codes (:data:`lfstream.codec.residual.RESIDUAL_MODES`):
            ``prediction`` (the prediction's error), ``views`` (the views themselves, for
            scenes warping cannot predict; no prediction is run and no gain maps are sent,
            the decoder does not warp) or ``half-views`` (the same at half size, for the
            lowest rates). ``views`` with an AV1 preset and ``residual == quality`` codes
            every view as one sequence whose key frame is the centre view (the centre
            payload; :func:`lfstream.codec.residual.encode_views_keyed`): one intra frame,
            not two. Rate control always makes that choice.
        post_filter: measure which of the decoder's JPEG post-filters
            (:data:`lfstream.codec.centre.jpeg.POST_FILTERS`, and a black floor) suits the centre
            view and name it in the JPEG; ``False`` leaves every frame at the default
            filter, the bytes of earlier versions.
        hance_map: send a JPEG-Hance strength map with the JPEG centre view
            (:mod:`lfstream.codec.centre.hance`): measured on the first frame and every hint key
            frame after it by decoding the frame, running the network and warping at each
            strength (the fast network on the CPU: about 0.15 s a 7x7x375x540 frame measured;
            the frames between only have their hint and gains read, to follow the stream). A
            decoder running JPEG-Hance (fast) then blends its correction by the map. JPEG
            centres without a residual layer only.
        device: where the hint's plane sweep runs: ``"cpu"`` (the kernels) or ``"cuda"``
            (tensor operations, :mod:`lfstream.codec.hint.sweep_batched`; the maps agree to float
            rounding, so the bytes may differ in a rare hint cell).
    """

    quality: int = 50
    depth_hint: bool = True
    hint_options: HintOptions = field(default_factory=HintOptions)
    gain_grid: int = 4  # per-view brightness gains on a grid x grid mesh; 0 sends none
    preset: str = DEFAULT_PRESET
    residual: int | None = None
    residual_mode: str = "prediction"
    post_filter: bool = True
    device: str = "cpu"
    hance_map: bool = False

    def __post_init__(self) -> None:
        from lfstream.models.device import check_device

        self.device = check_device(self.device)
        self.coding = preset_coding(self.preset)
        if self.residual is not None or self.residual_mode != "prediction":
            from lfstream.codec.residual import check_residual_mode, check_residual_quality

            check_residual_mode(self.residual_mode)
            if self.residual is None:
                raise LFValueError(f"residual_mode {self.residual_mode!r}: needs a residual quality")
            check_residual_quality(self.residual)
        self._reference = None  # the decoder whose prediction the residual corrects
        lo, hi = QUALITY_RANGE
        if not isinstance(self.quality, (int, np.integer)) or not lo <= self.quality <= hi:
            raise LFValueError(f"quality: an integer in {lo}..{hi}, got {self.quality!r}")
        if not isinstance(self.gain_grid, (int, np.integer)) or not 0 <= self.gain_grid <= 64:
            raise LFValueError(f"gain_grid: an integer in 0..64, got {self.gain_grid!r}")
        self.hint_options.validate()
        self._hints = HintTracker(self.hint_options, self.device)
        self._gains = GainTracker(self.hint_options.key_interval)  # key maps with the key hints' interval
        self._post_filters = PostFilterChooser(self.hint_options.key_interval)
        self.last_gains: np.ndarray | None = None  # the last frame's gain maps as measured (None: none sent)
        if self.hance_map:
            self.check_hance_map()
        self._hance_reference = None  # the decoder that follows the stream for the strength map
        self._hance_model = None
        self._hance_levels: np.ndarray | None = None
        self._hance_age: int | None = None  # frames since the map was measured
        self.last_hance_map: np.ndarray | None = None  # the last frame's strength levels (None: none sent)

    @property
    def takes_hance_map(self) -> bool:
        """Whether a JPEG-Hance strength map applies to this encoder's streams: a JPEG centre
        view and no residual layer (:attr:`hance_map`)."""
        return self.coding.codec == "jpeg" and self.residual is None

    def check_hance_map(self) -> None:
        """Refuses a strength map where it does not apply (:attr:`takes_hance_map`)."""
        if not self.takes_hance_map:
            raise LFValueError("hance_map: a JPEG-Hance strength map goes with a JPEG centre view (preset fast) "
                               "and no residual layer")

    def header(self, views: tuple[int, int], size: tuple[int, int], fps: float) -> StreamHeader:
        from lfstream.version import __version__

        centre_fails = self.coding.codec == "av1" and not av1_fits(size)
        # a half-views residual codes the views at half size
        residual_fails = False
        if self.residual is not None:
            from lfstream.codec.residual import coded_size as residual_coded_size

            residual_fails = not av1_fits(residual_coded_size(size, self.residual_mode))
        if centre_fails or residual_fails:
            what = f"preset {self.preset!r}" + (f" with a {self.residual_mode} residual" if self.residual is not None else "")
            half_views = residual_fails and self.residual_mode == "half-views"
            half = " (a half-views residual codes them at half size)" if half_views else ""
            raise LFValueError(f"{what}: AV1 codes views of at least {AV1_MIN_VIEW} pixels{half}, these are "
                               f"{size[0]}x{size[1]}; use the fast preset (JPEG) without a residual")
        meta = {"encoder": ENCODER_NAME, "version": __version__, "quality": int(self.quality), "gain_grid": self.gain_grid}
        if self.coding.codec != "jpeg":  # the AV1 presets' settings (a JPEG stream's header stays short)
            meta["preset"] = self.preset
            coding = CentreCoding("av1", self.residual_speed) if self.keys_views else self.coding
            meta["centre"] = coding.as_meta(self.quality)
        if self.depth_hint:
            meta["hint"] = self.hint_options.as_meta()
        if self.residual is not None:
            meta["residual"] = residual_meta(int(self.residual), self.residual_speed, self.residual_mode)
        if self.hance_map:  # the network the maps are measured for: a decoder's hance "auto" runs it
            from lfstream.codec.centre.hance import HANCE_MAP_PRESET

            meta["hance_map"] = HANCE_MAP_PRESET
        return StreamHeader(views=views, size=size, fps=fps, quality=int(self.quality), has_hint=self.depth_hint,
                            codec=self.coding.codec_id, meta=meta, has_residual=self.residual is not None)

    @property
    def codes_views(self) -> bool:
        """Whether the residual layer carries the views themselves (no prediction, no gains)."""
        return self.residual is not None and self.residual_mode != "prediction"

    @property
    def keys_views(self) -> bool:
        """Whether the views' sequence starts with the centre view as its key frame (the
        centre payload): mode ``views``, an AV1 centre, one quality for both."""
        return self.residual_mode == "views" and self.coding.codec == "av1" and self.residual == self.quality

    @property
    def last_hint(self):
        """The last frame's hint as the decoder rebuilds it
        (:class:`lfstream.codec.hint.QuantisedHint`), ``None`` before the first or without one."""
        return self._hints.last if self.depth_hint else None

    @property
    def last_ring_luma(self) -> np.ndarray | None:
        """The last frame's centre and outer-ring luma at the hint's resolution, as its sweep
        read them (:attr:`lfstream.codec.hint.HintMap.ring_luma`), where that frame's hint was
        a key hint (a stream's first always is); else ``None``."""
        return self._hints.last_ring_luma if self.depth_hint else None

    @property
    def residual_speed(self) -> int:
        """The residual layer's SVT-AV1 preset (:data:`RESIDUAL_SPEED`, :data:`VIEWS_SPEED`)."""
        return (VIEWS_SPEED if self.codes_views else RESIDUAL_SPEED)[self.preset]

    @property
    def stream_version(self) -> int:
        """The ``.lfs`` version of this encoder's streams."""
        return stream_version(self.coding.codec_id, self.residual is not None)

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
        check_unit_range(lf, f"frame {seq}")
        if self.codes_views and present is not None and not present.all():
            raise LFValueError(f"frame {seq}: residual_mode {self.residual_mode!r} codes every view and "
                               f"{int((~present).sum())} are missing; use the prediction mode, which reconstructs them")
        frame = to_uint8(np.asarray(lf))
        centre = centre_view(frame)
        hint_job = None
        if self.keys_views:  # the centre view is the views' key frame: coded with them (add_residual)
            centre_job = completed(b"")
            if self.depth_hint:
                hint_job = self._hints.start_encode(frame, seq, present)
        elif self.depth_hint:
            # the centre view's coding
            # does not depend on the hint: overlapped with it on a worker thread (measured on
            # lytro_bikes, 2 cores: a single-frame encode 24.8 -> 20.2 ms); same bytes
            centre_job = beside(lambda: self._code_centre(centre))
            hint_job = self._hints.start_encode(frame, seq, present)
        else:
            centre_job = completed(self._code_centre(centre))
        # the gains are measured against the hint while its payload is coded (start_encode)
        gain = self._gain_payload(frame, seq, present, hint_job is not None)
        image = centre_job.result()
        hint = b"" if hint_job is None else hint_job.result()
        packet = Packet(seq=seq, timestamp_us=timestamp_us, image=image, hint=hint, gain=gain)
        if self.residual is not None and frame.shape[0] * frame.shape[1] > 1:
            packet = self.add_residual(packet, frame, self.residual)
        if self.hance_map:
            packet = self.mark_hance(packet, frame, present)
        return packet

    def mark_hance(self, packet: Packet, frame: np.ndarray, present: np.ndarray | None = None) -> Packet:
        """``packet`` with the JPEG-Hance strength map in its JPEG (:attr:`hance_map`): a
        decoder without JPEG-Hance follows the stream (every packet, in stream order, so that
        delta hints and gains resolve), and on the first and every hint key interval's frame
        decodes it and the map is measured (:func:`lfstream.codec.centre.hance.measure_hance_map`);
        the frames between repeat it."""
        from dataclasses import replace

        from lfstream.codec.centre.hance import HANCE_MAP_PRESET, measure_hance_map
        from lfstream.codec.centre.jpeg import with_hance_map
        from lfstream.codec.decoder import Decoder

        frame = to_uint8(np.asarray(frame))
        if self._hance_reference is None:
            self._hance_reference = Decoder(self.header(frame.shape[:2], frame.shape[2:4], 30.0), depth="auto",
                                            hance="off")
        if self._hance_age is not None and self._hance_age < self.hint_options.key_interval:
            # a frame between measurements: its hint and gains only, for the deltas after it
            self._hance_reference.follow(packet)
        else:
            from lfstream.models.jpeg_hance import restore_images
            from lfstream.models.registry import load_model

            if self._hance_model is None:
                self._hance_model = load_model("jpeg_hance", HANCE_MAP_PRESET, "cpu")
            decoded = self._hance_reference.decode_packet(packet)
            restored = restore_images(decoded.centre[None], self._hance_model)[0]
            self._hance_levels = measure_hance_map(frame, decoded.centre, restored, decoded.disparity, decoded.axes,
                                                   decoded.gains, present,
                                                   occlusion=self._hance_reference.occlusion, warped=decoded.lf)
            self._hance_age = 0
        self._hance_age += 1
        self.last_hance_map = self._hance_levels
        return replace(packet, image=with_hance_map(packet.image, self._hance_levels))

    def _gain_payload(self, frame: np.ndarray, seq: int, present: np.ndarray | None, hinted: bool,
                      measured: np.ndarray | None = None) -> bytes:
        """Frame ``seq``'s shading gains (measured against the warp of the hint as sent, or
        ``measured`` so where the caller has them), coded; ``b""`` where the stream sends none."""
        if not (self.gain_grid > 0 and frame.shape[0] * frame.shape[1] > 1 and not self.codes_views):
            return b""
        gains = measured
        if gains is None:
            sent = self._hints.last if hinted else None  # the hint as the decoder will warp with it
            gains = measure_gains(frame, self.gain_grid, present=present,
                                  disparity=None if sent is None else sent.values(),
                                  axes=None if sent is None else sent.axes)
        self.last_gains = gains if shading_present(gains) else None
        return self._gains.encode(self.last_gains, seq)

    def coarser_first_hint(self):
        """Frame 0's key hint as it would be sent at twice the scale
        (:meth:`lfstream.codec.hint.HintTracker.coarser_key_hint`), or ``None``."""
        return self._hints.coarser_key_hint() if self.depth_hint else None

    def coarsen_first_hint(self, frame: np.ndarray, packet: Packet, present: np.ndarray | None = None,
                           gains: np.ndarray | None = None, payload: bytes | None = None) -> Packet:
        """Frame 0's ``packet`` with its key hint sent at twice the scale, from the same sweep,
        and its shading gains, where it has any, measured again against that hint (a frame
        without shading against the finer hint keeps none; ``gains``: that measurement where the
        caller made it, :func:`lfstream.codec.gains.measure_gains` against
        :meth:`coarser_first_hint`; ``payload``: :func:`lfstream.codec.hint.key_payload` of that
        hint, likewise);
        the frames after it follow at that scale (:attr:`hint_options`, which the header
        records). The packet is then what an encoder with that ``hint_scale`` makes of the
        frame (byte for byte on the shared samples and the synthetic clip)."""
        from dataclasses import replace

        if packet.seq != 0 or not packet.hint:
            raise LFValueError("coarsen_first_hint: a stream's first packet, with a hint")
        hint = self._hints.coarsen(payload)
        self.hint_options = self._hints.options
        if self.last_gains is None:
            return replace(packet, hint=hint)
        self._gains = GainTracker(self.hint_options.key_interval)  # frame 0's gains again, as a key map
        return replace(packet, hint=hint, gain=self._gain_payload(to_uint8(np.asarray(frame)), 0, present, True, gains))

    def _code_centre(self, centre: np.ndarray) -> bytes:
        """The centre view's payload, naming the post-filter where it is measured."""
        image = encode_centre(centre, self.quality, self.coding)
        if self.post_filter and self.coding.codec == "jpeg":
            image = self._post_filters.mark(centre, image)
        return image

    def predict(self, packet: Packet, views: tuple[int, int], size: tuple[int, int]) -> np.ndarray:
        """What the decoder reconstructs from ``packet`` before any residual: the reference
        prediction (:attr:`lfstream.codec.decoder.Decoder.applies_residual`). Packets must
        come in stream order (delta hints refer to earlier frames).

        Shape:
            - output: ``(U, V, H, W, 3)`` uint8
        """
        if self._reference is None:
            from lfstream.codec.decoder import Decoder

            self._reference = Decoder(self.header(views, size, 30.0), depth="auto", hance="off")
        return self._reference.decode_packet(packet).lf

    def add_residual(self, packet: Packet, frame: np.ndarray, quality: int) -> Packet:
        """``packet`` with a residual layer at ``quality`` against its prediction (in mode
        ``views``: the views themselves; with :attr:`keys_views`, the centre payload too)."""
        from dataclasses import replace

        from lfstream.codec.residual import encode_residual, encode_views_keyed

        if self.keys_views:
            image, residual = encode_views_keyed(frame, quality, self.residual_speed)
            return replace(packet, image=image, residual=residual)
        prediction = None
        if self.residual_mode == "prediction":
            prediction = self.predict(packet, frame.shape[:2], frame.shape[2:4])
        return replace(packet, residual=encode_residual(frame, prediction, quality, self.residual_speed,
                                                        half=self.residual_mode == "half-views"))


def residual_meta(quality: int, svt_preset: int, mode: str = "prediction") -> dict:
    """The header's record of a residual layer (``mode`` only where it is not the first
    one, so prediction streams keep their bytes)."""
    meta = {"codec": "av1", "quality": int(quality), "svt_preset": int(svt_preset)}
    if mode != "prediction":
        meta["mode"] = mode
    return meta


@dataclass
class EncodeStats:
    """What :func:`lfstream.codec.stream_encoder.encode_file` wrote."""

    frames: int = 0
    bytes: int = 0
    image_bytes: int = 0
    hint_bytes: int = 0
    residual_bytes: int = 0
    encode_s: float = 0.0

    def add(self, packet: Packet, seconds: float) -> None:
        self.frames += 1
        self.image_bytes += len(packet.image)
        self.hint_bytes += len(packet.hint)
        self.residual_bytes += len(packet.residual)
        self.encode_s += seconds


def frames_of(lf: np.ndarray) -> np.ndarray:
    """A frame ``(U, V, H, W, C)`` as a one-frame video; a video as it is (checked)."""
    check_lf(lf)
    return lf if lf.ndim == 6 else lf[None]


def write_stream_file(path: str | os.PathLike, header: StreamHeader, packets: Iterable[Packet]) -> EncodeStats:
    """Writes a header and packets as an ``.lfs`` file, atomically; returns the byte counts."""
    stats = EncodeStats()
    with atomic_open(Path(path)) as fh:
        writer = StreamWriter(fh, header)
        for packet in packets:
            writer.write(packet)
            stats.add(packet, 0.0)
        stats.bytes = writer.bytes_written
    return stats


__all__ = ["ENCODER_NAME", "PRESETS", "DEFAULT_PRESET", "preset_coding", "Encoder", "EncodeStats",
           "residual_meta", "write_stream_file", "frames_of"]
