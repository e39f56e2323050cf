"""Depth-based view synthesis: warp the centre view into every view (seed Eq. 3.3).

``L(x, u) = C(x + (u - u0) * d(x, u))`` with lfstream's disparity sign: a point at ``x`` in
the centre view with disparity ``d`` appears at ``x - d * (u - u0)`` in view ``u``, so
view ``u`` samples the centre view at ``x + d * (u - u0)``. Samples outside the centre view
are clamped to its border. A capture with its own view axes ``A``
(:func:`lfstream.lightfield.view_offsets`) uses ``d * A @ (u - u0)`` in place of ``d * (u - u0)``.

Occlusion: the per-view maps ``d(x, u)`` are the centre map forward-splatted into each view
with a z-test (the nearer surface wins); a pixel nothing landed on (a disocclusion, or a
crack where a surface stretches) takes the disparity of its nearest splatted neighbour on
the background side and is sampled at its own position, so a foreground edge neither
smears into the background nor leaves a crack.

The splat is skipped for a view where it cannot matter (:func:`splat_views`): view pixel
``p`` samples at ``p + δ d(q)`` with ``q = p + δ d(q)`` the centre pixel that lands on it, and
without the splat at ``p + δ d(p)``; the two differ by ``|δ| |d(q) - d(p)|``, which to first
order is at most ``|δ| (|δ_u| M_y + |δ_v| M_x)`` with ``M_x = max |∂d/∂x| |d|`` (neighbour
differences) and ``M_y`` the same along ``y``. Where that bound is at most
:data:`SPLAT_TOLERANCE_PX` the view samples with the centre map: on smooth scenes most views
skip the splat at a change of MPSNR within a few thousandths of a dB. The bound costs one
pass over the map.

The same bound is also taken per view row (:func:`splat_rows`), over the centre rows whose
pixels can land in that row: a view splats only its rows near a depth edge or a steep slope,
for the same quality as splatting whole views within a few thousandths of a dB.

The tolerance is one pixel: on the smooth, up-sampled hints the splat changes MPSNR by a
few hundredths of a dB at most, and a tighter tolerance splats many more rows for less than
that. A large parallax still splats (its bound exceeds the tolerance). The measurements
behind this choice are on the docs' experiments page.
"""

from __future__ import annotations

import functools
from concurrent.futures import Future

import numpy as np

from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import MAX_VIEWS_PER_AXIS, check_finite, read_only, to_uint8, view_offsets

#: The largest first-order difference (px) between a view's samples with and without the
#: z-tested splat at which the splat is skipped (:func:`splat_views`, :func:`splat_rows`;
#: one pixel: the module docstring's measurements).
SPLAT_TOLERANCE_PX = 1.0


def splat_views(disparity: np.ndarray, offsets: np.ndarray, tolerance: float = SPLAT_TOLERANCE_PX) -> np.ndarray:
    """Which views the occlusion-aware warp may splat: those where the centre map's own
    samples could be more than ``tolerance`` px from the splatted map's (the module
    docstring's first-order bound); never the centre view. The warp splats the rows of
    these views that :func:`splat_rows` names.

    Args:
        disparity: ``(H, W)`` float32 centre-view disparity, px per view step (finite).
        offsets: ``(U, V, 2)`` displacement of each view per unit disparity
            (:func:`lfstream.lightfield.view_offsets`).
        tolerance: px; 0 splats every view but the centre.

    Shape:
        - output: ``(U, V)`` bool
    """
    from lfstream.codec.warp.splat_kernels import fold_bounds

    mx, my = fold_bounds(read_only(np.ascontiguousarray(disparity, np.float32)))
    return _splat_mask(float(mx), float(my), offsets, tolerance)


def splat_rows(disparity: np.ndarray, offsets: np.ndarray, tolerance: float = SPLAT_TOLERANCE_PX) -> np.ndarray:
    """The view rows the occlusion-aware warp splats: the bound of :func:`splat_views` taken
    per view row over the centre rows whose pixels can reach it, so a view splats only the
    rows near a depth edge or a steep slope and samples the others with the centre map.

    View row ``y`` of a view that moves ``du`` px per unit disparity vertically receives
    centre pixels from rows ``y - r ... y + r`` at most, ``r = ceil(|du| max|d| + 0.5) + 1``
    (:func:`splat_reach`), and a pixel's splatted and unsplatted samples lie on a path
    within those rows; so ``M_x`` and ``M_y`` of the module docstring, taken as maxima over
    those rows only (:func:`lfstream.codec.warp.splat_kernels.row_fold_bounds`), bound the difference
    there. A row is splatted where ``|δ| (|δ_u| M_y + |δ_v| M_x) > tolerance``: every row of
    a view :func:`splat_views` names at most (the maxima over all rows are the larger).

    Args:
        disparity: ``(H, W)`` float32 centre-view disparity, px per view step (finite).
        offsets: ``(U, V, 2)`` displacement of each view per unit disparity.
        tolerance: px; 0 splats every row of every view but the centre.

    Shape:
        - output: ``(U, V, H)`` bool
    """
    return _splat_plan(np.ascontiguousarray(disparity, np.float32), offsets, tolerance)[0]


def splat_reach(max_abs_disparity: float, offsets: np.ndarray) -> np.ndarray:
    """How many rows from its own a centre pixel can land in each view (``ceil(|du| max|d| +
    0.5)``: the splat rounds to the nearest row), plus one row for float32 rounding.

    Shape:
        - output: ``(U, V)`` int64
    """
    du = np.abs(np.asarray(offsets, np.float64)[..., 0])
    return (np.ceil(np.minimum(du * float(max_abs_disparity), 1e9) + 0.5) + 1).astype(np.int64)


def _window_max(a: np.ndarray, r: int) -> np.ndarray:
    """``out[y] = max(a[y - r : y + r + 1])``, clipped at the ends: a sparse table for the
    full windows (``O(H log r)``), running maxima for those the ends clip."""
    h = a.shape[0]
    if r >= h - 1:
        return np.full(h, a.max(initial=0.0), a.dtype)
    y = np.arange(h)
    out = np.empty(h, a.dtype)
    out[:r] = np.maximum.accumulate(a)[np.minimum(y[:r] + r, h - 1)]
    out[h - r:] = np.maximum.accumulate(a[::-1])[::-1][np.maximum(y[h - r:] - r, 0)]
    inner = h - 2 * r  # windows y - r .. y + r wholly inside
    if inner > 0:
        n = 2 * r + 1
        table, span = a, 1
        while 2 * span <= n:  # table[i] = max(a[i : i + 2 * span])
            table = np.maximum(table[:-span], table[span:])
            span *= 2
        out[r:h - r] = np.maximum(table[:inner], table[n - span:n - span + inner])
    return out


def _splat_plan(d: np.ndarray, offsets: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`splat_rows` and :func:`splat_reach` of one centre map (float32, contiguous)."""
    from lfstream.codec.warp.splat_kernels import row_fold_bounds

    h = d.shape[0]
    rx, ry = np.empty(h, np.float32), np.empty(h, np.float32)
    row_fold_bounds(read_only(d), rx, ry)
    reach = splat_reach(float(np.abs(d).max(initial=0.0)), offsets)
    if not _splat_mask(float(rx.max(initial=0.0)), float(ry.max(initial=0.0)), offsets, tolerance).any():
        # no view splats by the whole map's bound, so no row by its rows' (the same values
        # as _rows_from_bounds gives, without its windows: dino, cotton, lytro_translucent)
        return np.zeros((*offsets.shape[:-1], h), bool), reach
    return _rows_from_bounds(rx, ry, reach, offsets, tolerance), reach


def _rows_from_bounds(rx: np.ndarray, ry: np.ndarray, reach: np.ndarray, offsets: np.ndarray,
                      tolerance: float) -> np.ndarray:
    """:func:`splat_rows` from the per-row fold bounds and the views' :func:`splat_reach`
    (shared with the batched torch warp, which computes the same float32 bounds on its
    device)."""
    off = np.asarray(offsets, np.float64)
    du, dv = np.abs(off[..., 0]), np.abs(off[..., 1])
    rx64, ry64 = np.asarray(rx, np.float64), np.asarray(ry, np.float64)
    out = np.zeros((*off.shape[:-1], rx64.shape[0]), bool)
    moving = (du > 0) | (dv > 0)
    for r in np.unique(reach[moving]):
        # rows y - r .. y + r, and the row pairs starting in them (ry[k]: rows k and k + 1;
        # the last pair reaches one row further: a bound a little larger, never smaller)
        mx = _window_max(rx64, int(r))[None]
        my = _window_max(ry64, int(r))[None]
        sel = moving & (reach == r)
        a, b = du[sel][:, None], dv[sel][:, None]
        out[sel] = np.hypot(a, b) * (a * my + b * mx) > tolerance
    return out


def _occlusion_plan(d: np.ndarray, offsets: np.ndarray, occlusion: bool) -> tuple[np.ndarray, np.ndarray]:
    """The view rows splatted with ``occlusion`` (:func:`splat_rows`) and each view's reach;
    none without it."""
    if occlusion:
        return _splat_plan(d, offsets, SPLAT_TOLERANCE_PX)
    return np.zeros((*offsets.shape[:-1], d.shape[0]), bool), np.zeros(offsets.shape[:-1], np.int64)


def _splat_mask(mx: float, my: float, offsets: np.ndarray, tolerance: float) -> np.ndarray:
    """:func:`splat_views` from the fold bounds."""
    off = np.asarray(offsets, np.float64)
    du, dv = np.abs(off[..., 0]), np.abs(off[..., 1])
    bound = np.hypot(du, dv) * (du * my + dv * mx)
    return (bound > tolerance) & ((du > 0) | (dv > 0))


def _linear_taps(n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's INTER_LINEAR resize taps from ``n_in`` to ``n_out`` samples (half-pixel
    centres, clamped at the ends): per output sample the two input indices and the weight
    of the first, computed in float64 (OpenCV's own float32 weights are
    :func:`lfstream.codec.gains.resize_taps`, the flat decode's; these stay because the
    warp's bytes, on the CPU and the GPU, follow them)."""
    f = (np.arange(n_out, dtype=np.float64) + 0.5) * (n_in / n_out) - 0.5
    i0 = np.floor(f)
    frac = f - i0
    frac[i0 < 0] = 0.0
    i0 = np.clip(i0, 0, n_in - 1).astype(np.int64)
    frac[i0 >= n_in - 1] = 0.0
    i1 = np.minimum(i0 + 1, n_in - 1)
    return np.stack([i0, i1], axis=1), (1.0 - frac).astype(np.float32)


def warp_views(
    centre: np.ndarray,
    disparity: np.ndarray | float,
    views: tuple[int, int],
    occlusion: bool = True,
    gains: np.ndarray | None = None,
    axes: np.ndarray | None = None,
    beside: Future | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Synthesises a light field from its centre view and the centre view's disparity.

    One fused, parallel kernel does every view: splatting and hole filling (occlusion),
    bilinear sampling in 1/1024-pixel fixed point and the
    per-view shading gains.

    Args:
        centre: ``(H, W, C)`` uint8 or float in ``[0, 1]``.
        disparity: ``(H, W)`` centre-view disparity in pixels per view step, or a constant.
        views: ``(U, V)`` of the output.
        occlusion: per-view disparity by z-tested forward splatting where it can matter
            (:func:`splat_rows`; see the module docstring).
        gains: ``(U, V, gh, gw, 1 or C)`` per-view gain maps (:mod:`lfstream.codec.gains`),
            bilinearly up-sampled and multiplied in; ``None``: none.
        axes: ``(2, 2)`` view axes of the capture (:func:`lfstream.lightfield.view_offsets`);
            ``None``: the convention.
        beside: work running on another thread meanwhile (the decoder's residual layer):
            until it is done the views are warped on this thread alone, a few at a time,
            the rest then on every thread (:data:`BESIDE_CHUNK_VIEWS`); the same pixels.
        out: where to write the views (``(U, V, H, W, C)`` uint8, C-contiguous; returned):
            a frame of a caller's video array, which then needs no copy; ``None``: a new array.

    Shape:
        - output: ``(U, V, H, W, C)`` uint8
    """
    if centre.ndim != 3:
        raise LFShapeError(f"centre: expected (H, W, C), got shape {tuple(centre.shape)}")
    h, w, c = centre.shape
    u, v = _check_views(views)
    d = np.broadcast_to(np.asarray(disparity, np.float32), (h, w))
    check_finite(d, "disparity")
    offsets = view_offsets((u, v), axes)
    src = np.ascontiguousarray(to_uint8(np.asarray(centre)))
    gains = _check_gains(gains, (u, v), c)
    _check_out(out, (u, v, h, w, c))
    if not np.any(d):  # every view is the centre view: copies, or OpenCV's gain multiply of it
        result = np.empty((u, v, h, w, c), np.uint8) if out is None else out
        if gains is None:
            result[...] = src
            return result
        from lfstream.codec.gains import apply_gains

        return apply_gains(np.broadcast_to(src, (u, v, h, w, c)), gains, out=result)
    d = np.ascontiguousarray(d)
    return _warp_kernel(src, d, None, offsets, *_occlusion_plan(d, offsets, occlusion), gains, beside, out)


def _check_out(out: np.ndarray | None, shape: tuple[int, ...], dtype=np.uint8) -> None:
    """Refuses an output array the kernel cannot write in place."""
    if out is not None and (not isinstance(out, np.ndarray) or out.shape != shape or out.dtype != dtype
                            or not out.flags.c_contiguous or not out.flags.writeable):
        got = f"{out.shape} {out.dtype}" if isinstance(out, np.ndarray) else type(out).__name__
        raise LFValueError(f"out: a writeable C-contiguous {np.dtype(dtype).name} array of shape {shape}, got {got}")


def warp_views_at(centre: np.ndarray, disparity: np.ndarray, views: tuple[int, int], keys: list[tuple[int, int]],
                  gains: np.ndarray | None = None, axes: np.ndarray | None = None) -> np.ndarray:
    """:func:`warp_views` for the views ``keys`` of a ``views`` grid only (the same kernel and
    pixels; the encoder's check of its own prediction needs a few views, not all).

    Args:
        centre: ``(H, W, C)`` uint8 or float in ``[0, 1]``.
        disparity: ``(H, W)`` centre-view disparity, px per view step.
        views: ``(U, V)`` of the grid ``keys`` index.
        keys: ``(u, v)`` of the views to synthesise.
        gains: ``(U, V, gh, gw, 1 or C)`` per-view gain maps of the whole grid, or ``None``.
        axes: ``(2, 2)`` view axes; ``None``: the convention.

    Shape:
        - output: ``(len(keys), H, W, C)`` uint8
    """
    if centre.ndim != 3 or np.ndim(disparity) != 2 or np.shape(disparity) != centre.shape[:2]:
        raise LFShapeError(f"centre (H, W, C) and disparity (H, W) must agree; got {tuple(centre.shape)} "
                           f"and {np.shape(disparity)}")
    u, v = _check_views(views)
    rows, cols = np.asarray(keys, np.int64).reshape(-1, 2).T
    if np.any(rows < 0) or np.any(rows >= u) or np.any(cols < 0) or np.any(cols >= v):
        raise LFValueError(f"keys: views of a {u}x{v} grid, got {list(keys)}")
    d = np.ascontiguousarray(disparity, np.float32)
    check_finite(d, "disparity")
    src = np.ascontiguousarray(to_uint8(np.asarray(centre)))
    gains = _check_gains(gains, (u, v), src.shape[2])
    offsets = np.ascontiguousarray(view_offsets((u, v), axes)[rows, cols][None])  # a 1 x len(keys) grid
    if gains is not None:
        gains = np.ascontiguousarray(gains[rows, cols][None])
    return _warp_kernel(src, d, None, offsets, *_occlusion_plan(d, offsets, True), gains)[0]


def _check_views(views: tuple[int, int], name: str = "views") -> tuple[int, int]:
    """``(U, V)``, each in 1..MAX_VIEWS_PER_AXIS (else LFValueError naming ``name``)."""
    u, v = views
    if not (1 <= u <= MAX_VIEWS_PER_AXIS and 1 <= v <= MAX_VIEWS_PER_AXIS):
        raise LFValueError(f"{name}: each in 1..{MAX_VIEWS_PER_AXIS}, got {tuple(views)}")
    return u, v


def _check_gains(gains: np.ndarray | None, views: tuple[int, int], c: int) -> np.ndarray | None:
    """The gain maps as float32, or ``None`` where there are none or all are 1."""
    from lfstream.codec.gains import check_gain_maps

    if gains is None:
        return None
    gains = check_gain_maps(gains, views, c)
    return None if np.all(np.abs(gains - 1.0) < 1e-6) else gains


#: Relative cost of warping one view in the fused kernel (:func:`deal_views`), by the taps
#: its samples need: four (a view off both axes), two along a row or a column (on the
#: centre's row or column), none (the centre view, a copy); and what a z-tested splat with
#: hole filling adds; the ratios of per-view times measured on one thread.
VIEW_COST_TAPS = {"all": 1.0, "column": 0.8, "row": 0.65, "centre": 0.2}
VIEW_COST_SPLAT = 0.5


def deal_views(offsets: np.ndarray, splat: np.ndarray, tasks: int,
               views: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Shares the views of one warp among ``tasks`` parallel tasks by estimated cost
    (:data:`VIEW_COST_TAPS`, :data:`VIEW_COST_SPLAT`): the costliest view first, each to the
    least loaded task (ties to the lower view index, so the deal is deterministic). Which
    task warps a view changes no byte of it.

    Round-robin dealing, which this replaces, gave a 3x3 grid's four corners (four taps,
    splatted) and the centre to one task and the four edge views (two taps) to the other.

    Args:
        offsets: ``(U, V, 2)`` displacement of each view per unit disparity.
        splat: ``(U, V)`` the share of each view's rows splatted (bool: all or none).
        tasks: how many to deal to (at most one per view is used).
        views: the flat view indices ``u * V + v`` to deal; ``None``: every view.

    Shape:
        - output: ``order`` ``(N,)`` int64 flat view indices task by task (N: the views
          dealt), and ``starts`` ``(tasks + 1,)`` int64: task ``t`` warps
          ``order[starts[t]:starts[t + 1]]``, ``tasks = min(tasks, N)`` (at least 1). With
          ``tasks=1`` the order is the costliest view first.
    """
    du = tuple((np.asarray(offsets[..., 0]).ravel() != 0).tolist())
    dv = tuple((np.asarray(offsets[..., 1]).ravel() != 0).tolist())
    # the share of rows to a tenth: the deal is an estimate, and a stream's frames then share it
    share = tuple(np.round(np.asarray(splat, np.float64).ravel(), 1).tolist())
    subset = None if views is None else tuple(int(k) for k in np.asarray(views).ravel())
    order, starts = _deal(du, dv, share, max(1, int(tasks)), subset)
    return order.copy(), starts.copy()


@functools.lru_cache(maxsize=64)  # a stream deals the same grid frame after frame
def _deal(du: tuple[bool, ...], dv: tuple[bool, ...], splat: tuple[float, ...],
          tasks: int, subset: tuple[int, ...] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`deal_views` of the views' displacement flags (nonzero per axis)."""
    taps = {(True, True): VIEW_COST_TAPS["all"], (True, False): VIEW_COST_TAPS["column"],
            (False, True): VIEW_COST_TAPS["row"], (False, False): VIEW_COST_TAPS["centre"]}
    cost = [taps[a, b] + VIEW_COST_SPLAT * s for a, b, s in zip(du, dv, splat)]
    views = list(range(len(cost))) if subset is None else list(subset)
    tasks = max(1, min(tasks, len(views)))
    load = [0.0] * tasks
    dealt: list[list[int]] = [[] for _ in range(tasks)]
    for k in sorted(views, key=lambda i: (-cost[i], i)):
        t = min(range(tasks), key=load.__getitem__)  # the first least loaded task
        dealt[t].append(k)
        load[t] += cost[k]
    order = np.array([k for views in dealt for k in views], np.int64)
    starts = np.cumsum([0] + [len(views) for views in dealt]).astype(np.int64)
    return order, starts


#: Views a call warps on the calling thread alone while other work runs beside the warp
#: (:func:`warp_views`'s ``beside``: the decoder's residual layer, which dav1d decodes on one
#: thread). The warp's kernel deals its views to its threads before it starts, so a third
#: busy thread on two cores slowed both (measured, synthetic 7x7x375x540 with its residual at
#: 0.01 bpp: the residual decode 8.3 -> 16 ms, the warp 17.5 -> 25 ms); one thread beside it
#: leaves each its core (both unchanged), and the views left when it is done go to every
#: thread. Same pixels. Decodes, alternating processes, 8 rounds: the synthetic clip's
#: rate-control streams at 0.08 and 0.04 bpp 50.6 -> 44.0 and 42.6 -> 39.5 ms, lytro_bikes
#: best q80 with a residual at q60 60.9 -> 48.7 ms. Where the residual decode is nearly done
#: when the warp starts there is nothing to gain: the decoder hands it over only from
#: :data:`lfstream.codec.decoder.BESIDE_MIN_BITS`.
BESIDE_CHUNK_VIEWS = 4


def _warp_kernel(src: np.ndarray, d: np.ndarray, view_disp: np.ndarray | None, offsets: np.ndarray,
                 splat: np.ndarray, reach: np.ndarray, gains: np.ndarray | None,
                 beside: Future | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """Runs the fused warp (:func:`lfstream.codec.warp.kernels.warp_all_views`) over every
    channel triple of ``src`` (H, W, C) uint8; ``splat``: (U, V, H) bool, the view rows
    splatted (:func:`splat_rows`), ``reach``: (U, V) int64 (:func:`splat_reach`);
    ``beside`` and ``out`` (checked by the caller): :func:`warp_views`'s."""
    import numba

    from lfstream.codec.warp.kernels import _LANES, pack_lanes, warp_all_views

    h, w, c = src.shape
    u, v = offsets.shape[:2]
    if gains is None:
        gains = np.ones((0, 0, 1, 1, 1), np.float32)
        rows, row_w = np.zeros((h, 2), np.int64), np.ones(h, np.float32)
        cols, col_w = np.zeros((w, 2), np.int64), np.ones(w, np.float32)
    else:
        rows, row_w = _linear_taps(h, gains.shape[2])
        cols, col_w = _linear_taps(w, gains.shape[3])
    if view_disp is None:
        view_disp = np.zeros((0, 0, 1, 1), np.float32)
    share = splat.mean(axis=-1)
    threads = numba.get_num_threads()
    order, starts = deal_views(offsets, share, threads)
    result = np.empty((u, v, h, w, c), np.uint8) if out is None else out
    out = result.reshape(u, v, h, w * c)  # the rows the kernel writes (a view)
    packed = np.empty((h + 2) * (w + 2), np.uint64)  # with a one-pixel border (pack_lanes)
    src, d, view_disp = read_only(src), read_only(d), read_only(view_disp)  # one signature (read_only)
    for ch0 in range(0, c, _LANES):  # three channels per pass, in the lanes of one uint64
        n_ch = min(_LANES, c - ch0)
        pack_lanes(src, ch0, n_ch, packed)

        def warp(order: np.ndarray, starts: np.ndarray, ch0: int = ch0, n_ch: int = n_ch) -> None:
            warp_all_views(packed, c, ch0, n_ch, d, view_disp, offsets, splat, reach, gains, rows, row_w, cols,
                           col_w, order, starts, out)

        # beside other work: one pass only (the views of a single channel triple)
        if beside is not None and threads > 1 and c <= _LANES and not beside.done():
            ranked, _ = deal_views(offsets, share, 1)  # the costliest view first
            order, starts = deal_views(offsets, share, threads, ranked[_warp_beside(beside, ranked, warp):])
        if len(order):
            warp(order, starts)
    return result


def _warp_beside(beside: Future, ranked: np.ndarray, warp) -> int:
    """Warps views of ``ranked`` in order, :data:`BESIDE_CHUNK_VIEWS` a call, on the
    calling thread alone (numba's thread count is per thread; restored) until ``beside``
    is done; returns how many it warped."""
    from lfstream.codec.workers import single_numba_thread

    done = 0
    with single_numba_thread():
        while done < len(ranked) and not beside.done():
            chunk = np.ascontiguousarray(ranked[done:done + BESIDE_CHUNK_VIEWS])
            warp(chunk, np.array([0, len(chunk)], np.int64))
            done += len(chunk)
    return done


def view_disparities(disparity: np.ndarray, views: tuple[int, int], occlusion: bool = True,
                     axes: np.ndarray | None = None, corrections: np.ndarray | None = None,
                     out: np.ndarray | None = None) -> np.ndarray:
    """The per-view disparity maps :func:`warp_views` samples each view with: the centre map
    forward-splatted into the view, holes filled from the background side (see the module
    docstring; only in the rows where it can matter, :func:`splat_rows`), or the centre map itself
    without ``occlusion``. ``warp_views_per_view`` with these maps gives exactly
    ``warp_views``'s light field; Depth-Net refines them.

    Args:
        disparity: ``(H, W)`` centre-view disparity in pixels per view step.
        views: ``(U, V)``.
        occlusion: splat with a z-test (as :func:`warp_views`).
        axes: ``(2, 2)`` view axes of the capture; ``None``: the convention.
        corrections: ``(3, H, W)`` maps ``c0, cy, cx`` of Depth-Net's refiner, added to
            each view's map as :func:`lfstream.models.depth_net.view_correction` computes
            them (float32, the same values to the bit), in the same pass: 6 ms a 7x7x375x540
            frame against 5 for the plain maps and 12 more for 49 numpy sums after them.
        out: a ``(U, V, H, W)`` float32 C-contiguous array to write the maps into.

    Shape:
        - output: ``(U, V, H, W)`` float32
    """
    d = np.ascontiguousarray(disparity, np.float32)
    if d.ndim != 2:
        raise LFShapeError(f"disparity: expected (H, W), got shape {tuple(d.shape)}")
    u, v = _check_views(views)
    check_finite(d, "disparity")
    if corrections is None:
        corr = np.empty((0, *d.shape), np.float32)
    else:
        corr = np.ascontiguousarray(corrections, np.float32)
        if corr.shape != (3, *d.shape):
            raise LFShapeError(f"corrections: expected (3, {d.shape[0]}, {d.shape[1]}), got {tuple(corr.shape)}")
        check_finite(corr, "corrections")
    from lfstream.codec.warp.splat_kernels import splat_all_views

    _check_out(out, (u, v, *d.shape), np.float32)
    if out is None:
        out = np.empty((u, v, *d.shape), np.float32)
    offsets = view_offsets((u, v), axes)
    splat_all_views(read_only(d), offsets, *_occlusion_plan(d, offsets, occlusion), read_only(corr), out)
    return out


def warp_views_per_view(centre: np.ndarray, disparities: np.ndarray, axes: np.ndarray | None = None,
                        gains: np.ndarray | None = None) -> np.ndarray:
    """``L(x, u) = C(x + (u - u0) d(x, u))`` with one disparity map per view (Depth-Net's
    output, seed Fig. 3.2), in the same fused kernel as :func:`warp_views` (bilinear in
    1/1024-pixel fixed point, border replicated, gains multiplied in).

    Args:
        centre: ``(H, W, C)`` uint8 or float in ``[0, 1]``.
        disparities: ``(U, V, H, W)`` px per view step.
        axes: ``(2, 2)`` view axes (:func:`lfstream.lightfield.view_offsets`); ``None``: the
            convention.
        gains: ``(U, V, gh, gw, 1 or C)`` per-view gain maps, or ``None``.

    Shape:
        - output: ``(U, V, H, W, C)`` uint8
    """
    if centre.ndim != 3 or disparities.ndim != 4 or disparities.shape[2:] != centre.shape[:2]:
        raise LFShapeError(f"centre (H, W, C) and disparities (U, V, H, W) must agree; got {tuple(centre.shape)} "
                           f"and {tuple(disparities.shape)}")
    u, v = _check_views(disparities.shape[:2], "disparities' views")
    maps = np.ascontiguousarray(disparities, np.float32)
    check_finite(maps, "disparities")
    src = np.ascontiguousarray(to_uint8(np.asarray(centre)))
    gains = _check_gains(gains, (u, v), src.shape[2])
    return _warp_kernel(src, np.ascontiguousarray(maps[u // 2, v // 2]), maps, view_offsets((u, v), axes),
                        np.zeros((u, v, maps.shape[2]), bool), np.zeros((u, v), np.int64), gains)


__all__ = ["SPLAT_TOLERANCE_PX", "VIEW_COST_TAPS", "VIEW_COST_SPLAT", "BESIDE_CHUNK_VIEWS", "deal_views", "splat_views",
           "splat_rows", "splat_reach", "view_disparities", "warp_views", "warp_views_at", "warp_views_per_view"]
