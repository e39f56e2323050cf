"""tools/train.py's losses on a small rendered LF: the decoded-LF objective of JPEG-Hance and
the hint refiner's photometric loss, both through :func:`train.crop_views`."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))

import train  # noqa: E402

from lfstream.models.registry import save_checkpoint, spec  # noqa: E402
from lfstream.synth import SynthConfig, render_clip  # noqa: E402

RECIPE = train.Recipe(model="jpeg_hance", batch=2, crop=32, margin=8, views=4, objective="lf")


@pytest.fixture(scope="module")
def sample() -> train.DepthSample:
    lf = render_clip(SynthConfig(views=5, size=(96, 128), layers=3, disparity_range=(-2.0, 2.5), motion=0.0,
                                 camera_pan=0.0, seed=3)).lf[0]
    return train.depth_sample("synthetic", lf, np.ones(lf.shape[:2], bool), 70, 4)


class Blur(torch.nn.Module):
    """A 'restoration' that only blurs: 5x5 box filter."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.nn.functional.avg_pool2d(torch.nn.functional.pad(x, (2, 2, 2, 2), mode="replicate"), 5, 1)


def test_lf_loss_of_the_identity_is_the_unrestored_input(sample):
    model = spec("jpeg_hance", "fast").build()  # untrained: returns its input
    loss, terms = train.hance_lf_loss(model, sample, RECIPE, np.random.default_rng(0), "cpu")
    assert torch.isfinite(loss)
    assert terms["lf_gain_db"] == pytest.approx(0.0, abs=1e-4)
    loss.backward()  # the zero-initialised head still gets a gradient: the loss trains it
    assert float(model.head.weight.grad.abs().sum()) > 0


def test_lf_loss_penalises_a_blur_and_is_seeded(sample):
    _, blurred = train.hance_lf_loss(Blur(), sample, RECIPE, np.random.default_rng(0), "cpu")
    assert blurred["lf_gain_db"] < -0.5  # a 5x5 blur costs dB on a textured render
    _, again = train.hance_lf_loss(Blur(), sample, RECIPE, np.random.default_rng(0), "cpu")
    assert again == blurred


def test_crop_views_draws_present_views_and_the_centre_only_when_asked(sample):
    rng = np.random.default_rng(1)
    ys, xs = np.array([0, 40]), np.array([8, 64])
    without = train.crop_views(sample, ys, xs, 16, 24, rng, with_centre=False)
    with_centre = train.crop_views(sample, ys, xs, 16, 25, rng, with_centre=True)
    assert len(without) == 2 * 24 and len(with_centre) == 2 * 25  # 5x5 views, all present
    assert [v.crop for v in without] == [0] * 24 + [1] * 24
    assert not any(v.oy == 0 and v.ox == 0 for v in without)
    assert sum(v.oy == 0 and v.ox == 0 for v in with_centre) == 2
    v = without[30]
    assert v.target.shape == (16, 16, 3) and v.disparity.shape == (16, 16) and v.gain.shape[:2] == (16, 16)


def test_untrained_refiner_loss_is_the_hints_and_the_hint_beats_flat(sample):
    model = spec("depth_net", "fast").build()  # zero head: the hint's maps exactly
    recipe = replace(RECIPE, model="depth_net", crop=48, views=3)

    def loss(s: train.DepthSample, **kw) -> float:
        with torch.no_grad():
            return float(train.refiner_batch_loss(model, s, recipe, np.random.default_rng(2), "cpu", **kw)[0])

    refined, hint = loss(sample), loss(sample, zero=True)
    assert np.isfinite(refined) and refined == pytest.approx(hint, rel=1e-6)
    flat = loss(replace(sample, view_maps=np.zeros_like(sample.view_maps)), zero=True)
    # the views are warped with their own maps and offsets: measured 0.59 of flat's MSE
    assert hint < 0.75 * flat


def _view_mse(s: train.DepthSample, a: int, b: int, offsets: np.ndarray | None = None) -> float:
    """MSE of view ``(a, b)`` of ``s`` predicted over the whole image as the refiner's loss
    predicts it: the centre bilinearly sampled along the view's map times its offset, gains in."""
    from lfstream.lightfield import to_network_input
    from lfstream.models.warp import pixel_grid, sample_bilinear

    oy, ox = (s.offsets if offsets is None else offsets)[a, b]
    gy, gx = pixel_grid(*s.hint.shape, "cpu", torch.float64)
    d = torch.from_numpy(np.ascontiguousarray(s.view_maps[a, b], np.float64))
    centre = to_network_input(s.centre).double()[None]
    warped = sample_bilinear(centre, (gy + d * float(oy))[None], (gx + d * float(ox))[None])[0]
    gain = torch.from_numpy(np.ascontiguousarray(s.gains[a, b], np.float64)).permute(2, 0, 1)
    return float(torch.mean((warped * gain - to_network_input(s.truth[a, b]).double()) ** 2))


@pytest.mark.parametrize("flip_y, flip_x, transpose", [(1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1)])
def test_a_mirrored_sample_is_the_same_light_field(sample, flip_y, flip_x, transpose):
    """The refiner's augmentation: every view of a mirrored or transposed sample is predicted
    exactly as well as before (to 1e-9 relative), and only because its offsets turned with
    it: the images mirrored under the old offsets predict the views worse."""
    t = train.transformed_sample(sample, bool(flip_y), bool(flip_x), bool(transpose))
    assert t.centre.shape == (sample.centre.shape[1::-1] + (3,) if transpose else sample.centre.shape)
    for a, b in [(0, 0), (1, 3), (4, 2)]:
        assert _view_mse(t, a, b) == pytest.approx(_view_mse(sample, a, b), rel=1e-9)
    stale = _view_mse(t, 0, 1, offsets=sample.offsets)  # offsets (-2, -1): no transform keeps them
    assert stale > 1.2 * _view_mse(sample, 0, 1)


def test_refiner_log_loss_and_flips_keep_the_hint_as_the_untrained_networks_output(sample):
    """``loss="log_mse"`` is the log of the MSE loss of the same draw; with ``flips`` the
    untrained refiner still equals the hint on every draw (its corrections are zero)."""
    model = spec("depth_net", "fast").build()
    recipe = replace(RECIPE, model="depth_net", crop=48, views=3)
    with torch.no_grad():
        mse = float(train.refiner_batch_loss(model, sample, recipe, np.random.default_rng(5), "cpu")[0])
        log = float(train.refiner_batch_loss(model, sample, replace(recipe, loss="log_mse"),
                                             np.random.default_rng(5), "cpu")[0])
        assert log == pytest.approx(np.log(mse + 1e-8), rel=1e-6)
        for seed in range(4):
            flipped = replace(recipe, flips="dihedral", loss="log_mse")
            refined, hint = (float(train.refiner_batch_loss(model, sample, flipped, np.random.default_rng(seed), "cpu",
                                                            zero=z)[0]) for z in (False, True))
            assert np.isfinite(refined) and refined == pytest.approx(hint, rel=1e-6)


@pytest.mark.slow
def test_two_phase_training_records_the_image_phase_as_the_init(tmp_path):
    """``tools/train.py jpeg_hance`` (fast): the image phase, then the decoded-LF phase from
    its weights; the second phase's checkpoint records the first's SHA-256 and recipe."""
    from lfstream.models.manifest import sha256_file
    from tests.conftest import shared

    shared("lytro_bikes")  # skips without the samples
    assert train.main(["jpeg_hance", "--steps", "1", "--out", str(tmp_path)]) == 0
    first = torch.load(tmp_path / "phase1" / "jpeg_hance-fast.ckpt", weights_only=False)
    second = torch.load(tmp_path / "phase2" / "jpeg_hance-fast.ckpt", weights_only=False)
    assert first["recipe"]["objective"] == "image" and first["recipe"]["init"] is None
    assert second["recipe"]["objective"] == "lf" and second["recipe"]["init"]["recipe"] == first["recipe"]
    model = spec("jpeg_hance", "fast").build()
    model.load_state_dict(first["model"])  # the first phase's weights, saved as the tool saves them
    assert save_checkpoint(model, "jpeg_hance", "fast", tmp_path / "first.pt") == second["recipe"]["init"]["sha256"]
    # the final weights are the second phase's, and they are not the first phase's
    assert sha256_file(tmp_path / "jpeg_hance-fast.pt") != second["recipe"]["init"]["sha256"]
    assert not torch.equal(first["model"]["head.weight"], second["model"]["head.weight"])


def test_bad_init_is_one_line_and_status_2(tmp_path, capsys):
    missing = tmp_path / "missing.pt"
    assert train.main(["jpeg_hance", "--init", str(missing), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(missing) in err
    with pytest.raises(SystemExit) as exc:  # argparse's error: usage and one line, status 2
        train.main(["refnet", "--init", "shipped", "--out", str(tmp_path)])
    assert exc.value.code == 2 and "--init" in capsys.readouterr().err


def test_scenes_option_names_shared_samples(tmp_path, capsys):
    """``--scenes`` (what tools/hance_strength.py leaves one out of): an unknown scene is
    argparse's one line and status 2, before anything trains."""
    with pytest.raises(SystemExit) as exc:
        train.main(["jpeg_hance", "--scenes", "lytro_bikes,nowhere", "--out", str(tmp_path)])
    assert exc.value.code == 2 and "nowhere" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_a_phase_trains_on_the_scenes_given_at_full_strength(tmp_path):
    """``--scenes``: the recipe records the scenes; the network trains its whole correction
    and is saved with the preset's strength (HanceConfig.strength)."""
    from tests.conftest import shared

    shared("lytro_bikes")  # skips without the samples
    assert train.main(["jpeg_hance", "--steps", "1", "--objective", "image", "--scenes", "dino",
                       "--out", str(tmp_path)]) == 0
    saved = torch.load(tmp_path / "jpeg_hance-fast.pt", weights_only=False)
    ckpt = torch.load(tmp_path / "jpeg_hance-fast.ckpt", weights_only=False)
    assert list(ckpt["recipe"]["scenes"]) == ["dino"]
    assert saved["config"]["strength"] == spec("jpeg_hance", "fast").config.strength


def test_the_seed_depth_loss_rewards_the_true_disparity(sample):
    """The seed's Depth-Net's photometric loss (the centre view warped by the predicted
    disparity against the true views): lower for the scene's own disparity than for zero,
    and the untrained network (zero head) scores exactly zero disparity's loss."""
    from lfstream.models.centre_depth import CentreDepthNet

    recipe = replace(RECIPE, model="depth_centre", crop=48, views=4, batch=3)

    class Fixed(torch.nn.Module):
        def __init__(self, d: np.ndarray | None) -> None:
            super().__init__()
            self.d = d

        def forward(self, crops: torch.Tensor) -> torch.Tensor:
            b, _, c, _ = crops.shape
            if self.d is None:
                return torch.zeros((b, 1, c, c))
            return torch.from_numpy(np.ascontiguousarray(self.d)).float()[None, None].expand(b, 1, c, c)

    def loss(model) -> float:
        with torch.no_grad():
            return float(train.centre_depth_batch_loss(model, sample, replace(recipe, flips="none"),
                                                       np.random.default_rng(4), "cpu")[0])

    zero = loss(Fixed(None))
    assert loss(CentreDepthNet()) == pytest.approx(zero, abs=1e-6)
    # a constant at the scene's median disparity beats zero (the sample's layers span -2 .. 2.5)
    assert loss(Fixed(np.full((48, 48), float(np.median(sample.hint)), np.float32))) < zero - 0.1


def test_the_seed_depth_net_trains_on_the_cpu_and_its_checkpoint_loads(tmp_path):
    """``tools/train.py depth_centre`` (the seed's Depth-Net, reduced to a few steps): it
    records the scenes it trained on, and the checkpoint loads as the registry's network
    with finite predictions that moved away from the untrained zero."""
    from lfstream.models.centre_depth import predict_centre_disparity
    from lfstream.models.registry import load_model
    from tests.conftest import shared

    shared("lytro_bikes")  # skips without the samples
    assert train.main(["depth_centre", "--steps", "3", "--batch", "2", "--scenes", "lytro_bikes",
                       "--out", str(tmp_path), "--checkpoint-every", "1000"]) == 0
    ckpt = torch.load(tmp_path / "depth_centre-fast.ckpt", weights_only=False)
    assert list(ckpt["recipe"]["scenes"]) == ["lytro_bikes"] and ckpt["recipe"]["model"] == "depth_centre"
    net = load_model("depth_centre", "fast", path=tmp_path / "depth_centre-fast.pt")
    d = predict_centre_disparity(np.random.default_rng(1).integers(0, 256, (1, 40, 56, 3), dtype=np.uint8), net)
    assert d.shape == (1, 40, 56) and np.isfinite(d).all() and np.abs(d).max() > 0
