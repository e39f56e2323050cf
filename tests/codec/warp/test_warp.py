"""The decoder's fused warp against the implementation it replaced: per-view sampling maps
(z-tested forward splatting, background-side hole filling) from plain Python, OpenCV's
bilinear remap, then OpenCV's up-sampled per-view gains."""

import cv2
import numba
import numpy as np
import pytest

from lfstream.codec.gains import apply_gains
from lfstream.codec.warp import cpu as warp_module
from lfstream.codec.warp.cpu import (
    SPLAT_TOLERANCE_PX,
    VIEW_COST_SPLAT,
    VIEW_COST_TAPS,
    deal_views,
    splat_reach,
    splat_rows,
    splat_views,
    view_disparities,
    warp_views,
    warp_views_at,
    warp_views_per_view,
)
from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import view_offsets
from lfstream.synth import synth_clip


def _reference_maps(disp: np.ndarray, n_u: int, n_v: int, occlusion: bool, axes=None, splat=None) -> np.ndarray:
    """maps[u, v, y, x] = (x_src, y_src), written out in plain Python: z-tested forward splatting
    of every centre pixel, holes given the disparity of their background-side neighbour, in
    the view rows ``splat`` (default: those :func:`splat_rows` names, with ``occlusion``);
    the centre map in the others."""
    h, w = disp.shape
    maps = np.empty((n_u, n_v, h, w, 2), np.float32)
    offsets = view_offsets((n_u, n_v), axes)
    if splat is None:
        splat = splat_rows(disp, offsets) if occlusion else np.zeros((n_u, n_v, h), bool)
    for u in range(n_u):
        for v in range(n_v):
            du, dv = offsets[u, v]
            if not splat[u, v].any() or (du == 0 and dv == 0):
                for y in range(h):
                    for x in range(w):
                        d = disp[y, x]
                        maps[u, v, y, x] = (x + d * dv, y + d * du)
                continue
            view = np.full((h, w), -np.inf, np.float32)
            for y in range(h):
                for x in range(w):
                    d = disp[y, x]
                    iy, ix = int(np.floor(y - d * du + 0.5)), int(np.floor(x - d * dv + 0.5))
                    if 0 <= iy < h and 0 <= ix < w and d > view[iy, ix]:
                        view[iy, ix] = d
            for y in range(h):
                row = view[y]
                holes = ~np.isfinite(row)
                if not splat[u, v, y]:
                    for x in range(w):
                        maps[u, v, y, x] = (x + disp[y, x] * dv, y + disp[y, x] * du)
                    continue
                for x in range(w):
                    if not holes[x]:
                        maps[u, v, y, x] = (x + row[x] * dv, y + row[x] * du)
                        continue
                    left = next((i for i in range(x - 1, -1, -1) if not holes[i]), None)
                    right = next((i for i in range(x + 1, w) if not holes[i]), None)
                    if left is None and right is None:
                        maps[u, v, y, x] = (x + disp[y, x] * dv, y + disp[y, x] * du)
                        continue
                    if left is None or (right is not None and row[right] < row[left]):
                        src = right
                    else:
                        src = left
                    # the background side's disparity, sampled from the hole pixel's own position
                    maps[u, v, y, x] = (x + row[src] * dv, y + row[src] * du)
    return maps


def _reference_warp(centre, disp, views, occlusion, gains=None, axes=None):
    maps = _reference_maps(disp, *views, occlusion, axes)
    out = np.empty((*views, *centre.shape), np.uint8)
    for u in range(views[0]):
        for v in range(views[1]):
            out[u, v] = cv2.remap(centre, maps[u, v], None, cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REPLICATE).reshape(centre.shape)
    return apply_gains(out, gains) if gains is not None else out


def _scene(seed: int = 5, size=(30, 38)):
    clip = synth_clip(1, 5, size, seed=seed, layers=3, motion=0, camera_pan=0, disparity_range=(-1.6, 2.2))
    return clip.lf[0, 2, 2], clip.disparity[0, 2, 2].astype(np.float32)


def _assert_close(got, ref, mean_tol=0.08):
    # one rounding step apart: OpenCV interpolates in float, the kernel in 1/1024 pixel
    # fixed point; where a splat position lies within float32 rounding of a half pixel
    # (fastmath may fuse the multiply-add), a pixel may come from the neighbouring source:
    # allowed on 0.5 % of samples (measured 0.09 % on these slanted planes, mean 0.05);
    # the reference rounds again after its gain multiply (mean_tol 0.25 there)
    diff = np.abs(got.astype(int) - ref.astype(int))
    assert (diff <= 1).mean() > 0.995
    assert diff.mean() < mean_tol


@pytest.mark.parametrize("occlusion", [True, False])
def test_fused_warp_matches_remap_of_reference_maps(occlusion):
    centre, disp = _scene()
    _assert_close(warp_views(centre, disp, (5, 3), occlusion=occlusion),
                  _reference_warp(centre, disp, (5, 3), occlusion))


def test_fused_warp_applies_gains_like_resize_and_multiply(rng):
    centre, disp = _scene(seed=8)
    gains = rng.uniform(0.6, 1.5, (3, 3, 4, 5, 3)).astype(np.float32)
    _assert_close(warp_views(centre, disp, (3, 3), gains=gains), _reference_warp(centre, disp, (3, 3), True, gains),
                  0.25)
    grey = rng.uniform(0.6, 1.5, (3, 3, 2, 2, 1)).astype(np.float32)  # one gain for every channel
    _assert_close(warp_views(centre, disp, (3, 3), gains=grey), _reference_warp(centre, disp, (3, 3), True, grey),
                  0.25)
    # gains of 1 change nothing
    ones = np.ones((3, 3, 2, 2, 3), np.float32)
    assert (warp_views(centre, disp, (3, 3), gains=ones) == warp_views(centre, disp, (3, 3))).all()
    with pytest.raises(LFShapeError):
        warp_views(centre, disp, (3, 3), gains=np.ones((2, 3, 2, 2, 3), np.float32))


def test_warp_into_a_given_array(rng):
    """``out`` receives the views (and is returned), the same bytes as a new array, on the
    kernel's path and on the flat one; an array the kernel cannot fill is refused."""
    centre, disp = _scene(seed=9, size=(30, 36))
    gains = rng.uniform(0.8, 1.2, (3, 5, 2, 2, 3)).astype(np.float32)
    video = np.zeros((2, 3, 5, 30, 36, 3), np.uint8)
    for d in (disp, np.zeros_like(disp)):
        for g in (None, gains):
            got = warp_views(centre, d, (3, 5), gains=g, out=video[1])
            assert got is video[1] or np.shares_memory(got, video)
            np.testing.assert_array_equal(video[1], warp_views(centre, d, (3, 5), gains=g))
    assert not video[0].any()
    for bad in (np.zeros((3, 5, 30, 36, 3), np.float32), np.zeros((3, 5, 30, 36, 4), np.uint8),
                np.zeros((3, 5, 36, 30, 3), np.uint8).transpose(0, 1, 3, 2, 4), [[0]]):
        with pytest.raises(LFValueError, match="out"):
            warp_views(centre, disp, (3, 5), out=bad)


@pytest.mark.parametrize("channels", [1, 4])
def test_fused_warp_any_channel_count(channels, rng):
    centre, disp = _scene(seed=11, size=(24, 20))
    img = np.ascontiguousarray(np.concatenate([centre, centre[..., :1]], axis=-1)[..., :channels])
    gains = rng.uniform(0.8, 1.2, (3, 3, 2, 2, channels)).astype(np.float32)
    _assert_close(warp_views(img, disp, (3, 3), gains=gains), _reference_warp(img, disp, (3, 3), True, gains), 0.25)


def test_fused_warp_same_bytes_at_any_thread_count(rng):
    centre, disp = _scene(seed=2, size=(40, 52))
    gains = rng.uniform(0.8, 1.2, (5, 5, 3, 3, 3)).astype(np.float32)
    threads = numba.get_num_threads()
    try:
        outs = []
        for n in sorted({1, threads}):
            numba.set_num_threads(n)
            outs.append(warp_views(centre, disp, (5, 5), gains=gains))
    finally:
        numba.set_num_threads(threads)
    assert all((o == outs[0]).all() for o in outs)


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_the_centre_view_is_the_centre_bit_for_bit(channels, rng):
    """The centre view is copied, not sampled (every sample position is a pixel's own,
    whatever the disparity): without gains it is the centre view itself, with gains within
    a level of OpenCV's up-sampled gains multiplied in."""
    centre, disp = _scene(seed=4, size=(26, 34))
    img = np.ascontiguousarray(np.concatenate([centre, centre[..., :1]], axis=-1)[..., :channels])
    for d in (disp, disp * 40.0):
        for occlusion in (True, False):
            np.testing.assert_array_equal(warp_views(img, d, (3, 5), occlusion=occlusion)[1, 2], img)
    maps = view_disparities(disp, (3, 3)) * 1.5
    np.testing.assert_array_equal(warp_views_per_view(img, maps)[1, 1], img)
    gains = rng.uniform(0.7, 1.3, (3, 3, 2, 3, channels)).astype(np.float32)
    ref = apply_gains(np.broadcast_to(img, (3, 3, *img.shape)).copy(), gains)[1, 1]
    diff = np.abs(warp_views(img, disp, (3, 3), gains=gains)[1, 1].astype(int) - ref.astype(int))
    assert diff.max() <= 1 and diff.mean() < 0.25  # OpenCV's up-sampled gains, rounded once more


def test_views_are_dealt_by_cost_and_each_once():
    """3x3 with the four corners splatted: round-robin gave one task the corners and the
    centre; the deal gives each task two corners. Every view is dealt exactly once, tasks are
    never more than the views, and no task's estimated load exceeds another's by more than
    the costliest view (the bound of dealing longest first)."""
    offsets = view_offsets((3, 3))
    splat = np.zeros((3, 3), bool)
    splat[[0, 0, 2, 2], [0, 2, 0, 2]] = True
    order, starts = deal_views(offsets, splat, 2)
    assert sorted(order.tolist()) == list(range(9)) and starts.tolist() == [0, 5, 9]
    corners = {0, 2, 6, 8}
    assert [len(corners & set(order[starts[t]:starts[t + 1]].tolist())) for t in range(2)] == [2, 2]
    order, starts = deal_views(offsets, splat, 16)
    assert starts.tolist() == list(range(10)) and sorted(order.tolist()) == list(range(9))
    order, starts = deal_views(offsets, splat, 1)
    assert starts.tolist() == [0, 9] and sorted(order.tolist()) == list(range(9))
    offsets = view_offsets((7, 7))
    splat = splat_views(np.outer(np.linspace(-1, 1, 40), np.ones(30)).astype(np.float32), offsets, 0.3)
    du, dv = offsets[..., 0].ravel() != 0, offsets[..., 1].ravel() != 0
    kind = np.where(du & dv, "all", np.where(du, "column", np.where(dv, "row", "centre")))
    cost = np.array([VIEW_COST_TAPS[k] for k in kind]) + VIEW_COST_SPLAT * splat.ravel()
    for tasks in (2, 3, 5):
        order, starts = deal_views(offsets, splat, tasks)
        assert sorted(order.tolist()) == list(range(49))
        loads = [cost[order[starts[t]:starts[t + 1]]].sum() for t in range(tasks)]
        assert max(loads) - min(loads) <= cost.max() + 1e-9
        # deterministic, and a copy the caller may keep
        again = deal_views(offsets, splat, tasks)
        assert (again[0] == order).all() and again[0] is not order


def test_a_subset_of_views_is_dealt_costliest_first():
    """deal_views of a subset deals those views only, each once, and with one task in
    order of cost, the costliest first (what the warp beside other work takes in chunks)."""
    offsets = view_offsets((5, 5))
    splat = np.zeros((5, 5))
    splat[0, 0] = 1.0
    order, starts = deal_views(offsets, splat, 1)
    du, dv = offsets[..., 0].ravel() != 0, offsets[..., 1].ravel() != 0
    kind = np.where(du & dv, "all", np.where(du, "column", np.where(dv, "row", "centre")))
    cost = np.array([VIEW_COST_TAPS[k] for k in kind]) + VIEW_COST_SPLAT * splat.ravel()
    assert order[0] == 0 and np.all(np.diff(cost[order]) <= 0) and order[-1] == 12  # the centre view last
    subset = order[7:]
    order2, starts2 = deal_views(offsets, splat, 2, subset)
    assert sorted(order2.tolist()) == sorted(subset.tolist()) and starts2.tolist()[::2] == [0, len(subset)]
    assert deal_views(offsets, splat, 8, subset[:3])[1].tolist() == [0, 1, 2, 3]  # no more tasks than views


class _Beside:
    """A stand-in for the future the decoder passes: done after ``polls`` checks."""

    def __init__(self, polls: int) -> None:
        self.polls = polls

    def done(self) -> bool:
        self.polls -= 1
        return self.polls < 0


@pytest.mark.parametrize("polls", [0, 3, 10**9])
def test_warp_beside_other_work_gives_the_same_views(polls, rng, monkeypatch):
    """Views warped on one thread while other work runs (``beside``: done at once, after a
    two chunks, never) and the rest on every thread are the views of the plain warp, bit
    for bit; the caller's numba thread count is restored."""
    centre, disp = _scene(seed=5, size=(40, 52))
    gains = rng.uniform(0.8, 1.2, (5, 5, 3, 3, 3)).astype(np.float32)
    expected = warp_views(centre, disp, (5, 5), gains=gains)
    threads = numba.get_num_threads()
    calls = []
    kernel = warp_module._warp_beside

    def counted(beside, ranked, warp):
        done = kernel(beside, ranked, warp)
        calls.append(done)
        return done

    monkeypatch.setattr(warp_module, "_warp_beside", counted)
    out = warp_views(centre, disp, (5, 5), gains=gains, beside=_Beside(polls))
    np.testing.assert_array_equal(out, expected)
    assert numba.get_num_threads() == threads
    if threads > 1:  # one thread: nothing to leave to the other work
        # polls: the check before the warp, then one before each chunk
        warped_alone = {0: None, 3: 2 * warp_module.BESIDE_CHUNK_VIEWS, 10**9: 25}[polls]
        assert calls == ([] if warped_alone is None else [warped_alone])


@pytest.mark.parametrize("channels", [3, 4])
def test_views_on_the_centres_row_and_column_sample_two_taps_to_the_bit(channels, rng):
    """A view on the centre's row (no vertical displacement) or column samples two taps,
    not four: the same bytes as the four-tap path, which runs where axes move those views by
    a displacement too small to change any position (1e-30 px per view step)."""
    centre, disp = _scene(seed=5, size=(40, 52))
    img = np.ascontiguousarray(np.concatenate([centre, centre[..., :1]], axis=-1)[..., :channels])
    gains = rng.uniform(0.8, 1.2, (5, 5, 3, 3, channels)).astype(np.float32)
    nudged = np.float32([[1.0, 1e-30], [1e-30, 1.0]])  # every view off both axes, by nothing
    offsets = view_offsets((5, 5), nudged)
    assert (offsets[2, [0, 1, 3, 4], 0] != 0).all() and (offsets[[0, 1, 3, 4], 2, 1] != 0).all()
    for g in (None, gains):
        for occlusion in (True, False):
            two_taps = warp_views(img, disp, (5, 5), occlusion=occlusion, gains=g)
            four_taps = warp_views(img, disp, (5, 5), occlusion=occlusion, gains=g, axes=nudged)
            np.testing.assert_array_equal(two_taps, four_taps)


def test_fused_warp_survives_huge_disparities():
    centre, _ = _scene(seed=3, size=(16, 18))
    for d in (1e6, -1e6, 3e38):
        out = warp_views(centre, np.full(centre.shape[:2], d, np.float32), (3, 3))
        # every sample is clamped to the border: values stay those of the centre's pixels
        assert out.shape == (3, 3, 16, 18, 3) and (out[1, 1] == centre).all()


def test_view_axes_move_views_along_them(rng):
    centre = (rng.random((40, 56, 3)) * 255).astype(np.uint8)
    disp = rng.uniform(-1.5, 1.5, (40, 56)).astype(np.float32)
    plain = warp_views(centre, disp, (5, 3))
    # the identity is the convention, byte for byte
    assert np.array_equal(warp_views(centre, disp, (5, 3), axes=np.eye(2)), plain)
    # flipped rows: view u is the convention's view U - 1 - u (exact, the same offsets)
    assert np.array_equal(warp_views(centre, disp, (5, 3), axes=np.diag([-1.0, 1.0])), plain[::-1])
    # a general matrix (a camera array's: rows flipped and longer, the rig rotated) against
    # the plain reference with the same offsets, occlusions included
    axes = np.array([[-1.08, -0.06], [-0.05, 1.0]])
    centre, disp = _scene()
    for occlusion in (True, False):
        _assert_close(warp_views(centre, disp, (5, 3), occlusion=occlusion, axes=axes),
                      _reference_warp(centre, disp, (5, 3), occlusion, axes=axes))


@pytest.mark.parametrize("occlusion", [True, False])
def test_view_disparities_are_the_reference_maps(occlusion):
    """The per-view maps Depth-Net refines are the ones the fused warp samples with: the
    reference's sample positions, as disparity (agree to 1e-5 on >= 99.5 % of the pixels;
    a splat position within float32 rounding of a half pixel may go either way)."""
    _, disp = _scene()
    axes = np.array([[1.0, 0.12], [-0.08, 0.93]], np.float32)
    maps = view_disparities(disp, (5, 3), occlusion=occlusion, axes=axes)
    ref = _reference_maps(disp, 5, 3, occlusion, axes)
    offsets = view_offsets((5, 3), axes)
    ys, xs = np.mgrid[0:disp.shape[0], 0:disp.shape[1]]
    for u in range(5):
        for v in range(3):
            oy, ox = offsets[u, v]
            if (u, v) == (2, 1):
                assert np.array_equal(maps[u, v], disp)
                continue
            # the reference's x position x + d * ox recovers d (|ox| >= 0.08 here)
            d_ref = (ref[u, v, ..., 0] - xs) / ox if abs(ox) > abs(oy) else (ref[u, v, ..., 1] - ys) / oy
            assert (np.abs(maps[u, v] - d_ref) < 1e-4).mean() > 0.995, (u, v)


@pytest.mark.parametrize("occlusion", [True, False])
def test_per_view_warp_of_the_view_disparities_is_the_warp(occlusion, rng):
    """warp_views_per_view(view_disparities(d)) == warp_views(d), byte for byte, with gains
    and view axes: an untrained Depth-Net refiner (zero correction) decodes what the hint
    decodes."""
    centre, disp = _scene(seed=9)
    gains = (1 + 0.15 * rng.standard_normal((5, 3, 4, 5, 3))).astype(np.float32)
    axes = np.array([[0.95, 0.1], [-0.05, 1.1]], np.float32)
    maps = view_disparities(disp, (5, 3), occlusion=occlusion, axes=axes)
    want = warp_views(centre, disp, (5, 3), occlusion=occlusion, gains=gains, axes=axes)
    assert np.array_equal(warp_views_per_view(centre, maps, axes, gains), want)
    with pytest.raises(LFShapeError):
        view_disparities(disp[None], (5, 3))


@pytest.mark.parametrize("occlusion", [True, False])
def test_view_disparities_add_the_refiners_corrections_as_it_does(occlusion, rng):
    """With Depth-Net's correction maps, each view's map is the plain map plus
    :func:`view_correction` at its offset, as numpy computes it in float32 (to the bit: the
    kernel has no fused multiply-add), with view axes; a wrong shape is refused."""
    from lfstream.models.depth_net import view_correction

    _, disp = _scene(seed=4)
    axes = np.array([[0.97, 0.11], [-0.06, 1.04]], np.float32)
    corr = (0.3 * rng.standard_normal((3, *disp.shape))).astype(np.float32)
    plain = view_disparities(disp, (5, 3), occlusion=occlusion, axes=axes)
    offsets = view_offsets((5, 3), axes)
    want = np.stack([[plain[u, v] + view_correction(corr, *offsets[u, v]) for v in range(3)] for u in range(5)])
    assert want.dtype == np.float32
    assert np.array_equal(view_disparities(disp, (5, 3), occlusion=occlusion, axes=axes, corrections=corr), want)
    with pytest.raises(LFShapeError, match="corrections"):
        view_disparities(disp, (5, 3), corrections=corr[:2])
    with pytest.raises(LFValueError, match="corrections"):
        view_disparities(disp, (5, 3), corrections=np.full_like(corr, np.nan))


def test_warping_selected_views_gives_those_views_of_the_whole_warp():
    """warp_views_at (the encoder's check of its prediction) is warp_views restricted to some
    views: the same kernel, the same pixels, with gains and view axes."""
    clip = synth_clip(1, 5, (40, 56), seed=2, vignetting=0.3)
    centre, d = clip.lf[0, 2, 2], clip.disparity[0, 2, 2]
    gains = np.random.default_rng(1).uniform(0.8, 1.2, (5, 5, 2, 3, 3)).astype(np.float32)
    axes = np.float32([[0.0, 1.0], [1.0, 0.1]])
    keys = [(0, 0), (0, 4), (2, 3), (4, 1)]
    whole = warp_views(centre, d, (5, 5), gains=gains, axes=axes)
    some = warp_views_at(centre, d, (5, 5), keys, gains=gains, axes=axes)
    np.testing.assert_array_equal(some, np.stack([whole[k] for k in keys]))
    with pytest.raises(LFValueError, match="keys"):
        warp_views_at(centre, d, (5, 5), [(5, 0)])


def _fold_bounds_reference(d: np.ndarray) -> tuple[float, float]:
    d = d.astype(np.float64)
    mx = (np.abs(np.diff(d, axis=1)) * np.maximum(np.abs(d[:, :-1]), np.abs(d[:, 1:]))).max(initial=0.0)
    my = (np.abs(np.diff(d, axis=0)) * np.maximum(np.abs(d[:-1]), np.abs(d[1:]))).max(initial=0.0)
    return mx, my


def _smooth_disparity(h: int, w: int, amplitude: float) -> np.ndarray:
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    return (amplitude * np.sin(xs / 9.0) * np.cos(ys / 13.0)).astype(np.float32)


@pytest.mark.parametrize("amplitude", [0.0, 0.3, 0.8, 2.5])
def test_splat_views_is_the_documented_bound(amplitude):
    """A view is splatted exactly where |delta| (|du| M_y + |dv| M_x) > tolerance, with M the
    neighbour differences times the larger |d| (float64 here); never the centre view."""
    axes = np.array([[1.0, 0.15], [-0.1, 0.9]], np.float32)
    d = _smooth_disparity(33, 47, amplitude)
    d[10:20, 12:30] += np.float32(0.1 * amplitude)  # a small step: occlusion edges count too
    offsets = view_offsets((7, 5), axes)
    mx, my = _fold_bounds_reference(d)
    du, dv = np.abs(offsets[..., 0].astype(np.float64)), np.abs(offsets[..., 1].astype(np.float64))
    want = (np.hypot(du, dv) * (du * my + dv * mx) > SPLAT_TOLERANCE_PX) & ((du > 0) | (dv > 0))
    got = splat_views(d, offsets)
    assert got.shape == (7, 5) and got.dtype == bool
    # float32 products against float64 ones: equal away from the threshold itself
    bound = np.hypot(du, dv) * (du * my + dv * mx)
    near = np.abs(bound - SPLAT_TOLERANCE_PX) < 1e-5
    assert np.array_equal(got[~near], want[~near])
    assert not got[3, 2]
    assert splat_views(d, offsets, tolerance=0.0).sum() == (35 - 1 if amplitude > 0 else 0)
    if amplitude == 0.0:
        assert not got.any()
    if amplitude == 2.5:  # a strong slope and a step: every view but the centre at a quarter pixel, some at one
        assert splat_views(d, offsets, tolerance=0.25).sum() == 34 and 0 < got.sum() < 34


def test_views_without_the_splat_are_the_splatted_views_within_the_tolerance(monkeypatch):
    """Where splat_rows skips a view row, its samples are at most the tolerance (one pixel)
    from the splatted ones' (plus the splat's own nearest-pixel rounding): on a textured
    centre with a gentle disparity the decoded rows differ from splatting every row by under
    a level on average, the splatted rows are the same bytes, and the rule leaves strong
    parallax alone (skipping those rows too moves them over three times as much)."""
    clip = synth_clip(1, 7, (60, 84), seed=4, layers=1, motion=0, camera_pan=0)
    centre = clip.lf[0, 3, 3]
    d = _smooth_disparity(60, 84, 1.6)
    offsets = view_offsets((7, 7))
    mask = splat_rows(d, offsets)
    views = splat_views(d, offsets)
    assert 0 < mask.sum() < mask.size and not mask[~views].any()  # rows of the views splat_views names
    assert (mask.any(-1) & ~mask.all(-1)).any()  # some views splat some rows, not all
    ring = np.maximum(np.abs(np.arange(7)[:, None] - 3), np.abs(np.arange(7)[None] - 3))
    assert not mask[ring == 1].any() and mask[ring == 3].any()
    got = warp_views(centre, d, (7, 7))
    monkeypatch.setattr(warp_module, "SPLAT_TOLERANCE_PX", 0.0)
    everywhere = warp_views(centre, d, (7, 7))
    diff = np.abs(got.astype(int) - everywhere.astype(int))
    assert np.array_equal(got[mask], everywhere[mask])  # splatted rows: the same bytes
    # measured: mean 0.53 levels, 99th percentile 5 (a sharp texture edge moved by a
    # fraction of a pixel makes the rare larger difference; at a quarter-pixel tolerance and
    # half this amplitude: 0.12 and 1)
    assert diff[~mask].mean() < 0.75 and np.percentile(diff[~mask], 99) <= 6
    monkeypatch.setattr(warp_module, "SPLAT_TOLERANCE_PX", np.inf)
    none = np.abs(warp_views(centre, d, (7, 7)).astype(int) - everywhere.astype(int))
    assert none[mask].mean() > 3 * diff[~mask].mean()


def test_splat_rows_is_the_bound_over_the_rows_within_reach():
    """A view row is splatted exactly where the bound of the fold maxima over the centre rows
    within the view's reach exceeds the tolerance (float64 reference, away from the
    threshold); the reach covers every row a centre pixel lands on."""
    d = _smooth_disparity(41, 37, 1.3)
    d[5:9, 10:20] += np.float32(0.9)  # an edge in a few rows only
    axes = np.array([[1.0, 0.2], [-0.1, 0.9]], np.float32)
    offsets = view_offsets((5, 7), axes)
    got = splat_rows(d, offsets)
    d64 = d.astype(np.float64)
    rx = (np.abs(np.diff(d64, axis=1)) * np.maximum(np.abs(d64[:, :-1]), np.abs(d64[:, 1:]))).max(axis=1)
    ry = np.append((np.abs(np.diff(d64, axis=0)) * np.maximum(np.abs(d64[:-1]), np.abs(d64[1:]))).max(axis=1), 0.0)
    reach = splat_reach(float(np.abs(d).max()), offsets)
    rows = np.arange(41)[:, None]
    for u in range(5):
        for v in range(7):
            du, dv = abs(float(offsets[u, v, 0])), abs(float(offsets[u, v, 1]))
            r = int(reach[u, v])
            # no centre pixel lands further than the reach from its own row
            assert r >= np.abs(np.floor(rows - d64 * float(offsets[u, v, 0]) + 0.5) - rows).max()
            for y in range(41):
                lo, hi = max(0, y - r), min(41, y + r + 1)
                bound = np.hypot(du, dv) * (du * ry[lo:hi].max() + dv * rx[lo:hi].max())
                if abs(bound - SPLAT_TOLERANCE_PX) > 1e-5:
                    assert got[u, v, y] == (bound > SPLAT_TOLERANCE_PX and (du > 0 or dv > 0)), (u, v, y)
    assert not got[2, 3].any()
    assert got.any() and not got.all(axis=-1)[got.any(axis=-1)].all()


def test_window_maxima_clip_at_the_ends(rng):
    from lfstream.codec.warp.cpu import _window_max

    for h in (1, 2, 5, 40):
        a = rng.random(h)
        for r in (0, 1, 3, h - 1, h + 5):
            want = [a[max(0, y - r):y + r + 1].max() for y in range(h)]
            np.testing.assert_array_equal(_window_max(a, r), want)
