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

#: The light field the warm-up runs: 3 x 3 views of 24 x 32 pixels, smooth values.
WARMUP_SHAPE = (3, 3, 24, 32, 3)


def warm_kernels(config: StreamConfig, decode: bool = True) -> None:
    """Runs the encoder, decoder, focal stack and metrics of ``config`` once on a tiny light
    field, so that their kernels are loaded (networks are not run: they load on their own),
    and imports the sink's video library when the stream writes videos.
    ``decode=False`` (a stream that ends at the transport) stops after the encoder; a stream
    that starts at the transport still encodes the tiny frame, to have a packet to decode."""
    u, v, h, w, c = WARMUP_SHAPE
    yy, xx = np.mgrid[0:h, 0:w]
    ramp = ((yy * 5 + xx * 3) % 256).astype(np.uint8)
    lf = np.ascontiguousarray(np.broadcast_to(ramp[None, None, :, :, None], (u, v, h, w, c)))
    if any(kind in config.save for kind in ("mp4", "mp4-lossless", "sweep", "lf")):
        import av  # noqa: F401 - the sink's video library: ~0.1 s to import, paid here once
    from lfstream.codec.decoder import Decoder

    encoder = config.encoder()
    packet = encoder.encode_frame(lf, 0, 0)
    if not decode:
        return
    header = encoder.header((u, v), (h, w), config.fps)
    # the networks are not warmed here (they load their weights when a decoder needs them)
    decoded = Decoder(header, depth="hint" if header.has_hint else "flat", hance="off").decode_packet(packet)
    from lfstream.metrics import mpsnr, mssim
    from lfstream.refocus import focal_stack

    if config.refocus in ("auto", "sas"):
        focal_stack(decoded.lf, slopes=[-0.5, 0.0, 0.5])
    if config.metrics:
        mpsnr(lf, decoded.lf)
        if config.mssim_every:
            mssim(lf, decoded.lf)


__all__ = ["WARMUP_SHAPE", "warm_kernels"]
