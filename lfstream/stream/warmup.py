"""Loading the compiled kernels before a run is timed.

numba compiles each kernel once and caches it on disk, but every process still loads each
cached kernel on its first call (tens to hundreds of milliseconds apiece, about a second
for a stream's whole set on the development machine). A stream's frames/s should measure
its frames, and ``--refocus auto`` should time its candidates warm, so the pipeline first
runs the same code paths (the same argument types, hence the same compiled signatures) on
a tiny light field; the summary reports the time as ``warmup_s``, apart from ``wall_s``.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

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


#: The modules whose numba kernels a stream compiles: their source stamps key the marker
#: that says they were compiled here before (:func:`_compiled_marker`).
KERNEL_MODULES = ("codec/_numba.py", "codec/warp/kernels.py", "codec/warp/splat_kernels.py", "codec/hint/kernels.py",
                  "codec/gains_kernels.py", "codec/residual_kernels.py", "codec/centre/hance_kernels.py", "codec/_entropy.py",
                  "refocus/_kernels.py", "_kernels.py")


def _compiled_marker() -> Path | None:
    """The file whose existence says a stream's kernels were compiled on this machine for
    these sources, numba and Python (numba caches each kernel on disk; this only decides
    whether compiling is likely); ``None`` where lfstream keeps no cache folder."""
    from lfstream.stream.sources import cache_dir

    folder = cache_dir()
    if folder is None:
        return None
    import numba

    root = Path(__file__).resolve().parents[1]
    key = hashlib.sha256(f"{numba.__version__} {sys.version} {root}".encode())
    for name in KERNEL_MODULES:
        try:
            st = (root / name).stat()
        except OSError:
            return None
        key.update(f" {name} {st.st_mtime_ns} {st.st_size}".encode())
    return folder / f"kernels-{key.hexdigest()[:16]}.compiled"


#: Seconds the warm-up waits for :func:`compile_beside`'s child (many times its usual compile
#: time) before it stops it and compiles the rest itself.
CHILD_COMPILE_TIMEOUT_S = 300


def compile_beside(warp: bool, focal: bool) -> subprocess.Popen | None:
    """Starts a child process that compiles the decoder's warp and the focal stack
    (:func:`compile_warp_and_focal_stack`: the two slowest kernels to compile) while this
    process compiles the encoder's and the metrics': numba caches what either compiles on disk, and each then loads the
    other's. Only where the kernels look uncompiled (no :func:`_compiled_marker`): a warm
    start would pay the child's imports for nothing. ``None`` where it is not started (or
    cannot be: the warm-up then compiles everything itself, as before)."""
    marker = _compiled_marker()
    if not (warp or focal) or marker is None or marker.exists():
        return None
    root = str(Path(__file__).resolve().parents[2])  # the folder lfstream is imported from
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p))
    code = f"from lfstream.stream.warmup import compile_warp_and_focal_stack; compile_warp_and_focal_stack({warp}, {focal})"
    try:
        return subprocess.Popen([sys.executable, "-c", code], env=env, stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        return None


def compile_warp_and_focal_stack(warp: bool = True, focal: bool = True) -> None:
    """Runs the decoder's warp (occlusion and gains: every branch of the fused kernel) and
    the focal stack on the warm-up light field, with the argument types the stream's
    decoder and refocus stage give them, so that numba compiles and caches those kernels
    (what :func:`compile_beside`'s child does; tests/stream checks the stream then compiles
    neither again)."""
    from lfstream.codec.warp.cpu import warp_views
    from lfstream.refocus import focal_stack

    lf = warmup_lf()
    u, v, h, w, _ = lf.shape
    views = lf
    if warp:
        centre = np.ascontiguousarray(lf[u // 2, v // 2])
        disparity = np.linspace(-1.0, 1.0, h * w, dtype=np.float32).reshape(h, w)
        gains = np.full((u, v, 2, 3, 3), 1.05, np.float32)
        views = warp_views(centre, disparity, (u, v), occlusion=True, gains=gains)
    if focal:
        focal_stack(views, slopes=[-0.5, 0.0, 0.5])


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
    if any(kind in config.save for kind in ("mp4", "mp4-lossless", "sweep", "lf")):
        import av  # noqa: F401 - the sink's video library: ~0.1 s to import, paid here once
    # where the kernels were not compiled yet (a first run), the warp and the focal stack
    # compile in a child process meanwhile
    child = compile_beside(warp=decode and config.device == "cpu",
                           focal=decode and config.refocus in ("auto", "sas"))
    try:
        _warm(config, decode, child)
    finally:
        if child is not None and child.poll() is None:  # Ctrl-C, or an error here
            child.kill()
            child.wait()
    marker = _compiled_marker()
    if marker is not None and not marker.exists():
        try:
            marker.touch()
        except OSError:
            pass


def _warm(config: StreamConfig, decode: bool, child: subprocess.Popen | None) -> None:
    """:func:`warm_kernels`' work; with ``child`` (:func:`compile_beside`) the metrics first,
    then its end awaited before the warp and the focal stack run here (then loaded from
    its cache, not compiled again)."""
    from lfstream.codec.decoder import Decoder
    from lfstream.metrics import mpsnr, mssim

    u, v, h, w, _ = WARMUP_SHAPE
    lf = warmup_lf()
    encoder = config.encoder()
    packet = encoder.encode_frame(lf, 0, 0)
    from lfstream.codec.hint import warm_axes_fit

    warm_axes_fit()  # the tiny frame's axes detection stops before its fit (rate control may hint too)
    if not decode:
        return
    if child is not None:
        if config.metrics:  # the same argument types as against the decoded views below
            mpsnr(lf, lf.copy())
            if config.mssim_every:
                mssim(lf, lf.copy())
        try:
            child.wait(timeout=CHILD_COMPILE_TIMEOUT_S)
        except subprocess.TimeoutExpired:  # never a hang: this process compiles what it needs itself
            child.kill()
            child.wait()
    header = encoder.header((u, v), (h, w), config.fps)
    # on the stream's device, so that a CUDA stream starts its context and its warp kernels
    # (Triton) here, not in the first timed frame (a frame of another size may still need
    # its own compile: Triton specialises on sizes)
    decoded = Decoder(header, depth="hint" if header.has_hint else "flat", hance="off",
                      device=config.device).decode_packet(packet)
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
    # run
    networks = Decoder(header, depth=config.depth, hance=config.hance, device=config.device, preset=config.networks)
    if networks.runs_networks:
        networks.decode_packet(packet)


__all__ = ["WARMUP_SHAPE", "KERNEL_MODULES", "warmup_lf", "warm_kernels", "compile_beside", "compile_warp_and_focal_stack"]
