"""What a stream does: :class:`StreamConfig` and the choices and ranges of its fields.

The CLI takes its choices and ranges from here (and from :mod:`lfstream.codec`), so a flag
and the library can never disagree. This module imports neither torch nor numba.
"""

from __future__ import annotations

from dataclasses import dataclass

from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.decoder import BATCH_RANGE, DEPTH_MODES, HANCE_MODES, NETWORK_PRESETS
from lfstream.codec.encoder import DEFAULT_PRESET, PRESETS, Encoder
from lfstream.codec.residual import RESIDUAL_MODES
from lfstream.errors import LFValueError
from lfstream.optics import PlenopticCamera

REFOCUS_MODES = ("auto", "refnet", "sas", "fourier", "none")
#: Named focal-plane sets of StreamConfig.alphas (besides explicit alphas).
FOCUS_MODES = ("auto", "seed")
TRANSPORTS = ("inproc", "file", "tcp")
#: mp4: one H.264 yuv420p video per focal plane (plays everywhere); mp4-lossless: the same
#: losslessly (x264 RGB, QP 0) for regression use; png: every plane of every frame; sweep:
#: one video stepping through the planes; lf: the reconstructed light field
#: (``reconstructed.avi``, a lossless Ut Video mosaic).
SAVE_KINDS = ("mp4", "mp4-lossless", "png", "sweep", "lf")
#: Bounded-queue sizes (frames a queue between two stages holds).
QUEUE_RANGE = (1, 256)


def check_range(name: str, value: float, bounds: tuple[float, float], integer: bool = True) -> None:
    """Raises :class:`LFValueError` naming ``name`` unless ``value`` lies in ``bounds``."""
    lo, hi = bounds
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if not ok or not lo <= value <= hi:
        raise LFValueError(f"{name}: {'an integer' if integer else 'a number'} in {lo}..{hi}, got {value!r}")


def check_choice(name: str, value: str, choices: tuple[str, ...]) -> None:
    """Raises :class:`LFValueError` naming ``name`` unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise LFValueError(f"{name}: one of {', '.join(choices)}, got {value!r}")


@dataclass
class StreamConfig:
    """What the pipeline does (the CLI's flags map onto these fields)."""

    quality: int = 50
    depth_hint: bool = True
    # a target size in bits per pixel: rate control picks quality and hint on the first frame
    bpp: float | None = None
    # the centre view's coding (lfstream.codec.encoder.PRESETS); None: the default's choice on
    # the first frame (lfstream.codec.rate.choose_default: fast from 7x7 views, AV1 with fewer,
    # the views themselves where warping cannot predict them), or with bpp every preset is a
    # rate-control candidate
    preset: str | None = None
    # quality of the residual layer (lfstream.codec.residual); None: none (with bpp, rate
    # control decides)
    residual: int | None = None
    # what the residual layer codes (lfstream.codec.residual.RESIDUAL_MODES)
    residual_mode: str = "prediction"
    # JPEG-Hance strength maps with each JPEG centre view (Encoder.hance_map): the decoder's
    # hance "auto" then runs the network, blended by them
    hance_map: bool = False
    depth: str = "auto"
    hance: str = "auto"
    # the decoder's networks' shipped weights (Decoder.preset: fast, or JPEG-Hance paper)
    networks: str = "fast"
    refocus: str = "auto"
    # "auto": planes fitted to the scene's disparity; "seed": the seed's sixteen alphas
    alphas: tuple[float, ...] | str = "auto"
    batch: int = 1
    device: str = "cpu"
    queue_size: int = 4
    transport: str = "inproc"
    save: tuple[str, ...] = ("mp4",)
    skip_static: bool = True
    static_threshold: float = 0.5
    # MSSIM (and the focal stack's PSNR against the input's) on frames 0, N, 2N, ...: 0.2 s
    # of the metrics stage per 7x7x375x540 frame, so sampled once a second of 30 fps video
    # (MPSNR is cheap: every frame); the summary's mssim_frames lists the frames measured
    mssim_every: int = 30
    metrics: bool = True
    fps: float = 30.0
    # the capturing camera, when known: each focal plane then records its refocus distance
    camera: PlenopticCamera | None = None

    def encoder(self) -> Encoder:
        """The encoder these fields describe (before rate control, which picks its own)."""
        return Encoder(quality=self.quality, depth_hint=self.depth_hint, preset=self.preset or DEFAULT_PRESET,
                       residual=self.residual, residual_mode=self.residual_mode, hance_map=self.hance_map)

    def validate(self) -> None:
        """Raises :class:`LFValueError` naming the first field out of its range."""
        check_range("quality", self.quality, QUALITY_RANGE)
        if self.bpp is not None:
            check_range("bpp", self.bpp, (1e-5, 24.0), integer=False)
        if self.preset is not None:
            check_choice("preset", self.preset, tuple(PRESETS))
        if self.residual is not None:
            check_range("residual", self.residual, QUALITY_RANGE)
        check_choice("residual_mode", self.residual_mode, RESIDUAL_MODES)
        if self.bpp is not None:
            from lfstream.codec.rate import RATE_CONTROL_CHOOSES, rate_control_conflict

            conflict = rate_control_conflict(self.residual, self.residual_mode, hance_map=self.hance_map)
            if conflict:
                raise LFValueError(f"{conflict}: rate control (bpp) {RATE_CONTROL_CHOOSES[conflict]}")
        if self.hance_map:
            self.encoder()  # refuses a coding the maps do not go with (an AV1 centre, a residual layer)
        if self.residual_mode != "prediction" and self.residual is None:
            raise LFValueError(f"residual_mode {self.residual_mode!r}: needs a residual quality")
        if isinstance(self.alphas, str):
            check_choice("alphas", self.alphas, FOCUS_MODES)
        else:
            from lfstream.optics import check_alpha

            if not self.alphas:
                raise LFValueError("alphas: at least one, or 'auto' / 'seed'")
            for a in self.alphas:
                check_alpha(a)
        check_choice("depth", self.depth, DEPTH_MODES)
        check_choice("hance", self.hance, HANCE_MODES)
        check_choice("networks", self.networks, NETWORK_PRESETS)
        check_choice("refocus", self.refocus, REFOCUS_MODES)
        check_choice("transport", self.transport, TRANSPORTS)
        bad = [s for s in self.save if s not in SAVE_KINDS]
        if bad:
            raise LFValueError(f"save: each of {', '.join(SAVE_KINDS)}, got {bad}")
        check_range("batch", self.batch, BATCH_RANGE)
        check_range("queue size", self.queue_size, QUEUE_RANGE)
        if self.mssim_every < 0 or self.static_threshold < 0:
            raise LFValueError("mssim_every and static_threshold must be >= 0")
        if not 0 < self.fps <= 10000:
            raise LFValueError(f"fps: in (0, 10000], got {self.fps!r}")
        from lfstream.models.device import check_device

        check_device(self.device)


__all__ = ["StreamConfig", "FOCUS_MODES", "REFOCUS_MODES", "TRANSPORTS", "SAVE_KINDS", "QUEUE_RANGE",
           "check_range", "check_choice"]
