"""Synthetic generator: determinism, ground truth, the disparity sign."""

import cv2
import numpy as np
import pytest

from lfstream.errors import LFValueError
from lfstream.lightfield import as_float
from lfstream.synth import SynthConfig, fronto_parallel_plane, render_clip, synth_clip


def test_deterministic_and_shaped():
    a = synth_clip(2, 5, (40, 48), seed=7, noise=2.0, vignetting=0.4)
    b = synth_clip(2, 5, (40, 48), seed=7, noise=2.0, vignetting=0.4)
    assert a.lf.shape == (2, 5, 5, 40, 48, 3) and a.lf.dtype == np.uint8
    assert a.disparity.shape == (2, 5, 5, 40, 48) and a.disparity.dtype == np.float32
    np.testing.assert_array_equal(a.lf, b.lf)
    np.testing.assert_array_equal(a.disparity, b.disparity)
    assert not np.array_equal(a.lf, synth_clip(2, 5, (40, 48), seed=8).lf)
    assert np.isfinite(a.disparity).all()


def residual_shift(ref: np.ndarray, img: np.ndarray) -> np.ndarray:
    """Least-squares (Lucas-Kanade) translation (dy, dx) that best maps ``img`` onto ``ref``;
    unbiased for the sub-pixel residuals measured here, unlike phase correlation."""
    gy, gx = np.gradient(ref.astype(np.float64))
    diff = (img - ref).astype(np.float64)
    a = np.array([[np.sum(gy * gy), np.sum(gy * gx)], [np.sum(gy * gx), np.sum(gx * gx)]])
    b = -np.array([np.sum(gy * diff), np.sum(gx * diff)])
    return np.linalg.solve(a, b)


@pytest.mark.parametrize("d", [-1.3, 0.45, 2.2])
def test_plane_warped_back_aligns(d):
    """A plane at disparity d, every view warped back by d, aligns with the centre view to
    < 0.05 px RMS (measured by least-squares registration of the smoothed images)."""
    clip = fronto_parallel_plane(7, (128, 128), d, seed=3)
    assert np.allclose(clip.disparity, d)
    lf = cv2.GaussianBlur(as_float(clip.lf[0]).mean(-1).reshape(49, 128, 128).transpose(1, 2, 0), (0, 0), 1.5)
    lf = lf.transpose(2, 0, 1).reshape(7, 7, 128, 128)
    inner = (slice(24, 104), slice(24, 104))
    errs = []
    for u in range(7):
        for v in range(7):
            # view(u, v)(p) = centre(p + d*(du, dv)): sample the view at p - d*(du, dv)
            m = np.float32([[1, 0, -d * (v - 3)], [0, 1, -d * (u - 3)]])
            back = cv2.warpAffine(lf[u, v], m, (128, 128), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
            errs.append(np.sum(residual_shift(lf[3, 3][inner], back[inner]) ** 2))
    assert np.sqrt(np.mean(errs)) < 0.05
    # the opposite sign is grossly misaligned: the test can tell the conventions apart
    m = np.float32([[1, 0, d * 3], [0, 1, d * 3]])
    wrong = cv2.warpAffine(lf[6, 6], m, (128, 128), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
    assert np.abs(lf[3, 3][inner] - wrong[inner]).mean() > 3 * np.abs(lf[3, 3][inner] - cv2.warpAffine(
        lf[6, 6], np.float32([[1, 0, -d * 3], [0, 1, -d * 3]]), (128, 128),
        flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)[inner]).mean()


def test_occlusion_ground_truth_is_front_most():
    clip = synth_clip(1, 5, (64, 64), seed=11, layers=3, motion=0.0, camera_pan=0.0)
    d = clip.disparity[0]
    far, near = SynthConfig().disparity_range
    assert far - 1e-3 <= d.min() and d.max() <= near + 1e-3
    # where a shape covers the centre view, its disparity exceeds the background's there
    assert len(np.unique(np.round(d[2, 2], 4))) > 3


def test_motion_moves_content_and_static_does_not():
    moving = synth_clip(3, 3, (48, 48), seed=1, motion=2.0)
    static = synth_clip(3, 3, (48, 48), seed=1, motion=0.0, camera_pan=0.0)
    assert np.abs(moving.lf[0].astype(int) - moving.lf[2]).mean() > 1
    np.testing.assert_array_equal(static.lf[0], static.lf[2])


def test_vignetting_darkens_corner_views():
    clip = synth_clip(1, 7, (64, 64), seed=2, vignetting=0.8)
    flat = synth_clip(1, 7, (64, 64), seed=2)
    ratio = clip.lf[0].mean(axis=(2, 3, 4)) / flat.lf[0].mean(axis=(2, 3, 4))
    assert ratio[0, 0] < ratio[3, 3] - 0.1


def test_bad_config_raises():
    for bad in (dict(views=0), dict(size=(4, 4)), dict(disparity_range=(1.0, -1.0)), dict(vignetting=2.0)):
        with pytest.raises(LFValueError):
            render_clip(SynthConfig(**bad))
