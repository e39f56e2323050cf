"""The decoder (seed chapter 3): JPEG decode, its post-filter (or JPEG-Hance where that
measured better), a disparity per
frame — from the hint (``depth="hint"``), zero (``depth="flat"``: every view is the centre
view) or Depth-Net's per-view maps (``depth="net"``) — and the backward warp of the centre
view into every view with occlusion handling (:mod:`lfstream.codec.warp.cpu`), then the
per-view shading gains, and the residual layer where the stream has one (added only to the
prediction it was computed against; a residual of mode ``views`` or ``half-views`` carries
the views themselves, so nothing is warped). The networks are pluggable stages with the shipped ``fast``
weights; ``hance="off"`` and ``depth="flat"``/``"hint"`` are the non-learned fallbacks.
"""

from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np

from lfstream.codec.bitstream import (
    CODEC_AV1,
    CODEC_JPEG,
    Packet,
    StreamHeader,
)
from lfstream.codec.centre import decode_centre
from lfstream.codec.centre.hance import HANCE_MAP_PRESET
from lfstream.codec.centre.jpeg import blend_restored, hance_map, hance_strength, post_filter_jpeg
from lfstream.codec.gains import GainDecoder, GainReferenceError
from lfstream.codec.hint import HintDecoder, HintReferenceError
from lfstream.codec.residual import VIEW_MODES, apply_residual, decode_residual, residual_mode
from lfstream.codec.warp.cpu import warp_views, warp_views_per_view
from lfstream.errors import BitstreamError, LFValueError

DEPTH_MODES = ("auto", "hint", "flat", "net")
#: The networks' presets a decoder can load (:data:`lfstream.models.registry.PRESETS`, named
#: again here because codec sits below models and the command line checks them without
#: importing torch; a test holds the two equal): ``fast`` (every network ships it) and
#: ``paper`` (the seed's sizes; JPEG-Hance ships it, Depth-Net does not).
NETWORK_PRESETS = ("fast", "paper")
HANCE_MODES = ("auto", "on", "off")
# "auto" runs JPEG-Hance only up to this JPEG quality per preset, where it was measured to
# beat what it replaces. Both presets are trained on real views after the post-filter, then
# fine-tuned on the decoded LF, and judged on scenes they were not trained on (seahorse,
# cotton, lytro_translucent; bench/networks.py). fast (four blocks at 0.617 of their trained
# correction, 2026-11-28): on the decoded LF at q30/40/50/60/70/80/90 seahorse +0.29/+0.33/
# +0.22/+0.27/+0.20/+0.26/+0.01 dB, cotton +0.25..+0.32, lytro_translucent +0.12/+0.11/+0.11/
# +0.10/+0.09/+0.07/+0.04, MSSIM higher on each (the two-block network it replaced lost on
# seahorse from q50: -0.07 / -0.21 dB at q50 / q70). paper (2026-11-27): centre views +0.19..+1.65
# dB at q10..q60, -0.00..+0.70 at q70, -1.39..+0.17 at q90; the decoded LF at q30/50/70
# seahorse +0.53/+0.30/-0.04 dB, cotton +0.68/+0.65/+0.60, lytro_translucent +0.32/+0.22/+0.10.
HANCE_MAX_QUALITY = {"fast": 80, "paper": 60}
#: Presets "auto" runs on a CUDA device only: on a CPU even the fast network costs about twice
#: the rest of a 7x7 decode, which would lose the decoder's lead over HEVC;
#: ``hance="on"`` runs it anywhere, and "auto" too on a stream with the encoder's strength maps
#: (:data:`lfstream.codec.centre.hance.HANCE_MAP_PRESET`), whose encoder measured where it helps.
HANCE_AUTO_GPU_ONLY = ("fast", "paper")
#: Frames per batch the decoder accepts (the networks and a CUDA warp run once a batch), in
#: ``decode`` and ``stream`` alike: 64 frames of 7x7x375x540 views are 1.9 GB.
BATCH_RANGE = (1, 64)
#: Residual bits per coded pixel from which the warp leaves the residual's decode a core
#: while it runs (:func:`lfstream.codec.warp.cpu.warp_views`'s ``beside``). Below it the decode
#: (dav1d, one thread) is nearly done when the warp starts, and handing it a core gained
#: nothing: the synthetic clip's rate-control streams, alternating processes, 8 rounds,
#: 0.0045 and 0.0086 bits a pixel (0.01 and 0.02 bpp) 1.02 and 1.03-1.05x, within the
#: noise; 0.026 and 0.056 (0.04 and 0.08 bpp) 0.93 and 0.84x, lytro_bikes at 0.12 0.84x.
BESIDE_MIN_BITS = 0.015
#: Threads that decode a batch's centre views (JPEG decode and post-filter, or AV1) side by
#: side: the cores. With the warp on a GPU the centre views one after another were most of a
#: batch's time; OpenCV's filter already uses every core for a JPEG. Batches of one are decoded inline.
CENTRE_WORKERS = max(1, os.cpu_count() or 1)


@dataclass
class DecodedFrame:
    """A decoded frame with the intermediate results users ask for."""

    seq: int
    timestamp_us: int
    lf: np.ndarray  # (U, V, H, W, 3) uint8
    centre: np.ndarray  # (H, W, 3) uint8, the decoded centre view
    disparity: np.ndarray  # (H, W) float32 centre-view disparity the warp used
    axes: np.ndarray | None = None  # (2, 2) view axes the disparity moves along; None: the convention
    gains: np.ndarray | None = None  # (U, V, gh, gw, 1 or 3) shading gains the views carry; None: none


def _settle(jobs: list[Future | None]) -> None:
    """Cancels the jobs not started and waits for the running ones, their outcome unread."""
    running = [j for j in jobs if j is not None and not j.cancel()]
    if running:
        wait(running)


@dataclass
class Decoder:
    """Decodes packets of one stream: JPEG decode -> JPEG-Hance -> disparity -> warp.

    Attributes:
        header: the stream's header.
        depth: ``"auto"`` (the hint where the stream has one, else flat), ``"hint"``,
            ``"flat"`` or ``"net"`` (Depth-Net: on a stream with a hint, the fast preset
            refines it; on one without, the seed's path, the disparity from the restored
            centre view alone, :mod:`lfstream.models.centre_depth`).
        occlusion: occlusion-aware per-view disparity in the warp (hint mode).
        hance: ``"auto"`` (JPEG-Hance where it helps: a JPEG centre view at quality <=
            HANCE_MAX_QUALITY[preset], on a CUDA device for :data:`HANCE_AUTO_GPU_ONLY`;
            or, on any device, a stream with the encoder's strength maps for ``preset``,
            ``Encoder(hance_map=True)``), ``"on"`` or ``"off"``.
        device: where the networks run (``"cpu"`` or ``"cuda"``); on a CUDA device a batch's
            frames are also warped there together (:attr:`warps_on_device`).
        preset: network preset whose shipped weights are used (:data:`NETWORK_PRESETS`).
        deblock: the post-filter of JPEG centre views (:func:`lfstream.codec.centre.jpeg.post_filter_jpeg`:
            strength from each JPEG's own quantisation table, the filter the encoder named
            in it) where JPEG-Hance does not run (a network gets the filter it was trained
            after). It is part of the prediction a residual layer corrects, so ``False``
            decodes a residual stream's prediction alone.
        precision: the networks' inference precision, ``"auto"`` (bfloat16 on a CPU that
            has it natively, float32 elsewhere), ``"float32"`` (the same bytes on every
            machine whose float32 kernels agree) or ``"bfloat16"``
            (:func:`lfstream.models.device.inference_precision`).
        depth_net: with ``depth="net"``, this network instead of the shipped weights (a
            training run's checkpoint, for evaluation tools).
    """

    header: StreamHeader
    depth: str = "auto"
    occlusion: bool = True
    hance: str = "auto"
    device: str = "cpu"
    preset: str = "fast"
    deblock: bool = True
    precision: str = "auto"
    depth_net: object | None = None  # torch.nn.Module

    def __post_init__(self) -> None:
        from lfstream.models.device import check_precision  # torch-free

        check_precision(self.precision)
        if self.depth not in DEPTH_MODES:
            raise LFValueError(f"depth: one of {', '.join(DEPTH_MODES)}, got {self.depth!r}")
        if self.hance not in HANCE_MODES:
            raise LFValueError(f"hance: one of {', '.join(HANCE_MODES)}, got {self.hance!r}")
        if self.preset not in NETWORK_PRESETS:
            raise LFValueError(f"preset: one of {', '.join(NETWORK_PRESETS)}, got {self.preset!r}")
        from lfstream.models.device import check_device

        self.device = check_device(self.device)
        if self.depth == "hint" and not self.header.has_hint:
            raise LFValueError("depth='hint': this stream carries no depth hint (encode with depth_hint=True)")
        # JPEG-Hance is trained on JPEG artefacts: "auto" never runs it on an AV1 centre view,
        # nor where a residual layer corrects the prediction without it
        jpeg_alone = self.header.codec == CODEC_JPEG and not self.header.has_residual
        use_hance = self.hance == "on" or (self.hance == "auto" and jpeg_alone and (
            self.header.meta.get("hance_map") == self.preset  # the encoder measured where it helps
            or (self.header.quality <= HANCE_MAX_QUALITY.get(self.preset, 0)
                and (self.preset not in HANCE_AUTO_GPU_ONLY or str(self.device).startswith("cuda")))))
        self._hance = None
        if use_hance:  # torch is imported only when a network runs
            from lfstream.models.registry import load_model

            self._hance = load_model("jpeg_hance", self.preset, self.device)
        self._hints = HintDecoder()
        self._last_disparity: np.ndarray | None = None
        self._last_axes: np.ndarray | None = None
        self.hint_fallbacks = 0  # delta hints whose reference frame never arrived
        self._gain_maps = GainDecoder()
        self._last_gains: np.ndarray | None = None
        self.gain_fallbacks = 0  # delta gain maps whose reference frame never arrived
        self.residual_skipped = 0  # residual layers not applied: this decoder's prediction is not their reference
        self._depth_net = None
        self._view_maps: np.ndarray | None = None  # Depth-Net's per-view maps, reused (_decode_batch)
        if self.depth == "net":
            from lfstream.models.registry import REGISTRY, load_model

            if self.depth_net is not None:
                self._depth_net = self.depth_net.to(self.device).eval()
            elif not self.header.has_hint and ("depth_centre", self.preset) in REGISTRY:
                # the seed's path: the disparity from the restored centre view alone
                self._depth_net = load_model("depth_centre", self.preset, self.device)
            else:
                self._depth_net = load_model("depth_net", self.preset, self.device)
                if self._depth_net.config.hint and not self.header.has_hint:
                    raise LFValueError("depth='net': the shipped Depth-Net refines the encoder's depth hint and this "
                                       "stream carries none (encode with --depth-hint, or decode with --depth flat)")

    @property
    def uses_hance(self) -> bool:
        return self._hance is not None

    @property
    def applies_residual(self) -> bool:
        """Whether a residual layer is added: only to the prediction the encoder computed it
        against — the hint's warp (the flat one for a stream without a hint), occlusion-aware,
        with the gains, without JPEG-Hance, a JPEG centre view post-filtered. ``depth="flat"``/
        ``"net"``, ``hance="on"`` or ``deblock=False`` on a JPEG stream decode the prediction
        alone (counted in :attr:`residual_skipped`). A residual of mode ``views``/``half-views``
        is applied whatever the settings: it replaces the views (:meth:`_views_only`)."""
        reference_depth = "hint" if self.header.has_hint else "flat"
        return (self.header.has_residual and self.depth in ("auto", reference_depth) and self.occlusion
                and self._hance is None and (self.deblock or self.header.codec != CODEC_JPEG))

    def decode_packet(self, packet: Packet) -> DecodedFrame:
        return self.decode_batch([packet])[0]

    @property
    def uses_depth_net(self) -> bool:
        """Whether frames get Depth-Net's per-view disparities (``depth="net"``)."""
        return self._depth_net is not None

    @property
    def runs_networks(self) -> bool:
        """Whether decoding runs a network (JPEG-Hance or Depth-Net), hence torch."""
        return self.uses_hance or self.uses_depth_net

    @property
    def network_precision(self) -> str | None:
        """What the networks' inference runs in here, ``"float32"`` or ``"bfloat16"``
        (:attr:`precision` resolved on :attr:`device`); ``None`` where no network runs."""
        if not self.runs_networks:
            return None
        from lfstream.models.device import inference_bfloat16

        return "bfloat16" if inference_bfloat16(self.device, self.precision) else "float32"

    @property
    def estimates_depth(self) -> bool:
        """Whether frames get a disparity of their own (hint or Depth-Net), not flat."""
        return self.depth in ("hint", "net") or (self.depth == "auto" and self.header.has_hint)

    def decode_centres(self, packets: list[Packet]) -> np.ndarray:
        """Centre-view decode (JPEG or AV1) and, where enabled, JPEG-Hance, batched.

        Shape:
            - output: ``(B, H, W, 3)`` uint8
        """
        # a network trained on post-filtered views gets them filtered whatever `deblock` says,
        # with the filter the stream names: trained after the default one, JPEG-Hance fast
        # still does better from the named one where the encoder chose another (seahorse q50
        # centre view: 45.66 dB from the named filter's 45.34, 45.56 from the default's 44.84)
        filtered = (self.deblock if self._hance is None else self._hance.config.after_deblock) \
            and self.header.codec == CODEC_JPEG

        def centre_of(p: Packet) -> np.ndarray:
            centre = decode_centre(p.image, self.header.codec, self.header.size, p.seq)
            return post_filter_jpeg(centre, p.image, p.seq) if filtered else centre

        workers = min(len(packets), CENTRE_WORKERS)
        if workers > 1:  # OpenCV and dav1d release the GIL: a batch's frames decode side by side
            with ThreadPoolExecutor(workers, thread_name_prefix="lfstream-centre") as pool:
                centres = np.stack(list(pool.map(centre_of, packets)))
        else:
            centres = np.stack([centre_of(p) for p in packets])
        if self._hance is not None:
            from lfstream.models.jpeg_hance import restore_images

            restored = restore_images(centres, self._hance, self.device, self.precision)
            if self.preset == HANCE_MAP_PRESET and self.header.codec == CODEC_JPEG:
                # the encoder's strength map (measured for this preset's network), where the
                # stream carries one: the correction blended in per tile (jpeg.hance_map)
                for k, p in enumerate(packets):
                    levels = hance_map(p.image, p.seq)
                    if levels is not None:
                        restored[k] = blend_restored(centres[k], restored[k], hance_strength(levels, centres.shape[1:3]))
            centres = restored
        return centres

    def reconstruct(self, packet: Packet, centre: np.ndarray, disparity: np.ndarray) -> DecodedFrame:
        """Warps a decoded centre view by a given centre-view disparity (occlusion-aware) and
        applies the packet's shading gains; also serves callers that reuse a disparity (the
        packet's hint is still read, so later delta hints can refer to it). A residual layer
        is added too: with a reused disparity the result differs from a full decode by what
        the two predictions differ (the stream's static skip audits that)."""
        return self._add_residual(packet, self._warp(packet, centre, disparity, self._read_hint(packet)))

    def follow(self, packet: Packet) -> None:
        """Reads ``packet``'s hint and gain maps into this decoder's references without
        reconstructing its frame, so that the deltas of the packets after it resolve as after
        a full decode (the encoder's strength map follows its own stream this way between the
        frames it measures: a JPEG centre without a residual layer, whose views are all the
        state a packet leaves besides these)."""
        self._read_hint(packet)
        self._gains(packet)

    def _read_hint(self, packet: Packet) -> np.ndarray | None:
        """Parses the packet's hint (remembered for later deltas) where the frames get a
        disparity; the view axes it names, else the last ones."""
        if packet.hint and self.estimates_depth:
            try:
                self._last_axes = self._hints.parse(packet.hint, self.header.size, packet.seq).axes
            except HintReferenceError:
                self.hint_fallbacks += 1
        return self._last_axes

    @staticmethod
    def _views_only(packet: Packet) -> bool:
        """Whether the packet's residual carries the views themselves: then there is nothing
        to predict (the warp is skipped) and nothing the settings could leave out."""
        return residual_mode(packet.residual) in VIEW_MODES

    def _residual_applies(self, packet: Packet) -> bool:
        return bool(packet.residual) and (self.applies_residual or self._views_only(packet))

    def _long_residual(self, packet: Packet) -> bool:
        """Whether the packet's residual holds at least :data:`BESIDE_MIN_BITS` bits a coded
        pixel (its decode then outlasts the work before the warp)."""
        u, v = self.header.views
        h, w = self.header.size
        return 8 * len(packet.residual) >= BESIDE_MIN_BITS * max(1, u * v - 1) * h * w

    def _residual_centre(self, packet: Packet) -> bytes | None:
        """What a views sequence may start with: the centre payload's key frame (format 4)."""
        return packet.image if self.header.codec == CODEC_AV1 else None

    def _start_residuals(self, packets: list[Packet]) -> list[Future | None]:
        """Each packet's residual layer decoding (dav1d) on a worker thread, started before the
        centre view, the hint and the warp, which it does not depend on (``None`` where none
        is applied)."""
        from lfstream.codec.workers import in_background, on_worker_thread

        if on_worker_thread():  # decoded inline there: a worker must not wait on the pool
            return [None] * len(packets)
        return [in_background(lambda p=p: decode_residual(p.residual, self.header.views, self.header.size, p.seq,
                                                          self._residual_centre(p)))
                if self._residual_applies(p) else None for p in packets]

    def _add_residual(self, packet: Packet, frame: DecodedFrame, planes: Future | None = None) -> DecodedFrame:
        """``frame`` with the packet's residual layer where it applies; ``planes``: its
        decoding started by :meth:`_start_residuals` (a future), else decoded here."""
        if self._residual_applies(packet):
            apply_residual(frame.lf, packet.residual, packet.seq, self._residual_centre(packet),
                           planes=None if planes is None else planes.result())
        elif packet.residual:
            self.residual_skipped += 1
        return frame

    def _hint_disparity(self, packet: Packet, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The packet's hint, decoded, and its view axes; where it is a delta to a frame that
        never arrived (a lossy transport), the last disparity this decoder produced stands
        in until the next key hint (counted in :attr:`hint_fallbacks`)."""
        h, w = self.header.size
        try:
            d, self._last_axes = self._hints.decode_with_axes(packet.hint, (h, w), guide=centre, frame=packet.seq)
        except HintReferenceError:
            self.hint_fallbacks += 1
            d = self._last_disparity if self._last_disparity is not None else np.zeros((h, w), np.float32)
        self._last_disparity = d
        return d, self._last_axes

    def _gains(self, packet: Packet) -> np.ndarray | None:
        """The packet's gain maps; where they are a delta to a frame that never arrived, the
        last maps this decoder decoded stand in until the next key map (counted in
        :attr:`gain_fallbacks`)."""
        if not packet.gain:
            return None
        try:
            self._last_gains = self._gain_maps.decode(packet.gain, self.header.views, packet.seq)
        except GainReferenceError:
            self.gain_fallbacks += 1
        return self._last_gains

    def _warp(self, packet: Packet, centre: np.ndarray, disparity: np.ndarray,
              axes: np.ndarray | None = None, beside: Future | None = None,
              out: np.ndarray | None = None) -> DecodedFrame:
        """The prediction of the views (or, for a residual of the views themselves, the
        centre alone); ``beside``: the packet's residual decoding, which the warp leaves a
        core while it runs (:func:`lfstream.codec.warp.cpu.warp_views`); ``out``: the array the
        views go into (:meth:`decode_batch`)."""
        if self._views_only(packet):  # the residual replaces every view but the centre
            u, v = self.header.views
            lf = np.empty((u, v, *centre.shape), np.uint8) if out is None else out
            lf[u // 2, v // 2] = centre
            return DecodedFrame(packet.seq, packet.timestamp_us, lf, centre, disparity, axes)
        # the warp kernel multiplies the gains in as it samples (no second pass over the views)
        gains = self._gains(packet)
        lf = warp_views(centre, disparity, self.header.views, occlusion=self.occlusion, gains=gains, axes=axes,
                        beside=beside, out=out)
        return DecodedFrame(packet.seq, packet.timestamp_us, lf, centre, disparity, axes, gains)

    @property
    def warps_on_device(self) -> bool:
        """Whether a batch's frames are warped together as tensor operations on :attr:`device`
        (:func:`lfstream.codec.warp.batched.warp_views_batched`: a CUDA device; the same bytes
        as the CPU kernel without gains, within a level on a few samples with them) rather
        than one by one in the fused CPU kernel."""
        return self.device.startswith("cuda")

    def _warp_on_device(self, packets: list[Packet], centres: np.ndarray, disparities: list[np.ndarray],
                        axes: list[np.ndarray | None]) -> list[DecodedFrame] | None:
        """:meth:`_warp` for a batch in one call on :attr:`device`; ``None`` (decided before
        any gain map is read) where the batch does not share one warp: view axes that
        differ, or a residual that replaces the views."""
        if any(self._views_only(p) for p in packets):
            return None
        first = axes[0]
        if any((a is None) != (first is None) or (a is not None and not np.array_equal(a, first)) for a in axes):
            return None
        import torch

        from lfstream.codec.warp.batched import warp_views_batched

        gains = [self._gains(p) for p in packets]
        shapes = {g.shape for g in gains if g is not None}
        if len(shapes) > 1:  # grids that differ: each frame with its own maps, on the CPU kernel
            lfs = [warp_views(c, d, self.header.views, occlusion=self.occlusion, gains=g, axes=first)
                   for c, d, g in zip(centres, disparities, gains)]
        else:
            dev = torch.device(self.device)
            stacked = None
            if shapes:  # frames without maps get ones: warped without gains, as the kernel does
                shape = next(iter(shapes))
                stacked = torch.from_numpy(np.stack([g if g is not None else np.ones(shape, np.float32)
                                                     for g in gains])).to(dev)
            warped = warp_views_batched(torch.from_numpy(np.ascontiguousarray(centres)).to(dev),
                                        torch.from_numpy(np.stack(disparities)).to(dev), self.header.views,
                                        occlusion=self.occlusion, gains=stacked, axes=first)
            lfs = list(_to_host(warped))
        return [DecodedFrame(p.seq, p.timestamp_us, lf, c, d, first, g)
                for p, lf, c, d, g in zip(packets, lfs, centres, disparities, gains)]

    def decode_batch(self, packets: list[Packet], centres: np.ndarray | None = None,
                     out: list[np.ndarray | None] | None = None) -> list[DecodedFrame]:
        """Decodes several packets; the networks run once over the batch. ``centres``: the
        output of :meth:`decode_centres` for these packets, when the caller already has it.
        ``out``: per packet, the ``(U, V, H, W, 3)`` uint8 C-contiguous array its views go
        into (a frame of the caller's video array, e.g. :func:`decode`'s: the CPU warp
        writes there, other paths are copied there), or ``None``: a new array."""
        if not packets:
            return []
        dests = [None] * len(packets) if out is None else list(out)
        if len(dests) != len(packets):
            raise LFValueError(f"out: one array (or None) per packet, got {len(dests)} for {len(packets)}")
        residuals = self._start_residuals(packets) if self._depth_net is None else [None] * len(packets)
        try:
            frames = self._decode_batch(packets, centres, dests, residuals)
        except BaseException:
            # a frame that fails (a damaged centre view, a hint) leaves no residual decode
            # behind: queued ones are cancelled and running ones waited for, so a run of
            # damaged streams cannot pile work up on the worker threads
            _settle(residuals)
            raise
        for f, dest in zip(frames, dests):
            if dest is not None and f.lf is not dest:  # a path that does not write in place
                dest[...] = f.lf
                f.lf = dest
        return frames

    def _decode_batch(self, packets: list[Packet], centres: np.ndarray | None,
                      out: list[np.ndarray | None], residuals: list[Future | None]) -> list[DecodedFrame]:
        h, w = self.header.size
        if centres is None:
            centres = self.decode_centres(packets)
        hints: list[np.ndarray | None] = []
        axes: list[np.ndarray | None] = []
        centre_net = self._depth_net is not None and not self._depth_net.config.hint
        for p, centre in zip(packets, centres):
            use_hint = (self.depth == "hint" or (self.depth == "net" and not centre_net)
                        or (self.depth == "auto" and p.hint))
            if use_hint and not p.hint:
                raise BitstreamError("packet has no depth hint", p.seq)
            d, a = self._hint_disparity(p, centre) if use_hint else (None, None)
            hints.append(d)
            axes.append(a)
        views_only = all(self._views_only(p) for p in packets)
        if self._depth_net is None or centre_net or views_only:
            if centre_net and not views_only:
                # the seed's path: each frame's disparity from its restored centre view, then
                # the warp the hint's disparity goes through (a residual's reference is the flat
                # prediction: not applied, counted as skipped by _add_residual)
                from lfstream.models.centre_depth import predict_centre_disparity

                disparities = list(predict_centre_disparity(centres, self._depth_net, self.device, self.precision))
            else:
                disparities = [hint if hint is not None else np.zeros((h, w), np.float32) for hint in hints]
            frames = self._warp_on_device(packets, centres, disparities, axes) if self.warps_on_device else None
            if frames is None:
                frames = [self._warp(p, centre, d, a, r if r is not None and self._long_residual(p) else None, o)
                          for p, centre, d, a, r, o in zip(packets, centres, disparities, axes, residuals, out)]
            return [self._add_residual(p, frame, r) for p, frame, r in zip(packets, frames, residuals)]
        self.residual_skipped += sum(1 for p in packets if p.residual)
        from lfstream.models.depth_net import DepthRefiner, predict_view_disparities

        stacked = np.stack(hints) if self._depth_net.config.hint else None
        refines = isinstance(self._depth_net, DepthRefiner)  # a DepthNet makes its maps itself
        if refines and (self._view_maps is None or self._view_maps.shape[0] < len(packets)):
            # the per-view maps' array, kept from batch to batch: fresh, its 40 MB a 7x7x375x540
            # frame were 6-12 ms of page faults a frame, and tens where the kernel compacted
            # huge pages for them
            self._view_maps = np.empty((len(packets), *self.header.views, h, w), np.float32)
        view_maps = predict_view_disparities(centres, self._depth_net, self.header.views, stacked, self.device, axes,
                                             out=self._view_maps if refines else None, precision=self.precision)
        u0, v0 = self.header.views[0] // 2, self.header.views[1] // 2
        frames = []
        for p, centre, maps, a in zip(packets, centres, view_maps, axes):
            gains = self._gains(p)
            frames.append(DecodedFrame(p.seq, p.timestamp_us, warp_views_per_view(centre, maps, a, gains), centre,
                                       maps[u0, v0].copy(), a, gains))  # a copy: the maps' array is reused
        return frames


def _to_host(tensor) -> np.ndarray:
    """A device tensor's values as a numpy array. From a CUDA device through page-locked memory
    from torch's caching host allocator: a batch's light fields (30 of 7x7x375x540: 893 MB)
    copied into fresh pageable memory took 688 ms on an H100 machine (2026-11-25), into a
    block of that allocator 31 ms (2026-11-27); once the frames of a batch are released, the
    next batch reuses their block. Elsewhere ``.cpu()``."""
    import torch

    if tensor.device.type != "cuda":
        return tensor.cpu().numpy()
    try:
        host = torch.empty(tensor.shape, dtype=tensor.dtype, pin_memory=True)
    except RuntimeError:  # page-locked memory refused (its limit, or a huge batch): the plain copy
        return tensor.cpu().numpy()
    host.copy_(tensor)
    return host.numpy()


__all__ = ["DEPTH_MODES", "NETWORK_PRESETS", "HANCE_MODES", "HANCE_MAX_QUALITY", "BATCH_RANGE", "BESIDE_MIN_BITS", "Decoder",
           "DecodedFrame"]
