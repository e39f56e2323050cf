"""The rig's view axes, detected from the views' flows (:func:`estimate_view_axes`): a camera
array whose rows are not the convention's (turned, mirrored) is swept along its own axes."""

from __future__ import annotations

import cv2
import numpy as np

from lfstream.codec.hint.grids import _coarser, _grids, _ring_views, sweep_views
from lfstream.codec.hint.options import MAX_AXIS_ENTRY, HintOptions
from lfstream.lightfield import check_lf, to_uint8

# view-axes detection (see the module docstring)
_AXES_SCALE = 4  # the detection's resolution divisor; an accepted fit is refined at the sweep's working one


_AXES_MAX_GAIN = 0.5  # the fit's mean flow residual must be below this share of the convention's


_AXES_MIN_SHIFT = 0.25  # px of the full view a warped pixel must move for the axes to matter


_AXES_SAMPLES = 2048  # textured pixels the fit keeps at most (every k-th: a few thousand fix 4 numbers)


# The detection's flows see luma divided by its local mean over this box (pixels at
# 1 / _AXES_SCALE): vignetting darkens outer views unevenly and pulled the flows of the
# synthetic clip (noise, vignetting 0.3) so far that its flipped or transposed grid went
# undetected (28.3 / 29.2 dB against 31.6 in its own order). The refinement keeps plain
# luma: on toys_array it fits 1.08 there, 1.49 on divided luma (the fast preset's decode:
# 19.31 against 16.98 dB).
_AXES_SHADING_BOX = 15


def _flows(images: np.ndarray, scale: int, preset: int, shading_free: bool = False) -> np.ndarray:
    """Dense optical flow (OpenCV's DIS) from ``images[0]`` to each other image, in pixels
    of the full view: ``images[0](x) ~ images[j](x + flow[j - 1](x))``. ``shading_free``:
    each image divided by its local mean first (15 x 15 box), so that vignetting, which
    darkens the outer views unevenly, does not pull the flow (:data:`_AXES_SHADING_BOX`).

    Shape:
        - images: ``(1 + J, h, w)`` float32 in [0, 1]
        - output: ``(J, h, w, 2)`` float32, ``(dx, dy)``
    """
    dis = cv2.DISOpticalFlow_create(preset)
    if shading_free:
        box = (_AXES_SHADING_BOX, _AXES_SHADING_BOX)
        images = [img / (cv2.blur(img, box, borderType=cv2.BORDER_REFLECT) + np.float32(1e-3)) * np.float32(0.5)
                  for img in images]
    as8 = [np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8) for img in images]
    return np.stack([dis.calc(as8[0], img, None) for img in as8[1:]]) * np.float32(scale)


def _fit_axes(images: np.ndarray, steps: np.ndarray, scale: int, preset: int,
              shading_free: bool = False) -> tuple[np.ndarray, bool]:
    """The view axes that best explain the flows from the centre image to the others, and
    whether they explain them clearly better than the convention (and matter).

    Every view j moves a centre pixel by ``-d(x) * A @ steps[j]``: over the views the flows
    of a pixel are one vector ``g = (A @ steps[j])_j`` times a per-pixel scalar, so ``g``
    is the leading eigenvector of the flows' second moments (textured pixels, outliers
    dropped twice), and ``A`` its least-squares fit. Normalised so that a step along ``v``
    moves a point by ``-d`` along the image axis it mostly moves along: ``x`` as in the
    convention (``A[1, 1] = 1``), or ``y`` for a grid stored with its view axes swapped or
    turned a quarter (``A[0, 1] = 1``, e.g. ``(V, U)`` order: ``A`` close to ``[[0, 1], [1,
    0]]``); the same with column 0 where the grid has one column.

    Args:
        images: ``(1 + J, h, w)`` luma at ``1 / scale``; images[0] the centre view.
        steps: ``(J, 2)`` view steps ``(u - u0, v - v0)`` of the other images.
        preset: OpenCV's DIS preset.
        shading_free: the flows on luma divided by its local mean (:func:`_flows`).
    """
    from lfstream.codec.hint.kernels import axes_moments, axes_moved, axes_prune, axes_residuals

    identity = np.eye(2, dtype=np.float32)
    _, h, w = images.shape
    # textured pixels away from the border (where points leave the view) carry the fit
    by, bx = max(2, h // 10), max(2, w // 10)
    if (h - 2 * by) * (w - 2 * bx) < 64:
        return identity, False
    gy, gx = np.gradient(images[0][by - 1:h - by + 1, bx - 1:w - bx + 1])
    texture = np.hypot(gx, gy)[1:-1, 1:-1].ravel()
    sel = np.flatnonzero(texture > np.median(texture))
    if sel.size < 32:
        return identity, False
    sel = sel[::-(-sel.size // _AXES_SAMPLES)]
    flows = _flows(images, scale, preset, shading_free)[:, by:h - by, bx:w - bx].reshape(len(steps), -1, 2)[:, sel]
    f = np.empty((sel.size, 2 * len(steps)), np.float64)  # one row per pixel: dy_j, dx_j
    f[:, 0::2] = flows[..., 1].T
    f[:, 1::2] = flows[..., 0].T
    weight = np.sqrt(texture[sel]).astype(np.float64)
    if not np.all(np.isfinite(f)):
        return identity, False
    k = np.zeros((2 * len(steps), 4))
    k[0::2, 0:2] = steps
    k[1::2, 2:4] = steps
    n = sel.size
    moments = np.empty((f.shape[1], f.shape[1]))
    r = np.empty(n)
    for _ in range(3):
        axes_moments(f, weight, n, moments)
        g = np.ascontiguousarray(np.linalg.eigh(moments)[1][:, -1])
        kept = axes_prune(g, f, weight, n, r, 3.0, 32)
        if not kept:
            break
        n = kept

    def mean_residual(line: np.ndarray) -> float:
        axes_residuals(line, f, n, r)
        return float(np.mean(r[:n]))

    a = np.linalg.lstsq(k, g, rcond=None)[0].reshape(2, 2)
    has_u, has_v = bool(np.any(steps[:, 0])), bool(np.any(steps[:, 1]))
    col = 1 if has_v else 0
    ref = a[int(np.argmax(np.abs(a[:, col]))), col]  # [1, 1] unless the grid is transposed or turned
    if abs(ref) < 0.1 * (np.abs(a).max() + 1e-12):  # a v step barely moves points: not a light field
        return identity, False
    a = a / ref
    if not has_u:
        a[:, 0] = (1.0, 0.0)
    if not has_v:
        a[:, 1] = (0.0, 1.0)
    if not np.all(np.isfinite(a)) or np.abs(a).max() > MAX_AXIS_ENTRY:
        return identity, False
    better = mean_residual(k @ a.ravel()) < _AXES_MAX_GAIN * mean_residual(k @ identity.ravel())
    # how far the axes move a warped pixel against the convention, at the outermost view
    moved = np.linalg.norm(steps @ a.T, axis=1)
    change = np.linalg.norm(steps @ (a - identity).T, axis=1) / np.maximum(moved, 1e-9)
    axes_moved(f, n, np.ascontiguousarray(change, np.float64), r)
    shift = float(np.percentile(r[:n], 98))
    return a.astype(np.float32), bool(better and shift >= _AXES_MIN_SHIFT)


def warm_axes_fit() -> None:
    """Loads the kernels of the view axes' fit (:func:`_fit_axes`) with the argument types it
    calls them with: a stream's warm-up frame is too small for the detection to reach its
    fit, which would otherwise load them (or compile them, on a fresh install) in the first
    timed frame."""
    from lfstream.codec.hint.kernels import axes_moments, axes_moved, axes_prune, axes_residuals

    n, views = 32, 2
    flows = np.zeros((n, 2 * views))
    weight, r = np.ones(n), np.empty(n)
    axes_moments(flows, weight, n, np.empty((2 * views, 2 * views)))
    line = np.ones(2 * views)
    axes_prune(line, flows, weight, n, r, 3.0, n)
    axes_residuals(line, flows, n, r)
    axes_moved(flows, n, np.ones(views), r)


def _axes_views(keys: list[tuple[int, int]], u: int, v: int, present: np.ndarray | None) -> list[int]:
    """Which sweep views (:func:`sweep_views`) the axes detection uses: of the outer ring
    (the longest flows, and the fit it was tuned on), those on the centre's row and column
    (pure steps along one axis) where each axis of the grid has one, else the whole ring."""
    centre = (u // 2, v // 2)
    keys = keys[: len(_ring_views(u, v, present))]  # sweep_views puts the ring first
    on_axis = [j for j, (a, b) in enumerate(keys) if (a == centre[0]) != (b == centre[1])]
    u_ok = any(keys[j][0] != centre[0] for j in on_axis) or all(a == centre[0] for a, _ in keys)
    v_ok = any(keys[j][1] != centre[1] for j in on_axis) or all(b == centre[1] for _, b in keys)
    return on_axis if on_axis and u_ok and v_ok else list(range(len(keys)))


def _detect_axes(grids: np.ndarray, steps: np.ndarray, use: list[int], work: int) -> np.ndarray:
    """The view axes of a frame from its sweep grids (centre first, then the views of
    ``steps``), by optical flow on the views ``use``: detected at ``1 / _AXES_SCALE`` on
    OpenCV's fast preset and luma freed of shading (every stream pays this, a few
    milliseconds), refined at the working resolution on the medium preset for captures off
    the convention only (where the refinement's fit is not accepted, the detection's axes)."""
    factor = max(1, _AXES_SCALE // work)
    grids = grids[[0, *(1 + j for j in use)]]
    steps = steps[use]
    coarse = _coarser(grids, factor) if factor > 1 else grids
    if min(coarse.shape[1:]) < 16:
        return np.eye(2, dtype=np.float32)
    axes, found = _fit_axes(coarse, steps, work * factor, cv2.DISOPTICAL_FLOW_PRESET_FAST, shading_free=True)
    if not found:
        return np.eye(2, dtype=np.float32)
    fine, found = _fit_axes(grids, steps, work, cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return fine if found else axes


def estimate_view_axes(lf: np.ndarray, present: np.ndarray | None = None,
                       work_scale: int = HintOptions.work_scale) -> np.ndarray:
    """The view axes of a light field (:func:`lfstream.lightfield.view_offsets`): the
    identity where it follows the convention, else the 2x2 matrix its views move along.

    Shape:
        - lf: ``(U, V, H, W, C)``
        - output: ``(2, 2)`` float32
    """
    u, v, h, w, _ = check_lf(lf, allow_video=False)
    frame = np.ascontiguousarray(to_uint8(np.asarray(lf)))
    keys = sweep_views(u, v, present)
    centre = (u // 2, v // 2)
    if not keys:
        return np.eye(2, dtype=np.float32)
    steps = np.asarray([(a - centre[0], b - centre[1]) for a, b in keys], np.float64)
    return _detect_axes(_grids(frame, [centre, *keys], work_scale), steps, _axes_views(keys, u, v, present),
                        work_scale)
