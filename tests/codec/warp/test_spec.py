"""Every warp backend against the written arithmetic (lfstream.codec.warp.spec)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lfstream.codec.warp import warp_views, warp_views_per_view
from lfstream.codec.warp.batched import warp_views_batched
from lfstream.codec.warp.spec import splatted_disparity, warp_views_spec
from lfstream.models.warp import warp_per_view


def _scene(seed: int, size=(26, 34), channels=3, amplitude=1.6):
    """A textured centre view and a disparity with a step (occlusions) and a slope."""
    rng = np.random.default_rng(seed)
    h, w = size
    centre = rng.integers(0, 256, (h, w, channels), dtype=np.uint8)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    d = amplitude * np.where(xs > w / 2, 1.0, -0.6).astype(np.float32) + 0.03 * ys + 0.2 * rng.standard_normal((h, w))
    return centre, d.astype(np.float32)


def _within_a_level(got: np.ndarray, ref: np.ndarray, share: float = 1e-3) -> None:
    diff = np.abs(got.astype(np.int16) - ref.astype(np.int16))
    assert diff.max() <= 1 and (diff > 0).mean() <= share, (diff.max(), (diff > 0).mean())


@pytest.mark.parametrize("occlusion", [True, False])
@pytest.mark.parametrize("views", [(5, 5), (3, 7)])
def test_the_cpu_kernel_is_the_spec_to_the_byte(occlusion, views):
    for seed in range(3):
        centre, d = _scene(seed)
        np.testing.assert_array_equal(warp_views(centre, d, views, occlusion=occlusion),
                                      warp_views_spec(centre, d, views, occlusion=occlusion))


def test_the_cpu_kernel_is_the_spec_with_axes_and_four_channels():
    centre, d = _scene(4, channels=4)
    axes = np.array([[0.9, 0.2], [-0.15, 1.1]], np.float32)
    np.testing.assert_array_equal(warp_views(centre, d, (5, 3), axes=axes), warp_views_spec(centre, d, (5, 3), axes=axes))


def test_the_cpu_kernel_applies_gains_as_the_spec_within_a_level():
    centre, d = _scene(5)
    gains = np.random.default_rng(5).uniform(0.7, 1.3, (5, 5, 3, 4, 3)).astype(np.float32)
    _within_a_level(warp_views(centre, d, (5, 5), gains=gains), warp_views_spec(centre, d, (5, 5), gains=gains))


@pytest.mark.parametrize("occlusion", [True, False])
def test_the_batched_tensor_path_is_the_spec_to_the_byte(occlusion):
    scenes = [_scene(s) for s in (6, 7)]
    got = warp_views_batched(torch.from_numpy(np.stack([c for c, _ in scenes])),
                             torch.from_numpy(np.stack([d for _, d in scenes])), (5, 5), occlusion=occlusion).numpy()
    for frame, (centre, d) in zip(got, scenes):
        np.testing.assert_array_equal(frame, warp_views_spec(centre, d, (5, 5), occlusion=occlusion))


def test_the_batched_tensor_path_applies_gains_as_the_spec_within_a_level():
    centre, d = _scene(8)
    gains = np.random.default_rng(8).uniform(0.7, 1.3, (5, 5, 3, 4, 1)).astype(np.float32)
    got = warp_views_batched(torch.from_numpy(centre[None]), torch.from_numpy(d[None]), (5, 5),
                             gains=torch.from_numpy(gains[None])).numpy()[0]
    _within_a_level(got, warp_views_spec(centre, d, (5, 5), gains=gains))


def test_the_spec_fills_a_hole_from_the_background_side():
    """A near block (d = 2) in front of a far background (d = 0): splatted into the view one
    step right (dv = 1), the block moves 2 px left and the uncovered pixels take the background."""
    d = np.zeros((1, 12), np.float32)
    d[0, 4:8] = 2.0
    maps = splatted_disparity(d, 0.0, 1.0)
    np.testing.assert_array_equal(maps[0], [0, 0, 2, 2, 2, 2, 0, 0, 0, 0, 0, 0])


def test_the_differentiable_warp_agrees_with_the_spec_where_nothing_is_occluded():
    """grid_sample in float against the 1/1024-pixel fixed point: within a level on most
    samples, at most two anywhere (a smooth disparity, the per-view warp)."""
    centre, _ = _scene(9)
    h, w = centre.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    d = (0.8 * np.sin(xs / 7.0) + 0.02 * ys).astype(np.float32)
    maps = np.broadcast_to(d, (3, 3, h, w)).copy()
    ref = warp_views_spec(centre, d, (3, 3), occlusion=False)
    np.testing.assert_array_equal(warp_views_per_view(centre, maps), ref)
    t = torch.from_numpy(centre).permute(2, 0, 1)[None].float()
    got = warp_per_view(t, torch.from_numpy(maps)[None])[0].permute(0, 1, 3, 4, 2)
    diff = np.abs(got.round().clamp(0, 255).numpy() - ref.astype(np.float32))
    assert diff.max() <= 2 and (diff > 1).mean() < 1e-3 and diff.mean() < 0.1, (diff.max(), diff.mean())
