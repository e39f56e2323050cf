"""The tensor plane sweep (the encoder's sweep for a GPU) against the CPU kernels and OpenCV
box filter it restates: costs to float32 rounding, the same winners, and the encoder's
maps within a thousandth of a pixel."""

import cv2
import numpy as np
import pytest
import torch

import lfstream
import lfstream.codec.hint as hint_mod
import lfstream.codec.hint.sweep as hint_sweep
from lfstream.cli import main
from lfstream.codec.encoder import Encoder
from lfstream.codec.hint import HintOptions, estimate_hint_map
from lfstream.codec.hint.kernels import sweep_cost, winner_subpixel
from lfstream.codec.hint.sweep_batched import box_mean, sweep_batched, sweep_cost_batched, winner_subpixel_batched
from lfstream.errors import LFShapeError, LFValueError
from lfstream.metrics import mpsnr
from lfstream.synth import synth_clip

COST_ATOL = 1e-6  # float32 sums in another order (costs are means of |differences| in [0, 1])


def _images(rng, n=5, size=(23, 31)):
    img = rng.uniform(0, 1, (n, *size)).astype(np.float32)
    return np.stack([cv2.GaussianBlur(x, (0, 0), 1.2) for x in img])


@pytest.mark.parametrize("axes", [np.eye(2, dtype=np.float32), np.array([[0.9, -0.3], [0.2, 1.1]], np.float32)])
def test_cost_agrees_with_the_kernel(rng, axes):
    """Sub-pixel shifts along any axes, and shifts that leave the image (replicated border)."""
    images = _images(rng)
    steps = np.array([[-2, -2], [-2, 2], [2, 0], [0, -1]], np.float32)
    offsets = np.ascontiguousarray(steps @ axes.T)
    shifts = np.array([-40.0, -3.3, -0.71, 0.0, 0.26, 1.5, 9.9, 37.0], np.float32)
    ref = np.empty((len(shifts), *images.shape[1:]), np.float32)
    sweep_cost(images, offsets, shifts, ref)
    got = sweep_cost_batched(torch.from_numpy(images), torch.from_numpy(offsets), torch.from_numpy(shifts),
                             chunk_pixels=3 * 4 * 23 * 31).numpy()  # three candidates a pass
    np.testing.assert_allclose(got, ref, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("radius", [0, 1, 2, 4])
def test_box_mean_is_opencvs_replicated_blur(rng, radius):
    cost = rng.uniform(0, 1, (3, 9, 14)).astype(np.float32)
    ref = cost.copy()
    if radius:
        for k in range(len(ref)):
            cv2.blur(ref[k], (2 * radius + 1, 2 * radius + 1), dst=ref[k], borderType=cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(box_mean(torch.from_numpy(cost), radius).numpy(), ref, rtol=0, atol=1e-6)


def test_winner_is_the_kernels_first_minimum_and_parabola(rng):
    cost = rng.uniform(0, 1, (9, 12, 17)).astype(np.float32)
    cost[4, :3] = cost[6, :3] = -1.0  # ties: the first wins
    cost[0, 5] = -2.0  # minima at either end keep the candidate itself
    cost[8, 6] = -2.0
    shifts = (np.float32(-1.5) + np.float32(0.375) * np.arange(9)).astype(np.float32)
    ref = np.empty(cost.shape[1:], np.float32)
    winner_subpixel(cost, shifts, ref)
    got = winner_subpixel_batched(torch.from_numpy(cost), torch.from_numpy(shifts)).numpy()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
    assert (got[5] == shifts[0]).all() and (got[6] == shifts[8]).all()


def test_the_whole_sweep_agrees_with_the_hints(rng):
    """sweep_batched is hint._sweep on a device: the same map where no two candidates tie."""
    clip = synth_clip(1, 5, (60, 84), seed=4, noise=1.0, motion=0, camera_pan=0)
    lf = np.ascontiguousarray(clip.lf[0])
    keys = hint_mod.sweep_views(5, 5)
    grids = hint_mod._high_pass(hint_mod._grids(lf, [(2, 2), *keys], 2))
    offsets = np.asarray([(a - 2, b - 2) for a, b in keys], np.float32)
    opts = HintOptions()
    ref = hint_mod._sweep(grids, offsets, -2.0, 3.0, 2, opts)
    got = hint_mod._sweep(grids, offsets, -2.0, 3.0, 2, opts, device="cpu")  # the kernels on "cpu"
    assert (got == ref).all()
    cands = (np.float32(-2.0) + np.float32(opts.step * 2 / 2) * np.arange(21)).astype(np.float32)
    cost = np.empty((len(cands), *grids.shape[1:]), np.float32)
    sweep_cost(grids, offsets, cands / np.float32(2), cost)
    for k in range(len(cands)):
        cv2.blur(cost[k], (5, 5), dst=cost[k], borderType=cv2.BORDER_REPLICATE)
    ref = np.empty(grids.shape[1:], np.float32)
    winner_subpixel(cost, cands, ref)
    got = sweep_batched(grids, offsets, cands, 2, opts.box_radius, "cpu")
    diff = np.abs(got - ref)
    assert np.mean(diff <= 1e-3) >= 0.999 and np.isfinite(got).all()


def test_the_encoder_sweeps_on_the_device(monkeypatch):
    """The encoder's tensor path (a CUDA device's), run here on the CPU: the same hint maps
    to a thousandth of a pixel, and decoded streams of equal quality."""
    clip = synth_clip(2, 5, (48, 64), seed=7, noise=1.0, motion=0.4)
    ref_map = estimate_hint_map(clip.lf[0])
    ref = lfstream.encode(clip.lf)
    monkeypatch.setattr(hint_sweep, "sweeps_on_device", lambda device: True)
    got_map = estimate_hint_map(clip.lf[0], device="cpu")
    assert got_map.search == pytest.approx(ref_map.search, abs=1e-3)
    assert np.mean(np.abs(got_map.disparity - ref_map.disparity) <= 1e-3) >= 0.99
    got = lfstream.encode(clip.lf)
    assert abs(np.mean(mpsnr(lfstream.decode(got), clip.lf)) - np.mean(mpsnr(lfstream.decode(ref), clip.lf))) <= 0.05
    assert abs(len(got) - len(ref)) <= 0.02 * len(ref)


def test_bad_device_and_shapes_are_clear_errors(tmp_path, capsys):
    with pytest.raises(LFValueError, match="device"):
        Encoder(device="tpu")
    with pytest.raises(LFShapeError):
        sweep_cost_batched(torch.zeros(1, 4, 4), torch.zeros(0, 2), torch.zeros(3))
    with pytest.raises(LFShapeError):
        sweep_cost_batched(torch.zeros(3, 4, 4), torch.zeros(3, 2), torch.zeros(3))
    with pytest.raises(LFValueError):
        winner_subpixel_batched(torch.zeros(2, 3, 3), torch.zeros(2))
    clip = synth_clip(1, 3, (16, 20), seed=1).lf
    np.save(tmp_path / "c.npy", clip)
    assert main(["encode", str(tmp_path / "c.npy"), "-o", str(tmp_path / "c.lfs"), "--device", "tpu"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "device" in err[0] and not (tmp_path / "c.lfs").exists()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_agrees_with_the_cpu():
    clip = synth_clip(1, 7, (96, 128), seed=3, noise=1.0, motion=0, camera_pan=0)
    ref = estimate_hint_map(clip.lf[0])
    got = estimate_hint_map(clip.lf[0], device="cuda")
    assert np.mean(np.abs(got.disparity - ref.disparity) <= 1e-3) >= 0.99
