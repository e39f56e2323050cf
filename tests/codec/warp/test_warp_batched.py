"""The batched tensor warp (the decoder's warp for a GPU) against the fused CPU kernel it
restates: the same bytes without gains, within a level on a few samples with them."""

import io

import numpy as np
import pytest
import torch

import lfstream
from lfstream.codec.api import iter_decode
from lfstream.codec.decoder import Decoder
from lfstream.codec.warp.batched import _row_fold_bounds, _splat_rows, _window_max, warp_views_batched
from lfstream.codec.warp.cpu import splat_rows, splat_views, view_disparities, warp_views, warp_views_per_view
from lfstream.codec.warp.splat_kernels import fold_bounds, row_fold_bounds
from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import view_offsets
from lfstream.synth import synth_clip


def _scene(seed: int, size=(28, 36), views=5):
    clip = synth_clip(1, views, size, seed=seed, layers=3, motion=0, camera_pan=0, disparity_range=(-1.6, 2.2))
    return clip.lf[0, views // 2, views // 2], clip.disparity[0, views // 2, views // 2].astype(np.float32)


def _batched(centres, disps, views, **kw):
    return warp_views_batched(torch.from_numpy(np.stack(centres)), torch.from_numpy(np.stack(disps)), views,
                              **kw).numpy()


def _assert_within_a_level(got, ref, share=1e-3):
    # the gain blend's float32 roundings may differ from the compiled kernel's (fused
    # multiply-adds it chose): measured 20 samples in 3e7 of a 7x7x375x540 warp, by one level
    diff = np.abs(got.astype(int) - ref.astype(int))
    assert diff.max() <= 1
    assert (diff > 0).mean() <= share


@pytest.mark.parametrize("occlusion", [True, False])
def test_same_bytes_as_the_kernel(occlusion):
    centre, disp = _scene(5)
    ref = warp_views(centre, disp, (5, 3), occlusion=occlusion)
    assert (_batched([centre], [disp], (5, 3), occlusion=occlusion)[0] == ref).all()


def test_the_same_views_skip_the_splat_as_on_the_kernel(rng):
    """Frames whose gentle disparity lets some views skip the splat (splat_views) and one
    that splats every view, in one batch: the same fold bounds as the kernel's, to the bit,
    so the same views skip, and the same bytes."""
    centre, steep = _scene(11, size=(30, 40))
    ys, xs = np.mgrid[0:30, 0:40].astype(np.float32)
    gentle = (0.9 * np.sin(xs / 7.0) * np.cos(ys / 5.0)).astype(np.float32)
    for d in (gentle, steep, rng.normal(0, 1, (30, 40)).astype(np.float32)):
        rows = _row_fold_bounds(torch.from_numpy(d).view(1, 1, 30, 40))[0].numpy()
        assert tuple(rows.max(axis=-1)) == tuple(np.float32(x) for x in fold_bounds(d))
        rx, ry = np.empty(30, np.float32), np.empty(30, np.float32)
        row_fold_bounds(d, rx, ry)
        np.testing.assert_array_equal(rows, np.stack([rx, ry]))
    mask = splat_views(gentle, view_offsets((7, 5)))
    assert 0 < mask.sum() < 34
    got = _batched([centre, centre], [gentle, steep], (7, 5))
    assert (got[0] == warp_views(centre, gentle, (7, 5))).all()
    assert (got[1] == warp_views(centre, steep, (7, 5))).all()


@pytest.mark.parametrize("views,size", [((7, 7), (60, 80)), ((5, 3), (30, 40)), ((9, 9), (8, 5)), ((7, 5), (1, 6)),
                                        ((3, 3), (6, 1))])
def test_the_splat_rows_decided_on_the_device_are_the_hosts(views, size, rng):
    """Every frame's view rows at once on the maps' device (no trip to the host) against
    splat_rows frame by frame: flat, noisy, gentle, huge and stepped maps, in one batch."""
    h, w = size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    step = np.zeros(size, np.float32)
    step[h // 2:] = 3.0
    maps = [np.zeros(size, np.float32), rng.normal(0, 1.5, size).astype(np.float32),
            rng.normal(0, 0.02, size).astype(np.float32), (0.9 * np.sin(xs / 7.0) * np.cos(ys / 5.0)).astype(np.float32),
            rng.normal(0, 40, size).astype(np.float32), step]
    offsets = view_offsets(views)
    got = _splat_rows(torch.from_numpy(np.stack(maps))[:, None], offsets.reshape(-1, 2), 1.0).numpy()
    ref = np.stack([splat_rows(d, offsets).reshape(-1, h) for d in maps])
    np.testing.assert_array_equal(got, ref)


def test_window_max_is_the_clipped_window_maximum(rng):
    a = torch.from_numpy(rng.random((3, 37)))
    reach = torch.from_numpy(rng.integers(0, 45, (3, 6)))
    got = _window_max(a, reach).numpy()
    for f in range(3):
        for k in range(6):
            r = int(reach[f, k])
            ref = [a[f, max(0, y - r):y + r + 1].max().item() for y in range(37)]
            np.testing.assert_array_equal(got[f, k], ref)


def test_view_axes_and_a_ragged_grid():
    centre, disp = _scene(7, size=(25, 31))
    axes = np.array([[0.9, 0.25], [-0.3, 1.1]], np.float32)
    ref = warp_views(centre, disp, (3, 4), axes=axes)
    assert (_batched([centre], [disp], (3, 4), axes=axes)[0] == ref).all()


def test_gains_within_a_level(rng):
    centre, disp = _scene(8)
    for cg in (3, 1):
        gains = rng.uniform(0.6, 1.5, (3, 3, 4, 5, cg)).astype(np.float32)
        got = _batched([centre], [disp], (3, 3), gains=torch.from_numpy(gains[None]))[0]
        _assert_within_a_level(got, warp_views(centre, disp, (3, 3), gains=gains))


def test_frames_of_a_batch_are_warped_independently(rng):
    """Two frames, one with gains and one with gains of 1 (warped without them, as the kernel
    does), in passes of a few views: each equals its own warp."""
    (c0, d0), (c1, d1) = _scene(2), _scene(3)
    gains = np.ones((2, 5, 5, 3, 3, 3), np.float32)
    gains[0] = rng.uniform(0.8, 1.2, (5, 5, 3, 3, 3))
    got = _batched([c0, c1], [d0, d1], (5, 5), gains=torch.from_numpy(gains), chunk_pixels=3 * 28 * 36)
    _assert_within_a_level(got[0], warp_views(c0, d0, (5, 5), gains=gains[0]))
    assert (got[1] == warp_views(c1, d1, (5, 5))).all()


def test_per_view_disparities_as_warp_views_per_view():
    centre, disp = _scene(11)
    maps = view_disparities(disp, (5, 5))
    maps[1, 3] += 0.4  # a map that is not the splat of the centre's
    ref = warp_views_per_view(centre, maps)
    got = warp_views_batched(torch.from_numpy(centre[None]), torch.from_numpy(disp[None]), (5, 5),
                             view_disparities=torch.from_numpy(maps[None])).numpy()[0]
    assert (got == ref).all()


def test_huge_disparities_clamp_to_the_border():
    centre, _ = _scene(3, size=(16, 18), views=3)
    for d in (1e6, -1e6, 3e38):
        out = _batched([centre], [np.full(centre.shape[:2], d, np.float32)], (3, 3))[0]
        assert (out == warp_views(centre, np.full(centre.shape[:2], d, np.float32), (3, 3))).all()
        assert (out[1, 1] == centre).all()


def test_an_empty_batch_gives_an_empty_batch():
    out = warp_views_batched(torch.zeros((0, 8, 9, 3), dtype=torch.uint8), torch.zeros((0, 8, 9)), (3, 5))
    assert out.shape == (0, 3, 5, 8, 9, 3) and out.dtype == torch.uint8


def test_bad_input_names_the_parameter():
    centre, disp = _scene(4, size=(12, 14), views=3)
    c, d = torch.from_numpy(centre[None]), torch.from_numpy(disp[None])
    with pytest.raises(LFShapeError, match="centres"):
        warp_views_batched(c.float(), d, (3, 3))
    with pytest.raises(LFShapeError, match="disparities"):
        warp_views_batched(c, d[:, :-1], (3, 3))
    with pytest.raises(LFValueError, match="disparities"):
        warp_views_batched(c, torch.full_like(d, float("nan")), (3, 3))
    with pytest.raises(LFShapeError, match="gains"):
        warp_views_batched(c, d, (3, 3), gains=torch.ones(1, 2, 3, 2, 2, 3))
    with pytest.raises(LFValueError):
        warp_views_batched(c, d, (0, 3))


def test_the_decoder_warps_a_batch_on_the_device(monkeypatch):
    """The decoder's batched path (a CUDA device's), run here on the CPU: every frame of a
    vignetted clip within a level of the kernel's decode, gains and all."""
    clip = synth_clip(3, 5, (40, 52), seed=9, noise=1.0, vignetting=0.3)
    data = lfstream.encode(clip.lf)
    ref = list(iter_decode(io.BytesIO(data), batch=3))
    assert all(fr.gains is not None for fr in ref)
    monkeypatch.setattr(Decoder, "warps_on_device", property(lambda self: True))
    got = list(iter_decode(io.BytesIO(data), batch=3))
    assert [fr.seq for fr in got] == [fr.seq for fr in ref]
    for a, b in zip(got, ref):
        _assert_within_a_level(a.lf, b.lf)
        assert (a.disparity == b.disparity).all() and (a.gains == b.gains).all()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_the_decoder_on_cuda_gives_the_cpu_decode():
    """The whole decode on a CUDA device (the batch's centre views side by side, the warp on
    the device, the light fields back through page-locked memory) against the CPU decode:
    every frame, within a level, the frames independent of each other once yielded."""
    clip = synth_clip(4, 5, (40, 52), seed=9, noise=1.0, vignetting=0.3)
    data = lfstream.encode(clip.lf)
    ref = list(iter_decode(io.BytesIO(data), hance="off"))
    got = list(iter_decode(io.BytesIO(data), hance="off", device="cuda", batch=3))
    assert [fr.seq for fr in got] == [fr.seq for fr in ref]
    for a, b in zip(got, ref):
        assert isinstance(a.lf, np.ndarray) and a.lf.dtype == np.uint8
        _assert_within_a_level(a.lf, b.lf)
    got[0].lf[...] = 0  # a frame's memory is its own
    assert not (got[1].lf == 0).all()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_agrees_with_the_cpu(rng):
    centre, disp = _scene(6)
    gains = torch.from_numpy(rng.uniform(0.8, 1.2, (1, 5, 5, 3, 3, 3)).astype(np.float32))
    cpu = warp_views_batched(torch.from_numpy(centre[None]), torch.from_numpy(disp[None]), (5, 5), gains=gains)
    gpu = warp_views_batched(torch.from_numpy(centre[None]).cuda(), torch.from_numpy(disp[None]).cuda(), (5, 5),
                             gains=gains.cuda())
    _assert_within_a_level(gpu.cpu().numpy(), cpu.numpy())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
@pytest.mark.parametrize("case", ["plain", "gains", "gain_per_channel", "per_view", "chunked"])
def test_the_fused_cuda_kernel_agrees_with_the_tensor_path(case, rng, monkeypatch):
    """The one-kernel warp (Triton, lfstream/codec/warp/triton.py) against the tensor path on
    the same CUDA device and against the CPU kernel: frames that splat and frames that do not,
    per-frame gains, Depth-Net's per-view maps, several passes."""
    pytest.importorskip("triton")
    from lfstream.codec import warp_batched

    centre, steep = _scene(13, size=(37, 53))
    ys, xs = np.mgrid[0:37, 0:53].astype(np.float32)
    gentle = (0.9 * np.sin(xs / 7.0) * np.cos(ys / 5.0)).astype(np.float32)
    noisy = rng.normal(0, 1.5, (37, 53)).astype(np.float32)
    disps = [gentle, steep, noisy]
    centres = torch.from_numpy(np.stack([centre, centre[::-1].copy(), centre[:, ::-1].copy()])).cuda()
    d = torch.from_numpy(np.stack(disps)).cuda()
    kw = {}
    if case in ("gains", "chunked", "gain_per_channel"):
        gains = rng.uniform(0.75, 1.25, (3, 7, 5, 3, 4, 3 if case == "gain_per_channel" else 1)).astype(np.float32)
        gains[1] = 1.0  # a frame without gains in a batch with them
        kw["gains"] = torch.from_numpy(gains).cuda()
    if case == "per_view":
        kw["view_disparities"] = torch.from_numpy(rng.uniform(-2, 2, (3, 7, 5, 37, 53)).astype(np.float32)).cuda()
    if case == "chunked":
        kw["chunk_pixels"] = 37 * 53 * 3 * 4  # four views a pass
    assert warp_batched._fused_warp(d.device) is not None
    fused = warp_views_batched(centres, d, (7, 5), **kw).cpu().numpy()
    monkeypatch.setattr(warp_batched, "_fused_warp", lambda device: None)
    tensor = warp_views_batched(centres, d, (7, 5), **kw).cpu().numpy()
    _assert_within_a_level(fused, tensor)
    if case != "per_view":
        for k in range(3):
            g = None if "gains" not in kw else kw["gains"][k].cpu().numpy()
            _assert_within_a_level(fused[k], warp_views(centres[k].cpu().numpy(), disps[k], (7, 5), gains=g))


_INTERPRETED = """
import numpy as np, torch
from lfstream.codec import warp_batched, warp_triton
from lfstream.synth import synth_clip
clip = synth_clip(1, 5, (13, 17), seed=13, layers=3, motion=0, camera_pan=0, disparity_range=(-1.6, 2.2))
centre = clip.lf[0, 2, 2]
rng = np.random.default_rng(0)
ys, xs = np.mgrid[0:13, 0:17].astype(np.float32)
d = torch.from_numpy(np.stack([clip.disparity[0, 2, 2].astype(np.float32),
                               (0.9 * np.sin(xs / 3.0) * np.cos(ys / 2.0)).astype(np.float32)]))
centres = torch.from_numpy(np.stack([centre, centre[::-1].copy()]))
gains = torch.from_numpy(rng.uniform(0.75, 1.25, (2, 5, 3, 3, 4, 1)).astype(np.float32))
outs = []
for fused in (warp_triton, None):
    warp_batched._fused_warp = lambda device, fused=fused: fused
    outs.append([warp_batched.warp_views_batched(centres, d, (5, 3), **kw).numpy()
                 for kw in ({}, {"gains": gains}, {"chunk_pixels": 13 * 17 * 2 * 4})])
for a, b in zip(*outs):
    assert np.array_equal(a, b), np.abs(a.astype(int) - b.astype(int)).max()
print("same bytes")
"""


def test_the_triton_kernels_in_the_interpreter_give_the_tensor_paths_bytes():
    """The CUDA kernels (lfstream/codec/warp/triton.py) run by Triton's interpreter on the CPU,
    where Triton is installed (CUDA builds of torch bring it): frames that splat some rows and
    not others, gains, several passes; the bytes of the tensor path."""
    pytest.importorskip("triton")
    import os
    import subprocess
    import sys

    env = {**os.environ, "TRITON_INTERPRET": "1"}
    done = subprocess.run([sys.executable, "-c", _INTERPRETED], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "same bytes" in done.stdout, done.stderr[-2000:]


def test_the_copy_to_the_host_falls_back_where_page_locked_memory_is_refused(monkeypatch):
    """A batch too large for page-locked memory (or a host that refuses it) is copied to the
    host the plain way, with the same values."""
    from lfstream.codec import decoder

    values = torch.arange(24, dtype=torch.uint8).reshape(2, 3, 4)

    class OnCuda:  # a stand-in for a CUDA tensor: its device and its plain copy
        device = torch.device("cuda")
        shape, dtype = values.shape, values.dtype

        def cpu(self):
            return values

    def refuse(*args, **kwargs):
        raise RuntimeError("CUDA error: out of memory (cudaHostAlloc)")

    monkeypatch.setattr(torch, "empty", refuse)
    np.testing.assert_array_equal(decoder._to_host(OnCuda()), values.numpy())
    assert (decoder._to_host(values) == values.numpy()).all()  # a CPU tensor: .cpu()
