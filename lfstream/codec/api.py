"""The codec's entry point for arrays: :func:`encode` (``lfstream.encode``), above the
encoder and rate control it configures (the decoder's is :func:`lfstream.codec.decoder.decode`)."""

from __future__ import annotations

import io

import numpy as np

from lfstream.codec.bitstream import Packet, StreamWriter, with_present
from lfstream.codec.encoder import DEFAULT_PRESET, Encoder, frames_of
from lfstream.codec.hint import HintOptions
from lfstream.codec.rate import (
    RATE_CONTROL_CHOOSES,
    choose_default,
    choose_rate,
    rate_control_conflict,
    uses_default_choice,
)
from lfstream.errors import LFStreamError, LFValueError
from lfstream.lightfield import check_lf


def encode(
    lf: np.ndarray,
    quality: int = 50,
    depth_hint: bool = True,
    fps: float = 30.0,
    hint_options: HintOptions | None = None,
    gain_grid: int = 4,
    present: np.ndarray | None = None,
    bpp: float | None = None,
    preset: str | None = None,
    residual: int | None = None,
    residual_mode: str = "prediction",
    post_filter: bool = True,
    device: str = "cpu",
    hance_map: bool = False,
) -> bytes:
    """Encodes one light field or an LF video to ``.lfs`` bytes.

    With no ``preset``, ``bpp`` or ``residual`` named, the coding is chosen per stream
    (:func:`lfstream.codec.rate.choose_default`): the seed's JPEG centre view and the depth
    hint from 7x7 views up, an AV1 centre with fewer views, and the views coded as one AV1
    sequence keyed by the centre view where the first frame shows that warping cannot predict
    them; the hint at 1/8 of the view instead of 1/4 where the first frame shows it predicts
    the views as well for the bytes it saves. A named preset is used as it is.

    Args:
        lf: the light field(s), uint8 or float in ``[0, 1]``.
        quality: the centre view's quality, 1..100.
        depth_hint: send the depth hint (else the centre view alone).
        fps: the stream's frame rate.
        hint_options: the hint's sweep and coding (:class:`HintOptions`).
        gain_grid: cells per axis of the per-view gain maps.
        present: mask of the views that exist (the centre view must); recorded in the stream,
            whose decode leaves the missing views zero.
        bpp: a target size in bits per pixel instead of ``quality`` and ``depth_hint``: rate
            control (:mod:`lfstream.codec.rate`) picks the quality, the hint, the preset (unless
            ``preset`` names one) and the residual layer.
        preset: the centre view's coding (:data:`PRESETS`).
        residual: quality 1..100 of the residual layer (:mod:`lfstream.codec.residual`), ``None``
            for none.
        residual_mode: what the residual codes: ``prediction``, ``views`` or ``half-views``
            (:attr:`Encoder.residual_mode`).
        post_filter: name the decoder's JPEG post-filter the encoder measured best
            (:attr:`Encoder.post_filter`; ``False``: the default filter).
        device: where the hint's plane sweep runs (:attr:`Encoder.device`).
        hance_map: send a JPEG-Hance strength map with each JPEG centre view
            (:attr:`Encoder.hance_map`; not with ``bpp``).

    Returns:
        The ``.lfs`` stream (:mod:`lfstream.codec.bitstream`).

    Raises:
        LFStreamError: bad shape, dtype, non-finite values or parameters.

    Shape:
        - lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``
        - present: ``(U, V)``
    """
    try:
        frames = frames_of(np.asarray(lf) if not hasattr(lf, "numpy") else lf.cpu().numpy())
    except (TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, LFStreamError):
            raise
        raise LFValueError(f"lf: not an array ({exc})") from exc
    if bpp is not None:
        conflict = rate_control_conflict(residual, residual_mode, post_filter, hance_map)
        if conflict:
            raise LFValueError(f"{conflict}: rate control (bpp) {RATE_CONTROL_CHOOSES[conflict]}")
        # rate control encoded every frame already: its stream is the answer
        return choose_rate(frames, bpp, fps, present, hint_options, gain_grid, preset=preset).stream(present)
    first = None
    if uses_default_choice(preset, depth_hint, residual, residual_mode):
        check_lf(frames[0], allow_video=False)
        choice = choose_default(frames[0], quality, present, hint_options, gain_grid, post_filter=post_filter,
                                device=device)
        enc, first = choice.encoder, choice.first
        if hance_map:
            first = with_default_hance_map(enc, first, frames[0], present)
    else:
        enc = Encoder(quality=quality, depth_hint=depth_hint, hint_options=hint_options or HintOptions(),
                      gain_grid=gain_grid, preset=preset or DEFAULT_PRESET, residual=residual,
                      residual_mode=residual_mode, post_filter=post_filter, device=device, hance_map=hance_map)
    buf = io.BytesIO()
    writer = StreamWriter(buf, with_present(enc.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps), present))
    for t, frame in enumerate(frames):
        writer.write(first if t == 0 and first is not None else
                     enc.encode_frame(frame, t, int(round(t * 1e6 / fps)), present))
    return buf.getvalue()


def with_default_hance_map(encoder: Encoder, first: Packet | None, frame: np.ndarray,
                           present: np.ndarray | None = None) -> Packet | None:
    """The default encode (:func:`lfstream.codec.rate.choose_default`) with JPEG-Hance strength
    maps: where its ``encoder`` codes a JPEG centre view, it sends them from frame 0 on
    (``first``, the packet the choice coded, is marked; it is final: any coarser hint is in
    it); where the choice codes the views themselves (AV1), nothing changes."""
    if not encoder.takes_hance_map:
        return first
    encoder.hance_map = True
    return first if first is None else encoder.mark_hance(first, frame, present)


__all__ = ["encode", "with_default_hance_map"]
