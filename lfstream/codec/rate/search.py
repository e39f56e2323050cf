"""Rate control's searches: every configuration coded to the target and measured.

The encoder's knobs are the preset (the centre view's codec: JPEG or AV1), its quality and
whether the depth hint is sent. The hint and the gain maps do not depend on the centre
view's coding, so they are computed once per frame; the size at every quality then costs
one centre-view encode per frame, and a search (:func:`_quality_bracket`: bisection's bracket
in fewer encodes) finds, for every preset with the hint and without it, the quality whose
stream is closest to the target. The candidates are decoded
on the first frame and the one with the higher MPSNR (over the views that exist) wins.

The residual layer (:mod:`lfstream.codec.residual`) is a candidate too: the centre view takes
a share of the target (:data:`RESIDUAL_SHARES`), the residual's quality is searched the same
way to fill the rest. Measured on lytro_bikes at 0.08 bpp, a centre view at about half the
budget was best (35.1 dB; a quarter 34.8, two thirds 35.0, nine tenths 34.1).

The last candidates code the views themselves as the residual's sequence (modes ``views`` and
``half-views``, :mod:`lfstream.codec.residual`): where warping cannot predict the scene they
are the better stream (toys_array), elsewhere the measurement leaves them out. A residual's or
the views' quality search stops at the first probe within :data:`PROBE_NEAR` of the target
(each probe is an AV1 sequence of every view).

``full`` (:func:`choose_configuration`) tries every preset, hint precision and family;
``quick`` (the ``fast`` preset's, :func:`_quick_configuration`) codes every frame once in the
default's configuration and searches the centre's quality. The model
(:mod:`lfstream.codec.rate.model`) replaces the full search by prediction.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader
from lfstream.codec.centre import CentreCoding, encode_centre
from lfstream.codec.centre.av1 import AV1_MIN_VIEW, av1_fits
from lfstream.codec.centre.jpeg import QUALITY_RANGE, PostFilterChooser
from lfstream.codec.encoder import PRESETS, RESIDUAL_SPEED, Encoder, residual_meta
from lfstream.codec.hint import HintOptions
from lfstream.codec.rate.common import (
    RATE_TOLERANCE,
    SEARCHED,
    RateChoice,
    _at_quality,
    _first_frame_mpsnr,
    _stream_bytes,
    validate_target,
)
from lfstream.codec.rate.default import PREDICTION_CHECK_MIN_CELLS, choose_default
from lfstream.codec.residual import VIEW_MODES, coded_size, encode_residual
from lfstream.errors import LFValueError
from lfstream.lightfield import centre_view, to_uint8

#: The second hint precision rate control tries (the default sends 1/4 resolution): at low
#: rates a 1/8 map costs a third of the bytes for 0.1-0.3 dB (measured on the shared samples).
COARSE_HINT_SCALE = 8


#: Shares of the target the centre view (with hint and gains) takes in residual candidates.
RESIDUAL_SHARES = (0.35, 0.55)


#: The preset of residual candidates when rate control may choose (AV1 centre and residual
#: at SVT-AV1 preset 8: the best measured quality per byte).
RESIDUAL_PRESET = "best"


#: The quick search adds the residual layer where the centre view alone needs a quality above
#: this: past it a JPEG spends its bits on a view the warp then blurs (lytro_bikes at 0.08
#: bpp: q96 alone 33.17 dB, q88 with a residual 34.85; at 0.04 q85 alone loses 0.38 dB MPSNR
#: to a residual but wins 0.014 MSSIM).
QUICK_MAX_CENTRE_QUALITY = 90


#: ... and tries the hint at twice the scale and no hint where the hint takes at least this
#: share of the target (lytro_bikes at 0.005 and 0.01 bpp, where the 1/4 hint is 53-100 % of
#: the target: the 1/8 one gives +0.4...+2.2 dB; cotton at 0.01: no hint +4.3 dB).
QUICK_HINT_SHARE = 0.2


#: Both searches take the first residual (or views) quality whose stream lands within this
#: share of the target instead of bracketing the nearest: each probe is an AV1 sequence of
#: every view. Measured:
#: the quick search's probes on synthetic, seahorse, bikes, translucent at 0.04-0.1 bpp 69 ->
#: 45 for -0.10...0.00 dB; the full search 20-38 % faster on the same scenes at 0.01-0.08 bpp,
#: -0.07...+0.34 dB.
PROBE_NEAR = 0.05


def _quality_bracket(size, target_bytes: float, near: float = 0.0) -> tuple[int, int]:
    """The bracket ``(lo, hi)``, ``hi = lo + 1``, of qualities around ``target_bytes`` over
    :data:`QUALITY_RANGE`: ``size(lo) <= target_bytes < size(hi)`` where the range allows
    (``size(q)`` grows with ``q``; it caches what it encodes). The same bracket as plain
    bisection (which probes ``(lo + hi) // 2`` and never the range's ends) in fewer probes,
    each an encode of the centre view or of the residual: after two bisection steps, each
    probe interpolates log-size linearly between the probes nearest the target (a codec's
    sizes are close to log-linear in its quality), strictly inside the bracket. Measured on
    the samples' centre views (80 targets each): 5.0 probes on average instead of 6.7 (AV1
    4.4-4.7, JPEG 5.2-5.5), at most 9. ``near`` > 0: the search stops at the first probe
    within that share of the target and returns it as ``(q, q)``."""
    lo, hi = QUALITY_RANGE
    log_target = float(np.log(target_bytes)) if target_bytes > 0 else -np.inf
    known: dict[int, float] = {}  # probed quality -> log size

    def probe(q: int) -> bool:
        nonlocal lo, hi
        got = size(q)
        known[q] = float(np.log(max(got, 1)))
        if known[q] <= log_target:
            lo = q
        else:
            hi = q
        return near > 0 and abs(got - target_bytes) <= near * target_bytes

    for _ in range(2):
        if hi - lo > 1 and probe(mid := (lo + hi) // 2):
            return mid, mid
    while hi - lo > 1:
        below = sorted(q for q in known if known[q] <= log_target)
        above = sorted(q for q in known if known[q] > log_target)
        # the probes nearest the target on either side; beyond every probe, the nearest two
        pair = (below[-1], above[0]) if below and above else (below[-2:] if below else above[:2])
        guess = (lo + hi) / 2
        if len(pair) == 2 and known[pair[1]] != known[pair[0]]:
            a, b = pair
            guess = a + (log_target - known[a]) * (b - a) / (known[b] - known[a])
        q = int(min(max(round(guess), lo + 1), hi - 1))
        if probe(q):
            return q, q
    return lo, hi


def _fitting_quality(size, target_bytes: float, near: float = 0.0) -> int | None:
    """Of the bracket around ``target_bytes`` (:func:`_quality_bracket`), the quality whose
    ``size`` is nearest the target without passing it by more than :data:`RATE_TOLERANCE`;
    ``None`` when even the lowest quality does not fit (it is encoded only where every probe
    passed the target). ``near`` > 0: the first probe within that share of the target is
    taken (:func:`_quality_bracket`; both searches' residual and views use
    :data:`PROBE_NEAR`)."""
    limit = target_bytes * (1 + RATE_TOLERANCE)
    bracket = _quality_bracket(size, target_bytes, near)
    if bracket[0] == QUALITY_RANGE[0] and size(QUALITY_RANGE[0]) > limit:
        return None
    fits = [q for q in sorted(set(bracket)) if size(q) <= limit]
    return min(fits, key=lambda k: abs(size(k) - target_bytes)) if fits else None


def _best_quality(frames: np.ndarray, packets: list[Packet], header: StreamHeader, target_bytes: float,
                  coding: CentreCoding, key_interval: int) -> tuple[int, list[bytes]]:
    """The quality whose stream is closest to ``target_bytes`` (:func:`_quality_bracket`;
    sizes grow with quality) and that stream's centre-view payloads, JPEGs naming their
    post-filter as an :class:`~lfstream.codec.encoder.Encoder` with hint key frames every
    ``key_interval`` frames names it (the search sizes leave its 10 bytes out)."""
    centres = [centre_view(to_uint8(f)) for f in frames]
    cache: dict[int, tuple[int, list[bytes]]] = {}

    def size(q: int) -> int:
        if q not in cache:
            images = [encode_centre(c, q, coding) for c in centres]
            at_q, moved = _at_quality(header, packets, q, images, coding)
            cache[q] = (_stream_bytes(at_q, moved), images)
        return cache[q][0]

    q = min(_quality_bracket(size, target_bytes), key=lambda k: abs(size(k) - target_bytes))
    if coding.codec != "jpeg":
        return q, cache[q][1]
    chooser = PostFilterChooser(key_interval)
    return q, [chooser.mark(c, img) for c, img in zip(centres, cache[q][1])]


def _residual_candidate(frames: np.ndarray, packets: list[Packet], header: StreamHeader, quality: int,
                        images: list[bytes], coding: CentreCoding, preset: str, opts: HintOptions,
                        gain_grid: int, target_bytes: float) -> tuple[int, StreamHeader, list[Packet]] | None:
    """The residual quality whose stream (centre at ``quality``) lands within
    :data:`PROBE_NEAR` of the target (else the nearest without passing it by more than
    :data:`RATE_TOLERANCE`, :func:`_fitting_quality`); ``None`` when even quality 1 does not
    fit."""


    at_q, moved = _at_quality(header, packets, quality, images, coding)
    ref = Encoder(quality=quality, depth_hint=header.has_hint, hint_options=opts, gain_grid=gain_grid, preset=preset,
                  residual=1)
    u, v, h, w = frames.shape[1:5]
    predictions = [ref.predict(p, (u, v), (h, w)) for p in moved]  # in stream order: delta hints
    frames8 = [to_uint8(f) for f in frames]
    base = _stream_bytes(at_q, moved)
    cache: dict[int, tuple[int, list[bytes]]] = {}

    def size(r: int) -> int:
        if r not in cache:
            payloads = [encode_residual(f, pred, r, RESIDUAL_SPEED[preset]) for f, pred in zip(frames8, predictions)]
            cache[r] = (base + sum(len(x) for x in payloads), payloads)
        return cache[r][0]

    r = _fitting_quality(size, target_bytes, PROBE_NEAR)
    if r is None:
        return None
    meta = {**at_q.meta, "residual": residual_meta(r, RESIDUAL_SPEED[preset])}
    with_res = replace(at_q, meta=meta)
    return r, with_res, [replace(p, residual=x) for p, x in zip(moved, cache[r][1])]


def _views_candidate(frames: np.ndarray, present: np.ndarray | None, preset: str, fps: float,
                     target_bytes: float, hint: bool, mode: str = "views") -> tuple[int, StreamHeader, list[Packet]] | None:
    """The stream whose residual codes the views themselves (``mode``: ``views`` or
    ``half-views``; no gains; the hint only with ``hint``: it does not shape the views, and costs toys_array 0.003 bpp)
    closest to the target without passing it by more than :data:`RATE_TOLERANCE`:
    the centre view and the views' sequence at one quality (the centre is one view among
    U * V: a better centre would buy 1/(U * V) of the MPSNR), searched like the centre's.
    ``None`` when even quality 1 does not fit. Its quality search stops within
    :data:`PROBE_NEAR` of the target, as the residual's (:func:`_fitting_quality`)."""


    cache: dict[int, tuple[int, StreamHeader, list[Packet]]] = {}

    def size(q: int) -> int:
        if q not in cache:
            enc = Encoder(quality=q, depth_hint=hint, preset=preset, residual=q, residual_mode=mode)
            header = enc.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
            packets = [enc.encode_frame(f, t, int(round(t * 1e6 / fps)), present) for t, f in enumerate(frames)]
            cache[q] = (_stream_bytes(header, packets), header, packets)
        return cache[q][0]

    q = _fitting_quality(size, target_bytes, PROBE_NEAR)
    return None if q is None else (q, cache[q][1], cache[q][2])


def _family(c: dict) -> str:
    """A candidate's family in the model's words (:mod:`lfstream.codec.rate.model`)."""
    if c["residual"] is None:
        return "centre"
    return "views" if c["residual_mode"] in VIEW_MODES else "prediction"


def _choice(candidates: list[dict], target_bpp: float) -> RateChoice:
    """The candidate within :data:`RATE_TOLERANCE` of the target with the best measured
    first-frame MPSNR (else the nearest to the target), as a :class:`RateChoice`."""
    def rank(c: dict) -> tuple:
        off = abs(c["bpp"] - target_bpp) / target_bpp
        measured = c["mpsnr_first_frame"] if c["mpsnr_first_frame"] is not None else 0.0
        return (off > RATE_TOLERANCE, -measured if off <= RATE_TOLERANCE else off)

    best = min(candidates, key=rank)
    header_q, packets_q, opts_q = best["_stream"]
    report = tuple({**{k: v for k, v in c.items() if k != "_stream"}, "family": _family(c)} for c in candidates)
    return RateChoice(best["quality"], best["depth_hint"], best["bpp"], best["mpsnr_first_frame"], report, header_q,
                      packets_q, best["preset"], opts_q, best["residual"], best["residual_mode"] or "prediction")


def _quick_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None,
                         hint_options: HintOptions | None, gain_grid: int, preset: str,
                         residual: bool, views_hint: bool = False) -> RateChoice | None:
    """Rate control's quick search (:data:`SEARCHES`) under ``preset``: the default's
    configuration of the first frame (:func:`choose_default`: the hint, at 1/8 of the view
    where that predicts as well as at 1/4), every frame coded once, then only the centre
    view's quality searched to the target (:func:`_best_quality`: about five centre-view
    encodes). Two kinds of rates need more:

    - low, where the hint takes :data:`QUICK_HINT_SHARE` of the target or more: the hint at
      twice the scale and no hint are candidates too (their centre views get those bytes);
    - high, where even the best centre view leaves more than :data:`RATE_TOLERANCE` of the
      target unspent or needs a quality above :data:`QUICK_MAX_CENTRE_QUALITY` (the
      prediction saturates): the residual layer fills the rest, the centre at the larger of
      :data:`RESIDUAL_SHARES`, its quality the first probe within :data:`PROBE_NEAR` of the
      target; and, with every view present, the views coded as one sequence (mode
      ``views``, searched the same way; the hint only with ``views_hint``).

    Where more than one candidate lands within the tolerance, each first frame is decoded
    and the better MPSNR wins, as in the full search; one candidate is not decoded
    (``mpsnr_first_frame`` ``None``). ``None`` where nothing lands within the tolerance or
    the prediction fails (the default would code the views): the full search decides there.
    """

    from lfstream.metrics import bpp

    views, size = tuple(frames.shape[1:3]), tuple(frames.shape[3:5])
    target_bytes = target_bpp * int(np.prod(frames.shape[:5])) / 8.0
    choice = choose_default(frames[0], 50, present, hint_options, gain_grid, post_filter=False, preset=preset)
    if choice.codes_views:
        return None
    enc = choice.encoder
    opts = enc.hint_options

    def coded(encoder: Encoder, first: Packet | None = None) -> list[Packet]:
        return [first if t == 0 and first is not None else encoder.encode_frame(f, t, int(round(t * 1e6 / fps)), present)
                for t, f in enumerate(frames)]

    candidates: list[dict] = []

    def add(q: int, r: int | None, at_q: StreamHeader, moved: list[Packet], hint: HintOptions | None,
            mode: str = "prediction") -> None:
        got = _stream_bytes(at_q, moved)
        if abs(got - target_bytes) <= RATE_TOLERANCE * target_bytes:
            candidates.append({"preset": preset, "quality": q, "depth_hint": at_q.has_hint,
                               "hint_scale": hint.hint_scale if at_q.has_hint and hint is not None else None,
                               "residual": r, "residual_mode": None if r is None else mode, "bpp": bpp(got, frames.shape),
                               "mpsnr_first_frame": None, **SEARCHED, "_stream": (at_q, tuple(moved), hint or HintOptions())})

    def centre_only(encoder: Encoder, packets: list[Packet], hint: HintOptions | None) -> tuple[int, int]:
        header = encoder.header(views, size, fps)
        q, images = _best_quality(frames, packets, header, target_bytes, encoder.coding, encoder.hint_options.key_interval)
        at_q, moved = _at_quality(header, packets, q, images, encoder.coding)
        add(q, None, at_q, moved, hint)
        return q, _stream_bytes(at_q, moved)

    packets = coded(enc, choice.first)
    q, got = centre_only(enc, packets, opts)
    if sum(len(p.hint) for p in packets) >= QUICK_HINT_SHARE * target_bytes:
        coarse = replace(opts, hint_scale=2 * opts.hint_scale)
        if hint_options is None and min(size) // coarse.hint_scale >= PREDICTION_CHECK_MIN_CELLS:
            enc_c = Encoder(quality=50, depth_hint=True, hint_options=coarse, gain_grid=gain_grid, preset=preset,
                            post_filter=False)
            centre_only(enc_c, coded(enc_c), coarse)
        enc_n = Encoder(quality=50, depth_hint=False, gain_grid=gain_grid, preset=preset, post_filter=False)
        centre_only(enc_n, coded(enc_n), None)
    saturated = got < target_bytes * (1 - RATE_TOLERANCE) or q > QUICK_MAX_CENTRE_QUALITY
    if saturated and residual and views[0] * views[1] > 1 and av1_fits(size):
        enc_r = Encoder(quality=50, depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=preset,
                        residual=1)
        header_r = enc_r.header(views, size, fps)
        q_r, images = _best_quality(frames, packets, header_r, RESIDUAL_SHARES[-1] * target_bytes, enc_r.coding,
                                    opts.key_interval)
        found = _residual_candidate(frames, packets, header_r, q_r, images, enc_r.coding, preset, opts, gain_grid,
                                    target_bytes)
        if found is not None:
            add(q_r, found[0], found[1], found[2], opts)
        if present is None or np.all(present):
            # the views themselves: where warping misses what the residual must then carry
            # (seahorse at 0.04-0.1 bpp: +1.5...+2.4 dB over the residual)
            views_found = _views_candidate(frames, present, preset, fps, target_bytes, views_hint)
            if views_found is not None:
                q_v, at_v, moved_v = views_found
                add(q_v, q_v, at_v, moved_v, HintOptions() if views_hint else None, "views")
    if not candidates:
        return None
    if len(candidates) > 1:
        for c in candidates:
            c["mpsnr_first_frame"] = _first_frame_mpsnr(frames, present, c["_stream"][0], list(c["_stream"][1]))
    return _choice(candidates, target_bpp)


def choose_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None = None,
                         hint_options: HintOptions | None = None, gain_grid: int = 4,
                         preset: str | None = None, residual: bool = True, views_hint: bool = False,
                         search: str | None = None) -> RateChoice:
    """The (preset, quality, depth hint, hint precision, residual) whose stream lands nearest
    ``target_bpp`` with the best first-frame MPSNR (see the module docstring). ``preset``:
    the only preset to consider; ``None`` considers every preset (and the residual layer
    with :data:`RESIDUAL_PRESET`). ``hint_options``: the only hint options to consider;
    ``None`` tries the default and a 1/8-resolution hint. ``residual``: whether residual
    candidates are tried (they cost a decode and several AV1 sequence encodes per frame).
    ``views_hint``: a candidate that codes the views themselves carries the depth hint too
    (a stream fits its focal planes to it; the views do not need it). ``search``: one of
    :data:`SEARCHES`; ``None``: ``quick`` under the ``fast`` preset (a fast encode is what it
    promises), ``full`` otherwise. The quick search searches one named preset: with
    ``preset=None`` the full search runs whatever ``search`` says.

    Shape:
        - frames: ``(T, U, V, H, W, 3)``
    """

    from lfstream.metrics import bpp

    validate_target(target_bpp, search, preset)
    if search == "model":
        raise LFValueError("search: the model is lfstream.codec.rate.choose_rate's")
    if preset is not None and (search or ("quick" if preset == "fast" else "full")) == "quick":
        quick = _quick_configuration(frames, target_bpp, fps, present, hint_options, gain_grid, preset, residual,
                                     views_hint)
        if quick is not None:
            return quick
    presets = tuple(PRESETS) if preset is None else (preset,)
    if not av1_fits(frames.shape[3:5]):  # views too small for AV1: the JPEG preset alone, no residual
        if preset not in (None, "fast"):
            raise LFValueError(f"preset {preset!r}: AV1 codes views of at least {AV1_MIN_VIEW} pixels, these are "
                               f"{frames.shape[3]}x{frames.shape[4]}")
        presets, residual = ("fast",), False
    pixels = int(np.prod(frames.shape[:5]))
    target_bytes = target_bpp * pixels / 8.0
    candidates = []

    def add(name: str, q: int, hint_scale: int | None, r: int | None, mode: str | None, at_q: StreamHeader,
            moved: list[Packet], opts: HintOptions) -> None:
        candidates.append({"preset": name, "quality": q, "depth_hint": at_q.has_hint, "hint_scale": hint_scale,
                           "residual": r, "residual_mode": mode, "bpp": bpp(_stream_bytes(at_q, moved), frames.shape),
                           "mpsnr_first_frame": _first_frame_mpsnr(frames, present, at_q, moved), **SEARCHED,
                           "_stream": (at_q, tuple(moved), opts)})

    hints = [hint_options] if hint_options is not None else [HintOptions(), HintOptions(hint_scale=COARSE_HINT_SCALE)]
    res_preset = RESIDUAL_PRESET if preset is None else preset
    for hint, opts in [(True, h) for h in hints] + [(False, HintOptions())]:
        # hints and gains do not depend on the preset: one encode per frame, the centre
        # view recoded per preset and quality (so no post-filter is measured on these q50 ones)
        enc = Encoder(quality=50, depth_hint=hint, hint_options=opts, gain_grid=gain_grid, post_filter=False)
        packets = [enc.encode_frame(f, t, int(round(t * 1e6 / fps)), present) for t, f in enumerate(frames)]
        for name in presets:
            enc_p = Encoder(quality=50, depth_hint=hint, hint_options=opts, gain_grid=gain_grid, preset=name)
            header = enc_p.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
            q, images = _best_quality(frames, packets, header, target_bytes, enc_p.coding, opts.key_interval)
            at_q, moved = _at_quality(header, packets, q, images, enc_p.coding)
            add(name, q, opts.hint_scale if hint else None, None, None, at_q, moved, opts)
        if not (residual and hint and opts.hint_scale == HintOptions().hint_scale and frames.shape[1] * frames.shape[2] > 1):
            continue
        enc_r = Encoder(quality=50, depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=res_preset,
                        residual=1)
        header_r = enc_r.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
        for share in RESIDUAL_SHARES:
            q, images = _best_quality(frames, packets, header_r, share * target_bytes, enc_r.coding,
                                      opts.key_interval)
            found = _residual_candidate(frames, packets, header_r, q, images, enc_r.coding, res_preset, opts,
                                        gain_grid, target_bytes)
            if found is not None:
                r, at_q, moved = found
                add(res_preset, q, opts.hint_scale, r, "prediction", at_q, moved, opts)

    if residual and frames.shape[1] * frames.shape[2] > 1 and (present is None or np.all(present)):
        # the views themselves (scenes warping cannot predict: toys_array); not where views
        # are missing: a prediction reconstructs those, a coded sequence would not
        for mode in VIEW_MODES:
            if not av1_fits(coded_size(tuple(frames.shape[3:5]), mode)):
                continue  # half-size views of small views: below what AV1 codes
            found = _views_candidate(frames, present, res_preset, fps, target_bytes, views_hint, mode)
            if found is not None:
                q, at_q, moved = found
                add(res_preset, q, HintOptions().hint_scale if views_hint else None, q, mode, at_q, moved, HintOptions())

    return _choice(candidates, target_bpp)

