"""Shift-and-sum and Fourier slice refocusing: definition, convention, stability."""

import numpy as np
import pytest
import torch

from lfstream.errors import LFStreamError, LFValueError
from lfstream.lightfield import as_float
from lfstream.metrics import psnr
from lfstream.optics import SEED_ALPHAS, alpha_from_slope, slope_from_alpha
from lfstream.refocus import (
    FocalStack,
    all_in_focus,
    focal_stack,
    fourier_slice,
    resolve_slopes,
    shift_and_sum,
)
from lfstream.refocus.shift_sum import _sas_frame_torch
from lfstream.synth import fronto_parallel_plane
from tests.conftest import random_lf, shared, shifted_views


def reference_sas(lf: np.ndarray, slopes, weights=None) -> np.ndarray:
    """Obviously-correct loop: every output pixel, every view, four bilinear taps."""
    u_n, v_n, h, w, c = lf.shape
    x = as_float(lf).astype(np.float64)
    wts = np.ones((u_n, v_n)) if weights is None else weights
    out = np.zeros((len(slopes), h, w, c))
    for k, s in enumerate(slopes):
        for y in range(h):
            for xx in range(w):
                num, den = np.zeros(c), 0.0
                for u in range(u_n):
                    for v in range(v_n):
                        sy, sx = y - s * (u - u_n // 2), xx - s * (v - v_n // 2)
                        y0, x0 = int(np.floor(sy)), int(np.floor(sx))
                        fy, fx = sy - y0, sx - x0
                        for yi, wy in ((y0, 1 - fy), (y0 + 1, fy)):
                            for xi, wx in ((x0, 1 - fx), (x0 + 1, fx)):
                                wt = wts[u, v] * wy * wx
                                if wt > 0 and 0 <= yi < h and 0 <= xi < w:
                                    num += wt * x[u, v, yi, xi]
                                    den += wt
                out[k, y, xx] = num / den if den > 1e-6 else 0.0
    return out


def test_sas_equals_reference_loop(rng):
    lf = random_lf(rng, (5, 4, 9, 11, 3))
    slopes = [-2.3, -0.4, 0.0, 0.61, 1.5, 7.0]
    np.testing.assert_allclose(shift_and_sum(lf, slopes), reference_sas(lf, slopes), atol=1e-4)
    wts = rng.random((5, 4)).astype(np.float32)
    np.testing.assert_allclose(shift_and_sum(lf, slopes, wts), reference_sas(lf, slopes, wts), atol=1e-4)


def test_torch_path_equals_cpu_kernel(rng, device):
    lf = random_lf(rng, (5, 5, 16, 20, 3))
    slopes = np.array([-1.7, 0.3, 0.9])
    cpu = shift_and_sum(lf, slopes)
    other = _sas_frame_torch(torch.from_numpy(lf).to(device), slopes, np.ones((5, 5), np.float32))
    np.testing.assert_allclose(other.cpu().numpy(), cpu, atol=1e-5)
    # the public function on a tensor returns a tensor on the same device
    t = focal_stack(torch.from_numpy(lf).to(device), slopes=slopes)
    assert isinstance(t, torch.Tensor) and t.device.type == device.type and t.dtype == torch.uint8


def test_alpha_one_is_mean_of_views(rng):
    lf = random_lf(rng, (7, 7, 12, 13, 3))
    out = shift_and_sum(lf, [slope_from_alpha(1.0)])[0]
    np.testing.assert_allclose(out, as_float(lf).mean(axis=(0, 1)), atol=1e-6)


def test_alpha_slope_conversion():
    for a in SEED_ALPHAS:
        assert alpha_from_slope(slope_from_alpha(a)) == pytest.approx(a)
    assert slope_from_alpha(0.5) == pytest.approx(-1.0)
    assert len(resolve_slopes()) == 16 and resolve_slopes()[-1] == pytest.approx(0.5)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(LFValueError):
            slope_from_alpha(bad)
        with pytest.raises(LFStreamError):
            focal_stack(np.zeros((3, 3, 8, 8, 3), np.uint8), alphas=[bad])
    with pytest.raises(LFValueError):
        alpha_from_slope(1.0)


@pytest.mark.parametrize("d", [-1.25, 0.5, 1.0])
def test_plane_is_sharpest_at_its_disparity(d):
    clip = fronto_parallel_plane(7, (96, 96), d, seed=2)
    slopes = np.round(np.arange(-2.0, 2.01, 0.25), 3)
    stack = shift_and_sum(clip.lf[0], slopes)
    inner = stack[:, 16:-16, 16:-16].mean(-1)
    sharp = [np.abs(np.diff(p, axis=0)).mean() + np.abs(np.diff(p, axis=1)).mean() for p in inner]
    assert slopes[int(np.argmax(sharp))] == pytest.approx(d)
    # and at that slope the views align: the plane equals the centre view (bilinear blur aside)
    k = int(np.argmin(np.abs(slopes - d)))
    assert psnr(stack[k, 16:-16, 16:-16], as_float(clip.lf[0, 3, 3, 16:-16, 16:-16])) > 30


@pytest.mark.parametrize("scene", ["dino", "cotton"])
def test_hci_views_align_under_the_convention(scene):
    """Under lfstream's (HCI) convention, one slope aligns the centre row, the centre column
    and both diagonals of a patch at once. A reader that swapped or mirrored a view axis
    would align the column (or a diagonal) at the opposite slope instead."""
    from lfstream import read_lf

    lf, present = read_lf(shared("hci_star", scene), return_mask=True)
    slopes = np.round(np.linspace(-2.5, 2.5, 51), 3)
    sets = {"row": np.zeros((9, 9), bool), "column": np.zeros((9, 9), bool),
            "diagonal": np.eye(9, dtype=bool), "antidiagonal": np.fliplr(np.eye(9, dtype=bool))}
    sets["row"][4] = True
    sets["column"][:, 4] = True

    def best_slope(patch, mask):
        # photo-consistency: variance across the views after shifting each by the slope
        idx = np.argwhere(mask)
        costs = []
        for s in slopes:
            shifted = shifted_views(patch, idx, s)[:, 8:-8, 8:-8]
            costs.append(shifted.var(axis=0).mean())
        return slopes[int(np.argmin(costs))]

    checked = 0
    for y0, x0 in [(100, 100), (100, 350), (350, 100), (350, 350), (230, 230), (60, 240), (420, 260)]:
        patch = lf[:, :, y0 : y0 + 64, x0 : x0 + 64]
        found = {name: best_slope(patch, m & present) for name, m in sets.items()}
        if abs(found["row"]) < 0.3:
            continue  # near the focal plane the sign cannot be told apart
        checked += 1
        for _name, s in found.items():
            assert s == pytest.approx(found["row"], abs=0.2), (scene, y0, x0, found)
    assert checked >= 2, f"{scene}: too few patches away from the focal plane to check the sign"


def test_fourier_matches_sas_and_precision(rng):
    clip = fronto_parallel_plane(5, (48, 56), 0.6, seed=1)
    lf = clip.lf[0]
    slopes = np.array([-0.8, 0.0, 0.6, 1.2])
    sas = shift_and_sum(lf, slopes)
    flr32 = fourier_slice(lf, slopes)
    flr64 = fourier_slice(lf, slopes, dtype=torch.float64)
    assert np.abs(flr32 - flr64).max() < 1e-4
    # brightness matches exactly; content to within the sinc-vs-bilinear difference
    np.testing.assert_allclose(flr32.mean(axis=(1, 2, 3)), sas.mean(axis=(1, 2, 3)), atol=3e-3)
    inner = (slice(None), slice(8, -8), slice(8, -8))
    for k in range(len(slopes)):
        assert psnr(flr32[inner][k], sas[inner][k], data_range=1.0) > 30
    np.testing.assert_allclose(flr32[1], sas[1], atol=1e-4)  # slope 0: both are the plain mean


def test_fourier_on_real_sample():
    from lfstream import read_lf

    lf = read_lf(shared("seahorse5x5", "camImagesFlat"))[:, :, 150:310, 150:330]
    alphas = [0.5, 0.8, 1.0, 1.5, 2.0]
    sas = focal_stack(lf, alphas)
    flr = focal_stack(lf, alphas, method="fourier")
    for k in range(len(alphas)):
        assert psnr(sas[k], flr[k]) > 35


@pytest.mark.parametrize("dtype", [np.uint8, np.float16, np.float32, np.float64])
def test_input_dtypes_keep_their_range(rng, dtype):
    lf8 = random_lf(rng, (3, 3, 12, 12, 3))
    lf = lf8 if dtype == np.uint8 else (lf8 / 255.0).astype(dtype)
    out = focal_stack(lf, [0.5, 1.0, 2.0])
    assert out.dtype == dtype and out.shape == (3, 12, 12, 3)
    ref = focal_stack(lf8, [0.5, 1.0, 2.0]).astype(np.float32) / 255
    # the reference is rounded to 8 bits (0.5/255); float16 adds its own rounding (< 1e-3)
    tol = 1.0 / 255 if dtype == np.uint8 else 0.5 / 255 + 1e-3
    np.testing.assert_allclose(np.asarray(out, np.float32) / (255.0 if dtype == np.uint8 else 1.0), ref, atol=tol)


@pytest.mark.parametrize("dtype", [np.int16, np.uint16, np.int64, bool])
def test_other_integer_samples_are_one_clear_error(rng, dtype):
    """Samples that are neither 8-bit levels nor floats in [0, 1]: one line (an int16 light
    field came back as a stack of ones), numpy or torch."""
    lf = random_lf(rng, (3, 3, 12, 12, 3)).astype(dtype)
    with pytest.raises(LFValueError, match=rf"lf: {np.dtype(dtype).name} samples; expected uint8, or float"):
        focal_stack(lf, [1.0])
    if dtype != np.uint16:  # (torch's uint16 is not a full dtype)
        with pytest.raises(LFValueError, match="samples; expected uint8, or float"):
            focal_stack(torch.from_numpy(lf), [1.0])


def test_extreme_alphas_stay_finite(rng):
    lf = random_lf(rng, (5, 5, 10, 10, 3))
    out = shift_and_sum(lf, [slope_from_alpha(a) for a in (1e-12, 1e-3, 1e3, 1e12)])
    assert np.isfinite(out).all()
    # tiny alpha: shifts far beyond the image, only the centre view still covers the plane
    np.testing.assert_allclose(out[0], as_float(lf[2, 2]), atol=1e-6)
    # huge alpha: slope -> 1
    np.testing.assert_allclose(out[3], shift_and_sum(lf, [1.0])[0], atol=1e-5)
    flr = fourier_slice(lf, [slope_from_alpha(1e-3), slope_from_alpha(1e3)])
    assert np.isfinite(flr).all()


def test_nan_input_is_rejected():
    lf = np.zeros((3, 3, 8, 8, 3), np.float32)
    lf[1, 1, 2, 2, 0] = np.nan
    with pytest.raises(LFValueError, match="NaN"):
        focal_stack(lf)


def test_video_aperture_mask_and_module(rng):
    video = random_lf(rng, (2, 5, 5, 10, 12, 3))
    out = focal_stack(video, [0.8, 1.25], aperture=1)
    assert out.shape == (2, 2, 10, 12, 3)
    np.testing.assert_array_equal(out[1], focal_stack(video[1], [0.8, 1.25], aperture=1))
    pin = focal_stack(video[0], [0.5, 2.0], aperture=0)
    np.testing.assert_array_equal(pin[0], video[0, 2, 2])  # a pinhole never refocuses
    missing = np.ones((5, 5), bool)
    missing[0, 0] = False
    a = focal_stack(video[0], [1.0], present=missing)
    np.testing.assert_allclose(a[0].astype(float), np.delete(video[0].reshape(25, 10, 12, 3), 0, 0).mean(0), atol=0.51)
    mod = FocalStack([0.8, 1.25], aperture=1)
    np.testing.assert_array_equal(mod(torch.from_numpy(video[0])).numpy(), out[0])


def test_all_in_focus_picks_each_pixels_plane():
    clip = fronto_parallel_plane(5, (64, 64), 0.8, seed=4)
    lf, d = clip.lf[0], clip.disparity[0, 2, 2]
    aif = all_in_focus(lf, d)
    ref = focal_stack(lf, slopes=[0.8])[0]
    np.testing.assert_allclose(aif.astype(int), ref.astype(int), atol=1)  # float32 0.8 vs 0.8: 8-bit rounding
    # two planes: each half of the image takes the plane of its own disparity
    d2 = np.where(np.arange(64)[None, :] < 32, -0.5, 0.8) * np.ones((64, 1))
    aif2 = all_in_focus(lf, d2, planes=14)
    stack = focal_stack(lf, slopes=[-0.5, 0.8])
    np.testing.assert_allclose(aif2[:, :32].astype(int), stack[0, :, :32].astype(int), atol=1)
    np.testing.assert_allclose(aif2[:, 32:].astype(int), stack[1, :, 32:].astype(int), atol=1)
    with pytest.raises(LFValueError):
        all_in_focus(lf, d[:10])


def test_scene_slopes_span_the_scene_a_depth_of_field_apart():
    from lfstream.refocus import plane_spacing, scene_slopes

    d = np.linspace(-1.0, 1.0, 10_000).reshape(100, 100)
    s = scene_slopes(d, (7, 7))
    step = plane_spacing((7, 7))
    assert step == pytest.approx(1 / 6)
    assert s[0] <= -0.95 and s[-1] >= 0.95 and np.allclose(np.diff(s), np.diff(s)[0])
    assert np.diff(s)[0] <= step + 1e-12  # neighbouring depths of field touch
    flat = scene_slopes(np.full((8, 8), 0.3), (5, 5))  # a single depth: min_planes around it
    assert len(flat) == 4 and np.mean(flat) == pytest.approx(0.3)
    deep = scene_slopes(np.linspace(-8, 8, 400).reshape(20, 20), (9, 9))
    assert len(deep) == 16 and deep[0] < -7 and deep[-1] > 7  # capped: wider spacing
    outliers = np.zeros((100, 100))
    outliers[0, :5] = 40.0  # 0.05 % of the pixels: ignored by the robust range
    assert scene_slopes(outliers, (7, 7)).max() < 1
