"""Rate control as a model of bytes against quality: one trial, one encode, at most one re-encode.

A stream under a target has three families of configuration (:mod:`lfstream.codec.rate.search`):

- ``centre``: the centre view and the depth hint (the decoder warps the centre into every
  view); its quality saturates at the warp's floor however many bits the centre gets;
- ``prediction``: the same with a residual layer, one AV1 sequence of what the warp misses;
- ``views``: the views themselves as one AV1 sequence keyed by the centre view (scenes no
  warp predicts, or whose per-view noise a residual codes no cheaper than the views).

The exhaustive search (``search="full"``) codes every family at every preset and hint
precision to the target and decodes each. This model (``search="model"``) measures instead
what decides between them, on the first frame (a key frame):

1. the default's analysis: the hint, the gains and the check of the prediction
   (:func:`lfstream.codec.rate.choose_default`, its JPEG centre: the hint and gains do not
   depend on the centre's coding);
2. the centre view's size against quality in the preset's coding, from trial encodes
   (log-size is close to linear in quality: a prior slope, then secant steps,
   :func:`fit_quality`), and the ``centre`` family's decoded quality (one prediction);
3. a trial of both sequence families on a central crop of every view (a quarter of the
   pixels, the fastest SVT-AV1 preset, one quality): their bytes scaled to the whole view and
   the preset's effort (:data:`SPEED_BYTES`), and their quality moved to the target along a
   prior slope (:data:`DB_PER_DOUBLING`), so the families are compared at equal bytes;
4. the family with the best predicted quality is coded once at the quality the size model
   gives; where it lands outside :data:`MODEL_TOLERANCE` of the target, the sequence is coded
   once more at the quality the measured point and the prior slope give. Where the two best
   predictions lie within :data:`DECIDE_MARGIN_DB`, both are coded and the decoded one wins.

Video: the configuration is chosen on the first frame and kept; each later frame's quality
follows the bits spent (:func:`lfstream.codec.rate.follow_rate`, x264's ABR in spirit) and a
frame over :data:`FRAME_CAP` times its share of the target is coded again lower (a VBV-like
bound). The report lists the model's predictions beside what was measured, so its error is
visible on every run.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, pack_header
from lfstream.codec.centre import encode_centre
from lfstream.codec.centre.av1 import av1_fits
from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.encoder import Encoder, preset_coding
from lfstream.codec.hint import HintOptions
from lfstream.codec.rate.common import (
    RateChoice,
    _first_frame_mpsnr,
    _stream_bytes,
    validate_target,
)
from lfstream.codec.rate.default import choose_default
from lfstream.codec.rate.follow import RateFollower
from lfstream.codec.rate.search import choose_configuration
from lfstream.codec.residual import apply_residual, encode_residual, encode_views_keyed
from lfstream.lightfield import centre_index, to_uint8

#: How far from the target (relative) a model-chosen single light field may land before
#: the sequence is coded again.
MODEL_TOLERANCE = 0.08
#: Prior slope of log-size per quality step: AV1 intra and sequences (SVT-AV1's CRF is
#: linear in quality) and JPEG, measured on the shared samples around the rates rate
#: control picks. Secant steps replace it once two sizes are known.
LOG_SIZE_PER_STEP = {"av1": 0.038, "jpeg": 0.025}
#: Bytes of an SVT-AV1 sequence at a preset relative to the trial's preset
#: (:data:`TRIAL_SPEED`) at the same quality, measured on the shared 7x7 samples' views
#: (qualities 10-50).
SPEED_BYTES = {4: 0.88, 8: 1.08, 12: 1.0, 13: 1.0}
#: MPSNR of an SVT-AV1 views sequence at a preset against the trial's preset at the same size
#: (dB), measured on the shared 7x7 samples at 0.01-0.08 bpp (the slower preset's better
#: inter prediction; a prediction residual, a smaller share of the stream, gains about none).
SPEED_DB = {4: 0.6, 8: 0.3, 12: 0.0, 13: 0.0}
#: The sequence trials' SVT-AV1 preset: the fastest.
TRIAL_SPEED = 13
#: Prior slope of MPSNR against bytes for the sequence families (dB per doubling), used to
#: compare the trials at equal bytes.
DB_PER_DOUBLING = 1.6
#: Where the two best predictions differ by less than this (dB), both are coded and decoded:
#: the trials' MPSNR predicted the coded families' within about a dB on the shared samples
#: and the synthetic scenes (their mosaic is a quarter of each view, and small views' mosaics
#: are harder than the view).
DECIDE_MARGIN_DB = 1.0
#: The share of a prediction-residual candidate's bytes its centre view takes.
RESIDUAL_CENTRE_SHARE = 0.45
#: How far over the target a coded candidate may land and still be chosen (relative).
RATE_TOLERANCE_MODEL = 0.10
#: The most codings of a sequence a family gets on the first frame: the predicted quality,
#: the re-coding of the part that missed along the prior slope, and a secant step where
#: those two bracket the target outside the tolerance (each stops within it).
SEQUENCE_CODINGS = 3
#: The lowest residual quality the model plans for: below it a residual codes little but
#: noise, and the centre view gives up bytes instead.
RESIDUAL_MIN_QUALITY = 2
#: Bytes a frame of a sequence costs whatever it holds (AV1 frame headers and the payload's
#: framing: a sequence of flat views measured 27-29 bytes a view at 96x128 to 352x512): kept
#: out of the trial's scaling from the mosaic's pixels to the view's.
SEQUENCE_FRAME_BYTES = 27
#: The sequence trials' first quality, and how far (quality steps) the prior slope may carry
#: it before a second trial measures the slope where the target lies (log-size is not
#: linear over the whole range: it falls faster at the lowest qualities).
TRIAL_QUALITY = 30
TRIAL_REACH = 8
#: Light fields of at most this many pixels (all views) are tried whole, not on a mosaic.
TRIAL_WHOLE_PIXELS = 4_000_000
#: The crop trial's views are this fraction of the view per side (a quarter of the pixels).
TRIAL_CROP = 0.5

#: SVT-AV1 presets of the sequence families and the centre's coding, per effort.
EFFORTS = {"best": {"centre": 8, "prediction": 8, "views": 4},
           "balanced": {"centre": 12, "prediction": 12, "views": 8}}


@dataclass(frozen=True)
class FamilyEstimate:
    """What the model predicts for one family on the first frame.

    Attributes:
        family: ``centre``, ``prediction`` or ``views``.
        db: predicted MPSNR (dB) at the target.
        quality: the centre's quality (``views``: the sequence's).
        residual: the residual sequence's quality (``None`` for ``centre``).
        predicted_bytes: the frame's predicted size at those qualities.
    """

    family: str
    db: float
    quality: int
    residual: int | None
    predicted_bytes: float


def fit_quality(size, target: float, slope: float, start: int = 50, probes: int = 4,
                near: float = 0.03, slack: float | None = None) -> int:
    """The quality whose ``size(q)`` is nearest ``target`` (bytes) without passing it by more
    than ``slack`` bytes (``None``: :data:`MODEL_TOLERANCE` of the target) where one does: a
    probe at ``start``, a step along the prior log-size ``slope`` per quality, then secant
    steps on the two nearest probes; at most ``probes`` sizes, fewer where one lands within
    ``near`` of the target. ``size`` caches what it codes."""
    lo, hi = QUALITY_RANGE
    known: dict[int, float] = {}

    def probe(q: int) -> float:
        known[q] = float(np.log(max(size(q), 1)))
        return known[q]

    log_t = float(np.log(max(target, 1.0)))
    q = int(np.clip(start, lo, hi))
    for _ in range(probes):
        got = probe(q)
        if abs(got - log_t) <= np.log1p(near):
            break
        pts = sorted(known, key=lambda k: abs(known[k] - log_t))[:2]
        s = slope
        if len(pts) == 2 and pts[0] != pts[1] and known[pts[0]] != known[pts[1]]:
            s = max((known[pts[1]] - known[pts[0]]) / (pts[1] - pts[0]), 1e-3)
        base = pts[0]
        nxt = int(np.clip(round(base + (log_t - known[base]) / s), lo, hi))
        if nxt in known:
            # a unit step towards the target where the secant repeats a probe
            nxt = int(np.clip(base + (1 if known[base] < log_t else -1), lo, hi))
            if nxt in known:
                break
        q = nxt
    limit = np.log(target + (MODEL_TOLERANCE * target if slack is None else slack))
    fits = [k for k in known if known[k] <= limit]
    pool = fits or [min(known, key=lambda k: known[k])]
    return min(pool, key=lambda k: abs(known[k] - log_t))


def _views_db(ref: np.ndarray, test: np.ndarray, present: np.ndarray | None) -> float:
    """Mean over the present views of each view's PSNR (dB, at most 100): MPSNR's measure
    on 8-bit views.

    Shape:
        - ref, test: ``(U, V, H, W, C)`` uint8
    """
    import cv2

    u, v = ref.shape[:2]
    n = ref[0, 0].size
    dbs = []
    for a in range(u):
        for b in range(v):
            if present is not None and not present[a, b]:
                continue
            # the sum of squares in C on the 8-bit views (no float copy of the light field)
            sq = cv2.norm(np.ascontiguousarray(ref[a, b]).reshape(-1, 1), np.ascontiguousarray(test[a, b]).reshape(-1, 1),
                          cv2.NORM_L2SQR)
            dbs.append(min(10.0 * np.log10(255.0**2 * n / max(sq, 1e-10)), 100.0))
    return float(np.mean(dbs))


def _crop(frame: np.ndarray) -> np.ndarray:
    """A trial sample of every view: the central :data:`TRIAL_CROP` of each quadrant, the four
    stitched into one view of a quarter of the pixels (a single central crop misjudges scenes
    whose centre differs from the rest: a glass bottle in front of a plain wall). Sides are
    multiples of 16, so the stitches fall on coding-block edges; light fields of at most
    :data:`TRIAL_WHOLE_PIXELS` (their trials are cheap, and a small view's mosaic is mostly
    stitches) and views too small for AV1's minimum are taken whole.

    Shape:
        - frame: ``(U, V, H, W, C)``
        - output: ``(U, V, h, w, C)``, ``h <= H / 2``, ``w <= W / 2``
    """
    h, w = frame.shape[2:4]
    th, tw = int(h * TRIAL_CROP / 2) // 16 * 16, int(w * TRIAL_CROP / 2) // 16 * 16
    if th < 8 or tw < 8 or not av1_fits((2 * th, 2 * tw)) or frame[..., 0].size <= TRIAL_WHOLE_PIXELS:
        return frame
    rows = []
    for y0 in (0, h // 2):
        cols = []
        for x0 in (0, w // 2):
            y = y0 + (h // 2 - th) // 2
            x = x0 + (w // 2 - tw) // 2
            cols.append(frame[:, :, y:y + th, x:x + tw])
        rows.append(np.concatenate(cols, axis=3))
    return np.ascontiguousarray(np.concatenate(rows, axis=2))


def sequence_trial(frame: np.ndarray, prediction: np.ndarray | None, quality: int,
                   present: np.ndarray | None) -> tuple[float, float]:
    """One sequence family on the trial mosaic of every view (:func:`_crop`) at ``quality``
    and :data:`TRIAL_SPEED`: (its bytes scaled to the whole view, MPSNR dB of the mosaic).
    ``prediction``: the decoder's warp the ``prediction`` family's residual corrects (its
    centre view's bytes are the caller's); ``None``: the ``views`` family (its key frame is
    its own centre view).

    Shape:
        - frame, prediction: ``(U, V, H, W, 3)`` uint8
    """
    from lfstream.codec.centre.av1 import decode_av1

    crop = _crop(frame)
    scale = (frame.shape[2] * frame.shape[3]) / (crop.shape[2] * crop.shape[3])
    frames = frame.shape[0] * frame.shape[1] - 1
    fixed = SEQUENCE_FRAME_BYTES * frames  # framing that does not grow with the pixels

    def whole(n: int) -> float:
        return fixed + scale * max(n - fixed, 0)

    if prediction is not None:
        pred = _crop(prediction)
        residual = encode_residual(crop, pred, quality, TRIAL_SPEED)
        return whole(len(residual)), _views_db(crop, apply_residual(pred.copy(), residual), present)
    key, rest = encode_views_keyed(crop, quality, TRIAL_SPEED)
    rec = np.zeros_like(crop)
    rec[centre_index(*frame.shape[:2])] = decode_av1(key, crop.shape[2:4])
    apply_residual(rec, rest, centre=key)
    return whole(len(key) + len(rest)), _views_db(crop, rec, present)


def fitted_trial(frame: np.ndarray, prediction: np.ndarray | None, target_bytes: float, speed: int,
                 present: np.ndarray | None) -> tuple[int, float, float, float]:
    """A sequence family's quality for ``target_bytes`` at SVT-AV1 preset ``speed``, from
    trials (:func:`sequence_trial`): one at :data:`TRIAL_QUALITY`; where the prior slope puts
    the target more than :data:`TRIAL_REACH` steps away, a second at that quality, and the
    slope between the two. Returns (quality, its predicted bytes, the nearer trial's bytes
    and MPSNR)."""
    lo, hi = QUALITY_RANGE
    q0 = TRIAL_QUALITY
    b0, db0 = sequence_trial(frame, prediction, q0, present)
    b0 *= SPEED_BYTES[speed]
    q1 = quality_for(b0, q0, target_bytes)
    if abs(q1 - q0) <= TRIAL_REACH:
        return q1, b0 * float(np.exp(LOG_SIZE_PER_STEP["av1"] * (q1 - q0))), b0, db0
    b1, db1 = sequence_trial(frame, prediction, q1, present)
    b1 *= SPEED_BYTES[speed]
    slope = float(np.log(max(b1, 1.0) / max(b0, 1.0))) / (q1 - q0)
    if slope <= 1e-3:
        slope = LOG_SIZE_PER_STEP["av1"]
    q = int(np.clip(round(q1 + np.log(max(target_bytes, 1.0) / max(b1, 1.0)) / slope), lo, hi))
    return q, b1 * float(np.exp(slope * (q - q1))), b1, db1


def at_target(db: float, got_bytes: float, target_bytes: float) -> float:
    """A trial's quality moved to the target along :data:`DB_PER_DOUBLING`."""
    return db + DB_PER_DOUBLING * float(np.log2(max(target_bytes, 1.0) / max(got_bytes, 1.0)))


def quality_for(bytes_at: float, quality: int, target_bytes: float) -> int:
    """The sequence quality whose size the prior log-size slope puts at ``target_bytes``,
    from one measured or predicted point (``bytes_at`` at ``quality``)."""
    lo, hi = QUALITY_RANGE
    step = float(np.log(max(target_bytes, 1.0) / max(bytes_at, 1.0))) / LOG_SIZE_PER_STEP["av1"]
    return int(np.clip(round(quality + step), lo, hi))


def with_centre(header: StreamHeader, packet: Packet, quality: int, image: bytes, coding) -> tuple[StreamHeader, Packet]:
    """``header`` and ``packet`` with the centre view coded at ``quality`` in ``coding``."""
    meta = {**header.meta, "quality": int(quality)}
    if coding.codec != "jpeg":
        meta["centre"] = coding.as_meta(quality)
    return replace(header, quality=int(quality), meta=meta), replace(packet, image=image)


def centre_sizes(centre: np.ndarray, coding):
    """A cached ``size(q)`` of the centre view in ``coding`` and the payloads it coded."""
    cache: dict[int, bytes] = {}

    def size(q: int) -> int:
        if q not in cache:
            cache[q] = encode_centre(centre, int(q), coding)
        return len(cache[q])

    return size, cache


def frame_budget(target_bpp: float, frame: np.ndarray) -> float:
    """A frame's share of the target, in bytes."""
    return float(target_bpp) * int(np.prod(frame.shape[:4])) / 8.0


@dataclass
class _Coded:
    """One family coded on the first frame: its header, packet, the encoder that continues
    the stream, and what it measured."""

    family: str
    header: StreamHeader
    packet: Packet
    encoder: object  # lfstream.codec.encoder.Encoder
    db: float
    estimate: FamilyEstimate


def _packet_bytes(header: StreamHeader, packet: Packet) -> int:
    return packet.size(header.version)


def model_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None = None,
                        hint_options: HintOptions | None = None, gain_grid: int = 4, preset: str | None = None,
                        views_hint: bool = False):
    """Rate control by the model (see the module docstring): the configuration chosen on
    the first frame from trial measurements, every frame coded once (a frame whose size
    misses the target by more than :data:`MODEL_TOLERANCE`, or a video frame over
    :data:`FRAME_CAP` times its share, once more). ``preset``: the effort (:data:`EFFORTS`;
    ``None``: ``best``). Returns :class:`lfstream.codec.rate.RateChoice`, whose
    ``candidates`` list each family's prediction and, where coded, its measurement; ``None``
    where the model does not apply (views too small for AV1, or the prediction fails with
    views missing): the caller's full search decides there.

    Shape:
        - frames: ``(T, U, V, H, W, 3)``

    Each candidate row has the searches' keys (the configuration, ``bpp`` and
    ``mpsnr_first_frame`` of the first frame where coded) and
    :data:`lfstream.codec.rate.SEARCHED`'s (``family``, ``coded``, the predictions).
    """
    from lfstream.metrics import bpp as bpp_of

    effort = preset if preset in EFFORTS else "best"
    speeds = EFFORTS[effort]
    u, v, h, w = frames.shape[1:5]
    views, size = (u, v), (h, w)
    all_present = present is None or bool(np.all(present))
    if not av1_fits(size) or u * v == 1:
        return None
    f0 = np.ascontiguousarray(to_uint8(np.asarray(frames[0])))
    budget = frame_budget(target_bpp, f0)
    choice = choose_default(f0, 50, present, hint_options, gain_grid, post_filter=False, preset="fast")
    if choice.codes_views and not all_present:
        return None
    coding = preset_coding(effort)
    slope = LOG_SIZE_PER_STEP[coding.codec]
    c0 = centre_index(u, v)
    centre = f0[c0]
    estimates: list[FamilyEstimate] = []
    context: dict[str, tuple] = {}
    if not choice.codes_views:
        opts = choice.encoder.hint_options
        header_c = Encoder(quality=50, depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=effort,
                           post_filter=False).header(views, size, fps)
        pkt0 = choice.first
        # the hint, gains and framing; the header's bytes shared by the frames
        side = _packet_bytes(header_c, replace(pkt0, image=b"")) + len(pack_header(header_c)) / len(frames)
        size_c, cache_c = centre_sizes(centre, coding)

        def predicted(q: int, residual: int | None = None):
            hdr, pkt = with_centre(header_c, pkt0, q, cache_c[q], coding)
            ref = Encoder(quality=int(q), depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=effort,
                          residual=residual, post_filter=False)
            return hdr, pkt, ref.predict(pkt, views, size)

        q_c = fit_quality(size_c, budget - side, slope)
        hdr, pkt, pred = predicted(q_c)
        db_c = _views_db(f0, pred, present)
        estimates.append(FamilyEstimate("centre", db_c, q_c, None, float(_packet_bytes(hdr, pkt))))
        context["centre"] = (hdr, pkt)
        q_rc = fit_quality(size_c, RESIDUAL_CENTRE_SHARE * (budget - side), slope, start=q_c)
        hdr_r, pkt_r, pred_r = predicted(q_rc, residual=1)
        room = budget - side - size_c(q_rc)
        q_r, res_bytes, trial_bytes, trial_db = fitted_trial(f0, pred_r, room, speeds["prediction"], present)
        if q_r < RESIDUAL_MIN_QUALITY:
            # the residual cannot shrink to its share (its lowest qualities code little but
            # noise): the centre takes what the residual leaves at that quality, predicted
            # by the same slope (the warp's error, not the centre's coding, sets its size)
            res_bytes *= float(np.exp(LOG_SIZE_PER_STEP["av1"] * (RESIDUAL_MIN_QUALITY - q_r)))
            q_r = RESIDUAL_MIN_QUALITY
            q_rc = fit_quality(size_c, max(budget - side - res_bytes, 1.0), slope, start=q_rc)
            hdr_r, pkt_r, pred_r = predicted(q_rc, residual=1)
            room = budget - side - size_c(q_rc)
        estimates.append(FamilyEstimate("prediction", at_target(trial_db, side + size_c(q_rc) + trial_bytes, budget),
                                        q_rc, q_r, side + size_c(q_rc) + res_bytes))
        context["prediction"] = (hdr_r, pkt_r, pred_r, room)
    if all_present:
        q_v, v_bytes, trial_bytes, trial_db = fitted_trial(f0, None, budget, speeds["views"], present)
        estimates.append(FamilyEstimate("views", at_target(trial_db, trial_bytes, budget) + SPEED_DB[speeds["views"]],
                                        q_v, q_v, v_bytes))
    ranked = sorted(estimates, key=lambda e: -e.db)
    chosen = [ranked[0]] + [e for e in ranked[1:2] if ranked[0].db - e.db < DECIDE_MARGIN_DB]
    if chosen == [ranked[0]] and ranked[0].family == "centre" and len(ranked) > 1 \
            and ranked[0].predicted_bytes < (1 - RATE_TOLERANCE_MODEL) * budget:
        # the centre saturates short of the target: the best sequence family spends the rest
        chosen.append(ranked[1])

    def views_encoder(q: int) -> Encoder:
        return Encoder(quality=int(q), depth_hint=views_hint, hint_options=HintOptions(), gain_grid=gain_grid,
                       preset=effort, residual=int(q), residual_mode="views")

    def code(est: FamilyEstimate) -> _Coded:
        """Frame 0 in ``est``'s family (the default's encoder is configured for the winner
        afterwards: both prediction families would share it)."""
        if est.family == "centre":
            hdr, pkt = context["centre"]
            return _Coded("centre", hdr, pkt, None, _first_frame_mpsnr(f0[None], present, hdr, [pkt]), est)
        if est.family == "prediction":
            hdr_r, pkt_r, pred_r, room = context["prediction"]
            cache: dict[int, bytes] = {}

            def residual_size(q: int) -> int:
                if q not in cache:
                    cache[q] = encode_residual(f0, pred_r, q, speeds["prediction"])
                return len(cache[q])

            # the predicted quality first; the part that missed is coded again along the slope
            q_r = fit_quality(residual_size, room, LOG_SIZE_PER_STEP["av1"], start=est.residual, probes=SEQUENCE_CODINGS,
                              near=MODEL_TOLERANCE * budget / max(room, 1.0), slack=RATE_TOLERANCE_MODEL * budget)
            residual = cache[q_r]
            hdr = Encoder(quality=est.quality, depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=effort,
                          residual=int(q_r), post_filter=False).header(views, size, fps)
            pkt = replace(pkt_r, residual=residual)
            return _Coded("prediction", hdr, pkt, None, _first_frame_mpsnr(f0[None], present, hdr, [pkt]),
                          replace(est, residual=int(q_r)))
        coded_views: dict[int, tuple] = {}

        def views_size(q: int) -> int:
            if q not in coded_views:
                enc_q = views_encoder(q)
                pkt_q = enc_q.encode_frame(f0, 0, 0, present)
                coded_views[q] = (enc_q, pkt_q)
            enc_q, pkt_q = coded_views[q]
            return _packet_bytes(enc_q.header(views, size, fps), pkt_q)

        q = fit_quality(views_size, budget, LOG_SIZE_PER_STEP["av1"], start=est.quality, probes=SEQUENCE_CODINGS,
                        near=MODEL_TOLERANCE, slack=RATE_TOLERANCE_MODEL * budget)
        enc, pkt = coded_views[q]
        hdr = enc.header(views, size, fps)
        return _Coded("views", hdr, pkt, enc, _first_frame_mpsnr(f0[None], present, hdr, [pkt]),
                      replace(est, quality=int(q), residual=int(q)))

    coded = [code(e) for e in chosen]
    fitting = [c for c in coded if _packet_bytes(c.header, c.packet) <= (1 + RATE_TOLERANCE_MODEL) * budget]
    if not fitting and "centre" in context:
        # every sequence passed the target by more than the tolerance: the centre family fits
        # (its quality is searched on the centre view alone)
        est = next(e for e in estimates if e.family == "centre")
        coded.append(code(est))
        fitting = coded[-1:]
    best = max(fitting or coded, key=lambda c: c.db)
    enc = best.encoder
    if enc is None:  # the default's encoder, its hint state kept, in the winner's configuration
        enc = choice.encoder
        enc.preset, enc.coding, enc.quality, enc.post_filter = effort, coding, best.estimate.quality, False
        if best.family == "prediction":
            enc.residual, enc.residual_mode = int(best.estimate.residual), "prediction"
    follower = RateFollower.after(enc, best.family, best.header, best.packet, target_bpp, int(np.prod(f0.shape[:4])))
    packets = [best.packet] + [follower.encode_frame(frames[t], t, int(round(t * 1e6 / fps)), present)
                               for t in range(1, len(frames))]
    total = _stream_bytes(best.header, packets)
    report = []
    hint_scale = choice.encoder.hint_options.hint_scale
    for e in estimates:
        hinted = e.family != "views" or views_hint
        row = {"preset": effort, "quality": e.quality, "depth_hint": hinted, "hint_scale": hint_scale if hinted else None,
               "residual": e.residual, "residual_mode": None if e.residual is None else
               ("views" if e.family == "views" else "prediction"), "bpp": None, "mpsnr_first_frame": None,
               "family": e.family, "coded": False, "predicted_db": round(e.db, 3),
               "predicted_bpp": bpp_of(int(e.predicted_bytes), f0.shape)}
        for c in coded:
            if c.family == e.family:
                row.update({"coded": True, "quality": c.estimate.quality, "residual": c.estimate.residual,
                            "mpsnr_first_frame": round(c.db, 3), "bpp": bpp_of(_packet_bytes(c.header, c.packet), f0.shape)})
        report.append(row)
    hdr = best.header
    return RateChoice(int(hdr.quality), bool(hdr.has_hint), bpp_of(total, frames.shape), best.db, tuple(report), hdr,
                      tuple(packets), effort, enc.hint_options if hdr.has_hint else HintOptions(),
                      None if best.family == "centre" else best.estimate.residual,
                      "prediction" if best.family != "views" else "views", follower)


def choose_rate(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None = None,
                hint_options: HintOptions | None = None, gain_grid: int = 4, preset: str | None = None,
                views_hint: bool = False, search: str | None = None):
    """Rate control's entry point: ``search`` one of :data:`~lfstream.codec.rate.common.SEARCHES` (``None``: ``quick``
    under the ``fast`` preset, else ``model``). The model falls back to the full search
    where it does not apply (:func:`model_configuration`).

    Shape:
        - frames: ``(T, U, V, H, W, 3)``
    """
    validate_target(target_bpp, search, preset)
    if search is None:
        search = "quick" if preset == "fast" else "model"
    if search == "model":
        chosen = model_configuration(frames, target_bpp, fps, present, hint_options, gain_grid, preset, views_hint)
        if chosen is not None:
            return chosen
        search = "full"
    return choose_configuration(frames, target_bpp, fps, present, hint_options, gain_grid, preset=preset,
                                views_hint=views_hint, search=search)
