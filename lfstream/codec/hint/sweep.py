"""The hint's estimation: the plane sweep over the views' block means and its winner
(:func:`estimate_hint_map`), the scene's disparity range, and the accuracy metrics
(:func:`disparity_errors`)."""

from __future__ import annotations

from concurrent.futures import wait

import cv2
import numpy as np

from lfstream.codec.hint.axes import _axes_views, _detect_axes
from lfstream.codec.hint.grids import HintMap, _coarser, _grids, _high_pass, _kept_array, _ring_views, _upsample, sweep_views
from lfstream.codec.hint.options import HintOptions
from lfstream.errors import LFShapeError
from lfstream.lightfield import check_lf, to_uint8, view_offsets


def sweeps_on_device(device: str | None) -> bool:
    """Whether a sweep on ``device`` runs as tensor operations
    (:func:`lfstream.codec.hint.sweep_batched.sweep_batched`: a CUDA device) rather than the CPU
    kernels (``None`` or ``"cpu"``)."""
    return device is not None and str(device).startswith("cuda")


def _sweep(images: np.ndarray, offsets: np.ndarray, lo: float, hi: float, scale: int, options: HintOptions,
           max_candidates: int = 128, device: str | None = None) -> np.ndarray:
    """Disparity (px of the full view per view step) at the resolution of ``images``; on a
    CUDA ``device`` the same sweep as tensor operations (:func:`sweeps_on_device`)."""
    from lfstream.codec.hint.kernels import sweep_cost, winner_subpixel

    reach = float(np.abs(offsets).max()) or 1.0
    step = max(options.step * scale / reach, options.min_spacing)  # candidate spacing in full-view px per view step
    n = int(np.ceil((hi - lo) / step)) + 1
    if n > max_candidates:
        n, step = max_candidates, (hi - lo) / (max_candidates - 1)
    n = max(n, 3)
    cands = (lo + step * np.arange(n)).astype(np.float32)
    if sweeps_on_device(device):
        from lfstream.codec.hint.sweep_batched import sweep_batched

        return sweep_batched(images, offsets, cands, scale, options.box_radius, device)
    cost = _kept_array("cost", (len(cands), *images.shape[1:]))
    sweep_cost(images, offsets, cands / np.float32(scale), cost)
    r = options.box_radius
    if r:
        for k in range(len(cands)):
            cv2.blur(cost[k], (2 * r + 1, 2 * r + 1), dst=cost[k], borderType=cv2.BORDER_REPLICATE)
    out = np.empty(images.shape[1:], np.float32)
    winner_subpixel(cost, cands, out)
    return out


def scene_range(disparity: np.ndarray, margin: float) -> tuple[float, float]:
    """Robust range of a disparity map (1st..99th percentile), widened by ``margin``."""
    lo, hi = np.percentile(disparity, [1, 99]) if disparity.size else (0.0, 0.0)
    return float(lo - margin), float(hi + margin)


def estimate_hint_map(lf: np.ndarray, options: HintOptions = HintOptions(), present: np.ndarray | None = None,
                      search: tuple[float, float] | None = None, axes: np.ndarray | None = None,
                      keep_ring_luma: bool = False, keep_coarse: bool = False, device: str | None = None) -> HintMap:
    """The centre view's disparity at the hint's resolution.

    Args:
        lf: one frame, uint8 or float in [0, 1].
        options: sweep parameters.
        present: ``(U, V)`` mask of views that exist (e.g. an HCI "star").
        search: ``(lo, hi)`` range to sweep (a video's previous frame); ``None``: the options'
            ``max_disparity``, else a coarse pass finds the scene's range.
        axes: the capture's view axes (a video's first frame); ``None``: detected
            (``options.geometry == "auto"``) or the convention.
        keep_ring_luma: fill :attr:`HintMap.ring_luma`.
        keep_coarse: fill :attr:`HintMap.coarse` (block means of the same working map and
            the same median: well under a millisecond).
        device: ``None`` or ``"cpu"``: the sweep on the CPU kernels; ``"cuda"``: the sweep as
            tensor operations there (:func:`sweeps_on_device`; the views' luma, the axes and
            the range pass's texture test stay on the CPU).

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output disparity: ``(H // hint_scale, W // hint_scale)``
    """
    options.validate()
    u, v, h, w, _ = check_lf(lf, allow_video=False)
    frame = np.ascontiguousarray(to_uint8(np.asarray(lf)))
    keys = sweep_views(u, v, present)
    s = min(options.hint_scale, h, w)
    work = max(1, min(options.work_scale, s))
    s -= s % work  # the sent grid is made of whole working-resolution blocks
    hs, ws = max(1, h // s), max(1, w // s)
    identity = np.eye(2, dtype=np.float32)
    if not keys:
        return HintMap(np.zeros((hs, ws), np.float32), s, (0.0, 0.0), identity if axes is None else axes)
    centre = (u // 2, v // 2)
    steps = np.asarray([(a - centre[0], b - centre[1]) for a, b in keys], np.float64)
    grids = _grids(frame, [centre, *keys], work, kept=True)
    f = s // work
    ring_luma = None
    if keep_ring_luma:
        n_ring = 1 + len(_ring_views(u, v, present))  # sweep_views puts the ring first
        # block means of block means are the map's block means (taken before the in-place
        # high-pass; OpenCV's area resize: numpy's mean over a reshape took 4 ms, this 0.2)
        ring_luma = np.stack([cv2.resize(g[: hs * f, : ws * f], (ws, hs), interpolation=cv2.INTER_AREA)
                              for g in grids[:n_ring]]) if f > 1 else grids[:n_ring].copy()
    detection = None
    if axes is None and options.geometry == "auto":
        # the detection (optical flow, a few ms) runs beside the sweeps, which assume the
        # convention meanwhile: it is what almost every capture turns out to follow, and
        # where the detection finds other axes the sweeps run again with them (same result
        # as detecting first, either way)
        from lfstream.codec.workers import beside

        use = _axes_views(keys, u, v, present)
        detection = beside(lambda: _detect_axes(grids, steps, use, work))
    guess = identity if axes is None else np.asarray(axes, np.float32)
    try:
        high_passed = None
        if detection is not None:  # the detection reads the plain grids meanwhile
            high_passed = _kept_array("high_passed", grids.shape)
            np.copyto(high_passed, grids)
            _high_pass(high_passed)
        lo, hi, work_map, grid_offsets = _sweeps(grids, high_passed, keys, (u, v), guess, work, options, search,
                                                  device)
    except BaseException:
        if detection is not None:  # done with this thread's kept grids before they are reused
            wait([detection])
        raise
    if detection is not None:
        axes = np.asarray(detection.result(), np.float32)
        if not np.array_equal(axes, guess):
            lo, hi, work_map, grid_offsets = _sweeps(grids, high_passed, keys, (u, v), axes, work, options, search,
                                                      device)
    else:
        axes = guess
    disp = _sent_grid(work_map, (h, w), s, work, options.median)
    coarse = _sent_grid(work_map, (h, w), 2 * s, work, options.median) if keep_coarse else None
    return HintMap(disp, s, (float(lo), float(hi)), axes, float(np.abs(grid_offsets).max()) or 1.0, ring_luma,
                   coarse)


def _sweeps(grids: np.ndarray, high_passed: np.ndarray | None, keys: list[tuple[int, int]], views: tuple[int, int],
            axes: np.ndarray, work: int, options: HintOptions, search: tuple[float, float] | None,
            device: str | None) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The range pass (where ``search`` is ``None`` and the options fix no range) and the
    working-resolution sweep of :func:`estimate_hint_map` for view ``axes``: the range swept,
    the working map and the whole grid's view offsets. ``high_passed``: ``grids`` through
    :func:`_high_pass` where the caller has it, else ``grids`` is high-passed in place."""
    rows, cols = np.asarray(keys).T
    grid_offsets = view_offsets(views, axes)
    offsets = np.ascontiguousarray(grid_offsets[rows, cols])
    if search is None:
        if options.max_disparity is not None:
            search = (-options.max_disparity, options.max_disparity)
        else:
            factor = max(1, options.coarse_scale // work)
            cs = work * factor
            images = _high_pass(_coarser(grids, factor))
            coarse = _sweep(images, offsets, -options.search_limit, options.search_limit, cs,
                            HintOptions(step=0.5, box_radius=1), device=device)
            # textureless pixels match anywhere: the range comes from the textured ones
            texture = cv2.blur(np.abs(images[0]), (3, 3))
            textured = texture > 0.01
            reach = float(np.abs(offsets).max()) or 1.0
            lo, hi = scene_range(coarse[textured] if textured.mean() > 0.05 else coarse, margin=0.5 * cs / reach)
            search = (max(lo, -options.search_limit), min(hi, options.search_limit))
    lo, hi = search
    if not hi > lo:  # an empty range (or one the search limit cut off entirely): around it
        lo, hi = min(lo, hi) - 0.5, max(lo, hi) + 0.5
    images = high_passed if high_passed is not None else _high_pass(grids)
    return lo, hi, _sweep(images, offsets, lo, hi, work, options, device=device), grid_offsets


def _sent_grid(work_map: np.ndarray, size: tuple[int, int], scale: int, work: int, median: int) -> np.ndarray:
    """The map sent at ``scale``: block means of the working-resolution map (``work`` px
    a cell), median-filtered where it is large enough."""
    h, w = size
    hs, ws = max(1, h // scale), max(1, w // scale)
    f = scale // work
    disp = work_map
    if f > 1:
        disp = cv2.resize(work_map[: hs * f, : ws * f], (ws, hs), interpolation=cv2.INTER_AREA)
    if median > 1 and min(disp.shape) >= median:
        disp = cv2.medianBlur(np.ascontiguousarray(disp, np.float32), median)
    return disp


def estimate_disparity(lf: np.ndarray, options: HintOptions = HintOptions(),
                       present: np.ndarray | None = None) -> np.ndarray:
    """The hint's disparity upsampled (bilinearly) to the views' resolution, for evaluation.

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output: ``(H, W)`` float32, pixels per view step
    """
    hm = estimate_hint_map(lf, options, present)
    h, w = np.asarray(lf).shape[2:4]
    return _upsample(hm.disparity, hm.scale, (h, w))


def disparity_errors(estimate: np.ndarray, truth: np.ndarray, border: int = 15) -> dict:
    """The HCI benchmark's metrics: ``mse_x100`` (MSE times 100) and ``badpix_007`` (share of
    pixels off by more than 0.07), excluding a border as the benchmark does."""
    e = np.asarray(estimate, np.float64)
    t = np.asarray(truth, np.float64)
    if e.shape != t.shape:
        raise LFShapeError(f"disparity shapes differ: {e.shape} vs {t.shape}")
    if border and min(e.shape) > 2 * border:
        e, t = e[border:-border, border:-border], t[border:-border, border:-border]
    diff = e - t
    return {"mse_x100": float(100 * np.mean(diff**2)), "badpix_007": float(np.mean(np.abs(diff) > 0.07))}
