"""Where and at what precision the networks run (lfstream.models.device).

Tolerances: bfloat16 against float32 inference, measured on the shared samples' centre
views (q50, post-filtered, 192 x 256 crops): JPEG-Hance at most 1 level on at most 4.1 % of
the samples, PSNR within 0.018 dB (asserted: 1 level, 8 %, 0.05 dB); Depth-Net fast's
per-view disparities within 0.0014 px (asserted 0.005).
"""

import numpy as np
import pytest
import torch

import lfstream
from lfstream.codec import jpeg_roundtrip
from lfstream.errors import LFValueError
from lfstream.metrics import psnr
from lfstream.models import device as dev
from lfstream.models.depth_net import build_depth_net, predict_view_disparities
from lfstream.models.jpeg_hance import restore_images
from lfstream.models.registry import load_model
from tests.conftest import shared


def test_bfloat16_only_on_a_cpu_that_has_it_natively(monkeypatch):
    monkeypatch.setattr(torch.cpu, "get_capabilities", lambda: {"avx512_bf16": True})
    assert dev.native_bfloat16("cpu") and dev.inference_bfloat16("cpu")
    assert not dev.native_bfloat16("cuda") and not dev.native_bfloat16("cuda:0")  # GPUs keep float32
    assert not dev.inference_bfloat16("cpu", "float32")
    monkeypatch.setattr(torch.cpu, "get_capabilities", lambda: {"amx_bf16": True})
    assert dev.native_bfloat16("cpu")
    monkeypatch.setattr(torch.cpu, "get_capabilities", lambda: {"avx512_bf16": False, "avx2": True})
    assert not dev.native_bfloat16("cpu") and not dev.inference_bfloat16("cpu")
    assert dev.inference_bfloat16("cpu", "bfloat16")  # asked for: emulated where not native


def test_precision_is_checked():
    with pytest.raises(LFValueError, match="precision"):
        dev.inference_bfloat16("cpu", "half")
    with pytest.raises(LFValueError, match="precision"):
        restore_images(np.zeros((1, 8, 8, 3), np.uint8), load_model("jpeg_hance"), precision="fp16")


def test_inference_precision_is_autocast_in_its_block_only():
    x = torch.rand(1, 3, 8, 8)
    conv = torch.nn.Conv2d(3, 4, 3, padding=1)
    with dev.inference_precision("cpu", "bfloat16") as on:
        assert on and conv(x).dtype == torch.bfloat16
    assert conv(x).dtype == torch.float32  # no state left behind
    with dev.inference_precision("cpu", "float32") as on:
        assert not on and conv(x).dtype == torch.float32


@pytest.mark.parametrize("preset", ["fast", "paper"])
@pytest.mark.parametrize("folder", [("seahorse5x5", "camImagesFlat"), ("lytro_translucent",)])
def test_hance_in_bfloat16_restores_like_float32(folder, preset):
    lf = lfstream.read_lf(shared(*folder))
    view = lf[lf.shape[0] // 2, lf.shape[1] // 2, 64:256, 64:320]
    filt = jpeg_roundtrip(view, 50, deblock=True)
    model = load_model("jpeg_hance", preset)
    full = restore_images(filt[None], model, precision="float32")[0]
    half = restore_images(filt[None], model, precision="bfloat16")[0]
    diff = np.abs(full.astype(np.int16) - half)
    assert diff.max() <= 1 and (diff > 0).mean() <= 0.08
    assert abs(psnr(view, half) - psnr(view, full)) <= 0.05
    assert np.array_equal(half, restore_images(filt[None], model, precision="bfloat16")[0])  # deterministic


def test_depth_refiner_in_bfloat16_refines_like_float32():
    lf = lfstream.read_lf(shared("lytro_translucent"))
    centre = jpeg_roundtrip(lf[3, 3, 64:256, 64:320], 50, deblock=True)
    hint = np.full(centre.shape[:2], 0.3, np.float32)
    model = load_model("depth_net", "fast")
    full, half = (predict_view_disparities(centre[None], model, (5, 5), hint[None], precision=p)
                  for p in ("float32", "bfloat16"))
    assert np.isfinite(half).all() and np.abs(full - half).max() <= 5e-3
    # the refiner's zero head is zero in bfloat16 too: the untrained network is the hint's maps
    untrained = build_depth_net("fast").eval()
    assert np.array_equal(predict_view_disparities(centre[None], untrained, (5, 5), hint[None], precision="bfloat16"),
                          predict_view_disparities(centre[None], untrained, (5, 5), hint[None], precision="float32"))


def test_the_decoder_follows_the_cpu(monkeypatch):
    """``lfstream.decode`` runs the networks at ``"auto"``: float32 bytes where the CPU has no
    native bfloat16, the bfloat16 ones where it has."""
    lf = lfstream.read_lf(shared("lytro_translucent"))[:, :, 64:192, 64:256]
    data = lfstream.encode(lf, preset="fast")
    wants = {p: lfstream.decode(data, hance="on", precision=p) for p in ("float32", "bfloat16")}
    assert not np.array_equal(wants["float32"], wants["bfloat16"])
    for native in (False, True):
        monkeypatch.setattr(dev, "native_bfloat16", lambda device, native=native: native and device == "cpu")
        assert np.array_equal(lfstream.decode(data, hance="on"), wants["bfloat16" if native else "float32"])
