"""JPEG-Hance, Depth-Net, RefNet: architectures, presets, losses, shipped weights.

Tolerances: parameter counts of the paper presets within 2 % of the seed's; float32
module/function agreement 1e-6; shipped-weight quality thresholds are margins below the
values measured by bench/networks.py (stated at each assert).
"""

import shutil

import numpy as np
import pytest
import torch

from lfstream.codec import jpeg_roundtrip
from lfstream.codec.warp.cpu import warp_views, warp_views_per_view
from lfstream.errors import LFShapeError, LFValueError, WeightsError
from lfstream.lightfield import view_offsets
from lfstream.metrics import mpsnr, psnr, ssim
from lfstream.models.depth_net import build_depth_net, grid_disparities
from lfstream.models.jpeg_hance import build_jpeg_hance, jpeg_hance, restore_images
from lfstream.models.losses import depth_net_loss, psi, refnet_loss, ssim_torch
from lfstream.models.refnet import build_refnet
from lfstream.models.registry import (
    REGISTRY,
    ModelSpec,
    count_params,
    list_models,
    load_model,
    manifest_entry,
    register,
    spec,
)
from lfstream.models.warp import warp_per_view
from lfstream.synth import fronto_parallel_plane, synth_clip
from tests.conftest import shared

SEED_PARAMS = {"jpeg_hance": 202_435, "depth_net": 38_200_000, "refnet": 12_500_000}


def test_the_decoders_network_presets_are_the_registrys():
    """codec.decoder names the presets again (below models, and torch-free for the command
    line): the same set as the registry builds."""
    from lfstream.codec.decoder import NETWORK_PRESETS
    from lfstream.models.registry import PRESETS

    assert sorted(NETWORK_PRESETS) == sorted(PRESETS)


@pytest.mark.parametrize("name", sorted(SEED_PARAMS))
def test_paper_preset_parameter_counts(name):
    n = count_params(spec(name, "paper").build())
    assert abs(n - SEED_PARAMS[name]) / SEED_PARAMS[name] < 0.02, (name, n)


def test_manifest_counts_match_built_models():
    shipped = [m for m in list_models() if m["weights"]]
    assert {(m["name"], m["preset"]) for m in shipped} >= {("jpeg_hance", "fast"), ("depth_net", "fast"), ("refnet", "fast")}
    for m in shipped:
        entry = manifest_entry(m["name"], m["preset"])
        assert entry["params"] == count_params(spec(m["name"], m["preset"]).build(**_views_of(entry)))
        assert len(entry["sha256"]) == 64 and entry["recipe"]["model"] == m["name"]


def _views_of(entry):
    v = entry["config"].get("views")
    return {"views": tuple(v)} if v else {}


def test_registry_refuses_duplicates():
    s = REGISTRY[("refnet", "fast")]
    with pytest.raises(LFValueError, match="already registered"):
        register(ModelSpec(s.name, s.preset, s.model_cls, s.config_cls, s.config))
    with pytest.raises(LFValueError, match="unknown model"):
        spec("refnet", "huge")


def test_saved_weights_are_the_same_bytes_under_any_name(tmp_path):
    """A checkpoint's SHA-256 (what the manifest records) depends on the weights only, not on
    the file name or the writing process."""
    from lfstream.models.registry import save_checkpoint

    model = build_jpeg_hance("fast")
    a = save_checkpoint(model, "jpeg_hance", "fast", tmp_path / "a.pt")
    b = save_checkpoint(model, "jpeg_hance", "fast", tmp_path / "other-name.pt")
    assert a == b
    torch.nn.init.ones_(model.head.bias)
    assert save_checkpoint(model, "jpeg_hance", "fast", tmp_path / "a.pt") != a
    assert torch.equal(load_model("jpeg_hance", "fast", path=tmp_path / "a.pt").head.bias, model.head.bias)


def test_corrupt_or_missing_weights_are_clear_errors(tmp_path):
    entry = manifest_entry("jpeg_hance", "fast")
    src = load_model.__globals__["WEIGHTS_DIR"] / entry["file"]
    bad = tmp_path / "w.pt"
    shutil.copy(src, bad)
    data = bytearray(bad.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(data))
    with pytest.raises(WeightsError, match="SHA-256"):
        load_model("jpeg_hance", "fast", path=bad, sha256=entry["sha256"])
    with pytest.raises(WeightsError, match="missing"):
        load_model("jpeg_hance", "fast", path=tmp_path / "nope.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(WeightsError, match="not a valid"):
        load_model("jpeg_hance", "fast", path=tmp_path / "junk.pt")
    with pytest.raises(WeightsError, match="no trained weights"):
        load_model("refnet", "paper")


def test_untrained_hance_is_identity_and_function_matches_module():
    torch.manual_seed(0)
    model = build_jpeg_hance("fast").eval()
    x = torch.rand(2, 3, 19, 23)
    with torch.no_grad():
        assert torch.allclose(model(x), x, atol=1e-6)
        for p in model.head.parameters():
            p.normal_(0, 0.1)
        assert torch.allclose(jpeg_hance(x, model), model(x), atol=1e-6)
        assert torch.allclose(jpeg_hance(x[0], model), model(x[:1])[0], atol=1e-6)
    with pytest.raises(LFShapeError):
        jpeg_hance(torch.rand(4, 8, 8), model)


def test_hance_strength_scales_the_trained_correction():
    """HanceConfig.strength: the output moves from the input by that share of the full-strength
    correction (where nothing clips); 0 returns the input; the fast preset's share is in (0, 1]."""
    from dataclasses import replace

    from lfstream.models.jpeg_hance import HANCE_PRESETS, JPEGHance

    torch.manual_seed(1)
    full = JPEGHance(replace(HANCE_PRESETS["fast"], strength=1.0)).eval()
    with torch.no_grad():
        for p in full.head.parameters():
            p.normal_(0, 0.02)
        x = 0.25 + 0.5 * torch.rand(2, 3, 17, 21)  # away from 0 and 1: no clipping
        correction = full(x) - x
        assert correction.abs().max() > 1e-3
        for share in (0.0, 0.4, 0.75):
            full.config = replace(full.config, strength=share)
            torch.testing.assert_close(full(x) - x, share * correction, atol=2e-6, rtol=1e-4)
    assert 0.0 < HANCE_PRESETS["fast"].strength <= 1.0


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
@pytest.mark.parametrize("preset", ["fast", "paper"])
def test_hance_in_strips_is_the_whole_forward_pass(preset, precision, monkeypatch, rng):
    """restore_images on the CPU runs row strips with their receptive field's context rows:
    the bytes of the whole image's forward pass at the same precision (exact here; a level
    on at most 1e-4 of the samples allowed for another CPU's kernels), also with strips of 8
    rows, a batch, a height that is not a multiple of the strip, and an image shorter than
    the context."""
    import lfstream.models.jpeg_hance as jh
    from lfstream.lightfield import to_network_input
    from lfstream.models.device import inference_precision

    model = load_model("jpeg_hance", preset, "cpu")

    def whole(images):
        with torch.inference_mode(), inference_precision("cpu", precision):
            y = model(to_network_input(images)).float().mul_(255.0).add_(0.5).clamp_(0, 255).to(torch.uint8)
        return y.permute(0, 2, 3, 1).numpy()

    tall = rng.integers(0, 256, (2, 61, 37, 3), dtype=np.uint8)
    short = np.ascontiguousarray(tall[1:, :5])
    wants = [whole(tall), whole(short)]
    for budget in (1, 40_000, 10 << 20):  # rows 8 (the least), a few strips, the whole image
        monkeypatch.setattr(jh, "HANCE_STRIP_BYTES", budget)
        for images, want in zip((tall, short), wants):
            diff = np.abs(restore_images(images, model, precision=precision).astype(np.int16) - want)
            assert diff.max() <= 1 and (diff > 0).mean() <= 1e-4, budget


@pytest.mark.parametrize("size", [(1, 1), (7, 33), (40, 64)])
def test_depth_refiner_any_size_and_finite_on_constant_images(size):
    torch.manual_seed(0)
    net = build_depth_net("fast").eval()
    for prm in net.head.parameters():  # a non-zero head, as after training
        torch.nn.init.normal_(prm, std=0.5)
    x = torch.full((2, 3, *size), 0.5)
    hint = torch.zeros(2, 1, *size)
    maps = torch.zeros(2, 5, 3, *size)
    offsets = torch.from_numpy(view_offsets((5, 3)))
    with torch.no_grad():
        d = net(x, hint, maps, offsets)
        c = net.corrections(torch.rand(2, 3, *size), torch.rand(2, 1, *size))
    assert d.shape == (2, 5, 3, *size) and torch.isfinite(d).all()
    assert c.abs().max() <= net.config.max_correction + 1e-6 and torch.isfinite(c).all()
    with pytest.raises(LFShapeError):
        net(x, hint, maps[:, :, :2], offsets)


def test_untrained_depth_refiner_decodes_exactly_the_hint(monkeypatch):
    """The refiner's last layer starts at zero: through the decoder, --depth net with an
    untrained refiner gives the bytes of --depth hint (gains and view axes included)."""
    import lfstream
    from lfstream.models import registry

    clip = synth_clip(1, 5, (48, 64), seed=4, noise=2.0, vignetting=0.3, motion=0, camera_pan=0)
    data = lfstream.encode(clip.lf[0])
    torch.manual_seed(0)
    monkeypatch.setattr(registry, "load_model", lambda *a, **k: build_depth_net("fast").eval())
    net = lfstream.decode(data, depth="net", hance="off")
    hint = lfstream.decode(data, depth="hint", hance="off")
    assert np.array_equal(net, hint)


def test_grid_disparities_maps_offsets():
    maps = np.arange(49, dtype=np.float32).reshape(7, 7, 1, 1)
    assert grid_disparities(maps, (7, 7))[..., 0, 0].tolist() == maps[..., 0, 0].tolist()
    assert grid_disparities(maps, (5, 5))[..., 0, 0][2, 2] == 24
    g = grid_disparities(maps, (9, 9))[..., 0, 0]
    assert g[0, 0] == 0 and g[8, 8] == 48 and g[4, 4] == 24


def test_warp_per_view_matches_warp_views_for_one_plane(rng):
    centre = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    maps = np.full((3, 5, 30, 40), 0.75, np.float32)
    a = warp_views_per_view(centre, maps)
    b = warp_views(centre, 0.75, (3, 5), occlusion=False)
    assert np.abs(a.astype(int) - b).max() <= 1
    with pytest.raises(LFShapeError):
        warp_views_per_view(centre, maps[..., :10])
    t = warp_per_view(torch.from_numpy(centre).permute(2, 0, 1).float()[None] / 255, torch.from_numpy(maps)[None])
    t8 = (t[0].permute(0, 1, 3, 4, 2) * 255 + 0.5).clamp(0, 255).byte().numpy()
    assert np.abs(t8.astype(int) - a).max() <= 1


@pytest.mark.parametrize("views", [(5, 5), (3, 7)])
def test_refnet_any_grid_and_untrained_is_view_mean(views):
    torch.manual_seed(0)
    net = build_refnet("fast", views=views).eval()
    lf = torch.rand(1, *views, 3, 20, 26)
    with torch.no_grad():
        out = net(lf)
    assert out.shape == (1, 16, 3, 20, 26)
    assert torch.allclose(out, lf.mean(dim=(1, 2))[:, None].expand_as(out), atol=1e-6)
    with pytest.raises(LFShapeError, match="RefNet built for"):
        net(torch.rand(1, 7, 7, 3, 20, 26))
    with torch.no_grad():
        assert torch.isfinite(net(torch.full((1, *views, 3, 8, 8), 0.3))).all()


def test_losses():
    torch.manual_seed(0)
    a, b = torch.rand(2, 3, 24, 24), torch.rand(2, 3, 24, 24)
    assert float(psi(a, a, 0.5)) == pytest.approx(0.0, abs=1e-6)
    assert float(psi(a, b, 0.5)) > 0.1
    # the differentiable SSIM agrees with the float64 metric (same window, valid region)
    ref = float(np.mean([ssim(x.permute(1, 2, 0).numpy(), y.permute(1, 2, 0).numpy(), data_range=1.0)
                         for x, y in zip(a, b)]))
    assert float(ssim_torch(a, b)) == pytest.approx(ref, abs=1e-3)
    stack = torch.rand(1, 16, 3, 16, 16)
    assert float(refnet_loss(stack, (stack + 0.01).clamp(0, 1))) < float(refnet_loss(stack, torch.rand_like(stack)))


def test_depth_loss_prefers_the_true_disparity():
    clip = fronto_parallel_plane(5, (48, 48), 1.0, seed=3)
    lf = torch.from_numpy(clip.lf[0]).permute(0, 1, 4, 2, 3).float()[None] / 255
    centre = lf[:, 2, 2]
    right, _ = depth_net_loss(centre, lf, torch.full((1, 5, 5, 48, 48), 1.0))
    wrong, _ = depth_net_loss(centre, lf, torch.full((1, 5, 5, 48, 48), -1.0))
    flat, _ = depth_net_loss(centre, lf, torch.zeros(1, 5, 5, 48, 48))
    assert float(right) < 0.5 * min(float(wrong), float(flat))


# --- shipped weights: quality floors below the measured values (bench/networks.py) ----------


def test_shipped_depth_net_stays_near_the_hint_on_a_held_out_light_field():
    """The shipped refiner on a scene it was not trained on, through the decoder: close to
    the hint it refines (it starts from the hint's own per-view maps) and far above flat."""
    import lfstream

    lf = lfstream.read_lf(shared("seahorse5x5", "camImagesFlat"))[:, :, 150:278, 150:310]
    data = lfstream.encode(lf)
    net, hint, flat = (mpsnr(lf, lfstream.decode(data, depth=d, hance="off")[0]) for d in ("net", "hint", "flat"))
    # measured on this crop: net 40.69, hint 40.97, flat 27.94 dB
    assert net > hint - 0.6 and net > flat + 8.0, (net, hint, flat)


@pytest.mark.parametrize("folder", [("seahorse5x5", "camImagesFlat"), ("hci_star", "cotton")])
def test_shipped_hance_beats_the_post_filter_on_held_out_scenes(folder):
    """JPEG-Hance fast restores the post-filtered JPEG (what the decoder feeds it) better
    than the post-filter alone, at the default quality, on scenes it was not trained on."""
    import lfstream
    from lfstream.metrics import ssim
    from lfstream.models.registry import manifest_entry

    model = load_model("jpeg_hance")
    assert model.config.after_deblock
    assert folder[-1] not in manifest_entry("jpeg_hance", "fast")["recipe"]["scenes"]
    lf, mask = lfstream.read_lf(shared(*folder), return_mask=True)
    view = lf[lf.shape[0] // 2, lf.shape[1] // 2, 64:320, 64:384]  # seahorse: mostly black
    filt = jpeg_roundtrip(view, 50, deblock=True)
    out = restore_images(filt[None], model)[0]
    # measured on the full centre views: seahorse +0.57 dB, cotton +0.27 (SSIM not lower)
    assert psnr(view, out) > psnr(view, filt) + 0.1
    assert ssim(view, out) > ssim(view, filt) - 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("folder, floor", [(("seahorse5x5", "camImagesFlat"), 0.17), (("hci_star", "cotton"), 0.25),
                                           (("lytro_translucent",), 0.1)])
def test_shipped_hance_gains_on_the_decoded_light_field_of_every_held_out_scene(folder, floor):
    """The target for JPEG-Hance fast: on the decoded light field of the default
    encode (its JPEG centre view, quality 50) of each scene it was not trained on, at least
    +0.1 dB MPSNR and MSSIM not lower, at the precision the decoder picks on this machine."""
    import lfstream
    from lfstream.metrics import mssim
    from lfstream.models.registry import manifest_entry

    assert folder[-1] not in manifest_entry("jpeg_hance", "fast")["recipe"]["scenes"]
    lf, mask = lfstream.read_lf(shared(*folder), return_mask=True)
    present = None if mask.all() else mask
    data = lfstream.encode(lf, present=present, preset="fast")
    on, off = (lfstream.decode(data, hance=mode)[0] for mode in ("on", "off"))
    # measured (bfloat16 / float32): seahorse +0.215 / +0.217 dB, cotton +0.294 / +0.293,
    # lytro_translucent +0.105 / +0.106; MSSIM +0.0002 / +0.0014 / +0.0009
    assert mpsnr(lf, on, present=mask) > mpsnr(lf, off, present=mask) + floor - 0.005
    assert mpsnr(lf, on, present=mask) > mpsnr(lf, off, present=mask) + 0.1
    assert mssim(lf, on, present=mask) > mssim(lf, off, present=mask)


def test_shipped_refnet_close_to_sas():
    from lfstream.refocus import focal_stack

    lf = synth_clip(1, 7, (64, 80), seed=77, motion=0, camera_pan=0).lf[0]
    out = focal_stack(lf, method="refnet")
    ref = focal_stack(lf)
    assert out.shape == ref.shape and out.dtype == np.uint8
    assert float(np.mean(psnr(ref, out))) > 30.0  # measured 34-47 dB on held-out 128x128 scenes
    with pytest.raises(LFValueError, match="sixteen"):
        focal_stack(lf, [0.5, 1.0], method="refnet")
    with pytest.raises(LFValueError, match="7x7"):
        focal_stack(lf[1:6, 1:6], method="refnet")
