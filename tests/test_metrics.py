import math

import numpy as np
import pytest
import torch
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from lfstream.errors import LFShapeError, LFValueError
from lfstream.metrics import bpp, dof_psnr, mpsnr, mssim, psnr, ssim
from tests.conftest import random_lf, shared


def _noisy_pair(rng, shape=(40, 50, 3), sigma=20):
    a = rng.integers(0, 256, size=shape).astype(np.uint8)
    b = np.clip(a + rng.normal(0, sigma, size=shape), 0, 255).astype(np.uint8)
    return a, b


@pytest.mark.parametrize("sigma", [2, 20, 80])
def test_agrees_with_scikit_image(rng, sigma):
    a, b = _noisy_pair(rng, sigma=sigma)
    ref_ssim = structural_similarity(
        a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255, channel_axis=-1
    )
    assert abs(ssim(a, b) - ref_ssim) < 1e-3
    assert abs(psnr(a, b) - peak_signal_noise_ratio(a, b, data_range=255)) < 0.01
    # float input in [0, 1] gives the same numbers
    assert abs(ssim(a / 255.0, b / 255.0) - ref_ssim) < 1e-3


@pytest.mark.parametrize("sigma", [1, 20])
def test_fused_numpy_ssim_agrees_with_float64_torch(rng, sigma):
    # the numpy path (float32 moments in a numba kernel) against torch's float64 convolution
    a, b = _noisy_pair(rng, shape=(2, 37, 45, 3), sigma=sigma)
    fused = ssim(a, b)
    exact = ssim(torch.from_numpy(a), torch.from_numpy(b)).numpy()
    assert np.abs(fused - exact).max() < 2e-6
    assert np.abs(ssim(a.astype(np.float32) / 255, b.astype(np.float64) / 255) - exact).max() < 2e-6
    # one channel, and a window that exactly fits
    g1, g2 = a[0, :11, :, :1], b[0, :11, :, :1]
    assert abs(ssim(g1, g2) - float(ssim(torch.from_numpy(g1), torch.from_numpy(g2)))) < 2e-6


def test_on_real_view_pair():
    from lfstream import read_lf

    lf = read_lf(shared("seahorse5x5", "camImagesFlat"))
    a, b = lf[2, 2, :200, :200], lf[2, 3, :200, :200]
    ref = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                data_range=255, channel_axis=-1)
    assert abs(ssim(a, b) - ref) < 1e-3


def test_batched_torch_matches_loop(rng, device):
    a = torch.from_numpy(rng.random((2, 3, 20, 24, 3)).astype(np.float32)).to(device)
    b = (a + 0.05 * torch.randn_like(a)).clamp(0, 1)
    batched = ssim(a, b)
    assert batched.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            assert abs(float(batched[i, j]) - float(ssim(a[i, j], b[i, j]))) < 1e-6
    assert psnr(a, b).shape == (2, 3)


def test_identity_and_symmetry(rng):
    a, b = _noisy_pair(rng)
    assert psnr(a, a) == math.inf
    assert ssim(a, a) == pytest.approx(1.0, abs=1e-9)
    assert psnr(a, b) == pytest.approx(psnr(b, a))
    assert ssim(a, b) == pytest.approx(ssim(b, a))
    const = np.full((16, 16, 3), 7, np.uint8)
    assert ssim(const, const) == pytest.approx(1.0)


def test_lf_metrics_average_views(rng):
    ref = random_lf(rng, (3, 3, 16, 16, 3))
    test = np.clip(ref.astype(int) + rng.integers(-9, 10, ref.shape), 0, 255).astype(np.uint8)
    per_view = [psnr(ref[u, v], test[u, v]) for u in range(3) for v in range(3)]
    assert mpsnr(ref, test) == pytest.approx(np.mean(per_view))
    per_view_s = [ssim(ref[u, v], test[u, v]) for u in range(3) for v in range(3)]
    assert mssim(ref, test) == pytest.approx(np.mean(per_view_s))
    video = np.stack([ref, test])
    assert mpsnr(video, video[::-1]).shape == (2,)
    assert dof_psnr(ref, test) > mpsnr(ref, test)  # averaging views averages the noise away


def test_bpp():
    assert bpp(16000, (7, 7, 375, 540, 3)) == pytest.approx(8 * 16000 / (49 * 375 * 540))
    assert bpp(100, (2, 7, 7, 10, 10, 3)) == pytest.approx(800 / (2 * 4900))
    with pytest.raises(LFShapeError):
        bpp(1, (3, 3))


def test_shape_mismatch_raises(rng):
    with pytest.raises(LFShapeError):
        psnr(np.zeros((8, 8, 3)), np.zeros((8, 9, 3)))
    with pytest.raises(LFShapeError):
        ssim(np.zeros((8, 8, 3)), np.zeros((8, 8, 3)))


def test_bjontegaard_deltas():
    from lfstream.metrics import bd_psnr, bd_rate

    rates = np.array([0.01, 0.02, 0.04, 0.08])
    psnrs = np.array([30.0, 33.0, 36.0, 39.0])
    # B needs exactly 20 % fewer bits for the same PSNR everywhere
    assert bd_rate(rates, psnrs, 0.8 * rates, psnrs) == pytest.approx(-20.0, abs=1e-6)
    # B is 1 dB better at every rate
    assert bd_psnr(rates, psnrs, rates, psnrs + 1) == pytest.approx(1.0, abs=1e-9)
    assert bd_rate(rates, psnrs, rates, psnrs) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(LFValueError):
        bd_rate(rates[:3], psnrs[:3], rates, psnrs)


def test_numpy_and_torch_psnr_paths_agree(rng):
    a = rng.integers(0, 256, (2, 3, 20, 24, 3), dtype=np.uint8)
    b = np.clip(a.astype(int) + rng.integers(-9, 10, a.shape), 0, 255).astype(np.uint8)
    fast = psnr(a, b)
    ref = psnr(torch.from_numpy(a), torch.from_numpy(b)).numpy()
    assert fast.shape == (2, 3) and np.allclose(fast, ref, atol=1e-9)
    fa, fb = a.astype(np.float32) / 255, b.astype(np.float32) / 255
    assert np.allclose(psnr(fa, fb), ref, atol=1e-4)
    assert psnr(a[0, 0], a[0, 0]) == np.inf


def test_bd_pchip_uses_the_pareto_front_and_agrees_with_the_cubic_fit_on_smooth_curves():
    from lfstream.metrics import bd_psnr, bd_rate, pareto_front

    rates = np.array([0.005, 0.01, 0.02, 0.04, 0.08])
    psnrs = 28 + 4 * np.log2(rates / 0.005) ** 0.8
    # a dominated point (more bits, lower quality: the seahorse-at-q70 kind of dip) is ignored
    noisy_r, noisy_d = np.append(rates, 0.03), np.append(psnrs, psnrs[1])
    r, d = pareto_front(np.log10(noisy_r), noisy_d)
    assert len(r) == len(rates) and np.all(np.diff(r) > 0) and np.all(np.diff(d) > 0)
    assert bd_rate(rates, psnrs, noisy_r * 0.7, noisy_d) == pytest.approx(-30.0, abs=1e-6)
    shifted = bd_psnr(rates, psnrs, rates, psnrs + 0.25)
    assert shifted == pytest.approx(0.25, abs=1e-9)
    # smooth curves: piecewise cubic and the single cubic fit agree closely
    other = 27.5 + 4.2 * np.log2(rates / 0.005) ** 0.8
    assert bd_rate(rates, psnrs, rates, other) == pytest.approx(bd_rate(rates, psnrs, rates, other, method="cubic"), abs=1.5)
    with pytest.raises(LFValueError):
        bd_rate(rates, psnrs, rates, other, method="spline")


def test_8_bit_levels_against_floats_are_measured_on_one_scale(rng):
    """uint8 against float in [0, 1] (the stream's metrics of a float input against its
    uint8 decode): the uint8 side is taken to [0, 1], as the convention has them the same
    values; compared raw they measured the scales' difference (about -41 dB, or 4.8 dB for
    a light field against itself divided by 255). With ``data_range`` given, as given."""
    ref = random_lf(rng, (3, 3, 16, 16, 3))
    test = np.clip(ref.astype(np.int64) + rng.integers(-12, 13, ref.shape), 0, 255).astype(np.uint8)
    as_float = test.astype(np.float32) / np.float32(255.0)
    for numpy_or_torch in (lambda a: a, torch.from_numpy):
        a, b = numpy_or_torch(ref), numpy_or_torch(as_float)
        assert float(mpsnr(a, b)) == pytest.approx(float(mpsnr(ref, test)), abs=1e-4)
        assert float(mpsnr(b, a)) == pytest.approx(float(mpsnr(ref, test)), abs=1e-4)
        assert float(mssim(a, b)) == pytest.approx(float(mssim(ref, test)), abs=1e-5)
    assert math.isinf(mpsnr(ref, ref.astype(np.float32) / np.float32(255.0)))
    raw = mpsnr(ref, as_float, data_range=255.0)  # the caller's range: the samples as they are
    assert raw < 10 < float(mpsnr(ref, test))  # the scales' difference, not the noise
