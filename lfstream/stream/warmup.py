"""Loading the compiled kernels before a run is timed.

numba compiles each kernel once and caches it on disk, but every process still loads each
cached kernel on its first call (tens to hundreds of milliseconds apiece, about a second
for a stream's whole set on the development machine). A stream's frames/s should measure
its frames, and ``--refocus auto`` should time its candidates warm, so the pipeline first
runs the same code paths (the same argument types, hence the same compiled signatures) on
a tiny light field; the summary reports the time as ``warmup_s``, apart from ``wall_s``.
"""

from __future__ import annotations

import numpy as np

from lfstream.stream.config import StreamConfig

#: The light field the warm-up runs: 3 x 3 views of 24 x 32 pixels (:func:`warmup_lf`).
WARMUP_SHAPE = (3, 3, 24, 32, 3)


def warmup_lf() -> np.ndarray:
    """The warm-up's light field: a texture seen with one pixel of parallax per view step
    and a brightness that differs between views, so that the encoder sends a hint and gain
    maps and the decoder's occlusion-aware warp runs with both (identical views would leave
    the warp, its splat test and the gains' kernels unloaded: a flat hint decodes by copies).

    Shape:
        - output: ``WARMUP_SHAPE`` uint8
    """
    u, v, h, w, _ = WARMUP_SHAPE
    yy, xx = np.mgrid[0:h + u, 0:w + v]
    texture = 128 + 60 * np.sin(xx * 0.9) * np.cos(yy * 0.7) + 40 * ((xx // 5 + yy // 4) % 2)
    lf = np.empty(WARMUP_SHAPE, np.uint8)
    for a in range(u):
        for b in range(v):
            gain = 1.0 - 0.08 * (abs(a - u // 2) + abs(b - v // 2))  # vignetting: darker away from the centre
            view = texture[a:a + h, b:b + w] * gain
            lf[a, b] = np.clip(view, 0, 255).astype(np.uint8)[..., None]
    return lf


def warm_kernels(config: StreamConfig, decode: bool = True) -> None:
    """Runs the encoder, decoder, focal stack and metrics of ``config`` once on a tiny light
    field (:func:`warmup_lf`), so that their kernels are loaded, and the decoder's networks
    where the stream runs any (JPEG-Hance, Depth-Net: torch's import and their first call),
    and imports the sink's video library when the stream writes videos. One frame serves
    read-only sources (the built-in clip) and writable ones (files, videos) alike: the
    kernels take their inputs read-only (:func:`lfstream.lightfield.read_only`;
    tests/stream checks both kinds of source). ``decode=False`` (a stream that ends at the
    transport) stops after the encoder; a stream that starts at the transport still encodes
    the tiny frame, to have a packet to decode."""
    u, v, h, w, _ = WARMUP_SHAPE
    if any(kind in config.save for kind in ("mp4", "mp4-lossless", "sweep", "lf")):
        import av  # noqa: F401 - the sink's video library: ~0.1 s to import, paid here once
    from lfstream.codec.decoder import Decoder

    lf = warmup_lf()
    encoder = config.encoder()
    packet = encoder.encode_frame(lf, 0, 0)
    if not decode:
        return
    header = encoder.header((u, v), (h, w), config.fps)
    # on the stream's device, so that a CUDA stream starts its context and its warp kernels
    # (Triton) here, not in the first timed frame (a frame of another size may still need
    # its own compile: Triton specialises on sizes)
    decoded = Decoder(header, depth="hint" if header.has_hint else "flat", hance="off",
                      device=config.device).decode_packet(packet)
    from lfstream.metrics import mpsnr, mssim
    from lfstream.refocus import focal_stack

    if config.refocus in ("auto", "sas"):
        focal_stack(decoded.lf, slopes=[-0.5, 0.0, 0.5])
    if config.metrics:
        mpsnr(lf, decoded.lf)
        if config.mssim_every:
            mssim(lf, decoded.lf)
    # last, as a stream without a hint refuses depth "net" (its stage reports that): the
    # networks the stream's decoder runs (hance "on", depth "net"; "auto" decides on the
    # warm-up's header, coded by the stream's encoder settings), so that torch's import
    # (0.8 s here) and their first call are not paid by the first frame inside the timed
    # run (the built-in clip with both: 3.6-4.1 frames/s with them in it, 4.6-5.3 without)
    networks = Decoder(header, depth=config.depth, hance=config.hance, device=config.device)
    if networks.runs_networks:
        networks.decode_packet(packet)


__all__ = ["WARMUP_SHAPE", "warmup_lf", "warm_kernels"]
