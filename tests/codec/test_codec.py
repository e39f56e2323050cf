"""Encoder/decoder: reconstruction quality, depth hint accuracy, warp, CLI."""

import io
import json

import numpy as np
import pytest
import torch

import lfstream
from lfstream.cli import main
from lfstream.codec.hint import HintOptions, decode_hint, disparity_errors, encode_hint, estimate_disparity
from lfstream.codec.warp.cpu import warp_views
from lfstream.errors import LFStreamError, LFValueError
from lfstream.metrics import capped, mpsnr, mssim, psnr
from lfstream.models.warp import warp_views_torch
from lfstream.synth import fronto_parallel_plane, synth_clip


def mean_psnr(ref, test):
    """MPSNR with identical views capped (the centre view of a warp is exact)."""
    return float(np.mean([capped(p) for p in np.ravel(psnr(ref, test))]))


def test_warp_zero_disparity_is_identity(rng):
    centre = rng.integers(0, 256, (20, 24, 3), dtype=np.uint8)
    out = warp_views(centre, np.zeros((20, 24), np.float32), (3, 5))
    assert out.shape == (3, 5, 20, 24, 3) and (out == centre).all()
    out = warp_views(centre, np.full((20, 24), 1e-9, np.float32), (3, 5), occlusion=False)
    assert np.abs(out.astype(int) - centre).max() <= 1


@pytest.mark.parametrize("occlusion", [True, False])
def test_warp_reconstructs_a_plane(occlusion):
    clip = fronto_parallel_plane(7, (64, 80), 0.9, seed=6)
    lf, d = clip.lf[0], clip.disparity[0, 3, 3]
    out = warp_views(lf[3, 3], d, (7, 7), occlusion=occlusion)
    inner = (slice(None), slice(None), slice(8, -8), slice(8, -8))
    assert mean_psnr(lf[inner], out[inner]) > 30
    flat = warp_views(lf[3, 3], 0.0, (7, 7))
    assert mean_psnr(lf[inner], out[inner]) > mean_psnr(lf[inner], flat[inner]) + 5


def test_occlusion_handling_helps_at_edges():
    clip = synth_clip(1, 7, (96, 128), seed=3, layers=4, motion=0, camera_pan=0, disparity_range=(-1.5, 2.0))
    lf, d = clip.lf[0], clip.disparity[0, 3, 3]
    with_occ = warp_views(lf[3, 3], d, (7, 7), occlusion=True)
    without = warp_views(lf[3, 3], d, (7, 7), occlusion=False)
    assert mean_psnr(lf, with_occ) >= mean_psnr(lf, without) - 0.05
    assert mssim(lf, with_occ) >= mssim(lf, without) - 1e-3


def test_torch_warp_matches_kernel_without_occlusion(rng, device):
    centre = rng.random((16, 20, 3)).astype(np.float32)
    d = (rng.random((16, 20)) * 0.6 - 0.3).astype(np.float32)
    ref = warp_views(centre, d, (3, 3), occlusion=False).astype(np.float32) / 255
    t = warp_views_torch(torch.from_numpy(centre).permute(2, 0, 1)[None].to(device),
                         torch.from_numpy(d)[None, None].to(device), (3, 3))
    got = t[0].permute(0, 1, 3, 4, 2).cpu().numpy()
    # the kernel quantises the float centre to 8 bits (0.5 level) and its output (0.5
    # level); its fixed-point interpolation adds under 0.1 level
    assert np.abs(got - ref).max() <= 1.1 / 255


def test_depth_hint_accuracy_on_synthetic_truth():
    clip = synth_clip(1, 7, (96, 128), seed=12, motion=0, camera_pan=0, noise=1.0)
    lf, gt = clip.lf[0], clip.disparity[0, 3, 3]
    est = estimate_disparity(lf)
    err = disparity_errors(est, gt)
    flat = disparity_errors(np.zeros_like(gt), gt)
    assert err["mse_x100"] < 0.5 * flat["mse_x100"] and err["badpix_007"] < flat["badpix_007"]
    data = encode_hint(est)
    back = decode_hint(data, gt.shape, guide=lf[3, 3])
    assert disparity_errors(back, gt)["mse_x100"] < 1.5 * err["mse_x100"] + 1.0
    assert len(data) < gt.size / 8  # well under a bit per pixel


def test_hint_improves_reconstruction_over_flat():
    clip = synth_clip(1, 7, (96, 128), seed=4, motion=0, camera_pan=0)
    lf = clip.lf[0]
    flat = lfstream.decode(lfstream.encode(lf, quality=90), depth="flat")[0]
    hint = lfstream.decode(lfstream.encode(lf, quality=90, depth_hint=True), depth="hint")[0]
    assert mean_psnr(lf, hint) > mean_psnr(lf, flat) + 1.0
    assert mssim(lf, hint) > mssim(lf, flat)


def test_api_errors():
    lf = synth_clip(1, 3, (16, 16), seed=0).lf[0]
    with pytest.raises(LFValueError):
        lfstream.encode(lf, quality=0)
    with pytest.raises(LFStreamError):
        lfstream.encode(np.zeros((3, 3), np.uint8))
    bad = lf.astype(np.float32) / 255
    bad[0, 0, 0, 0, 0] = np.inf
    with pytest.raises(LFValueError, match="NaN or Inf"):
        lfstream.encode(bad)
    data = lfstream.encode(lf, depth_hint=False)
    with pytest.raises(LFValueError, match="hint"):
        lfstream.decode(data, depth="hint")
    # the seed's path runs on a stream without a hint (the fast Depth-Net from the centre
    # view); the paper preset's Depth-Net ships no weights: one clear error
    assert lfstream.decode(data, depth="net").shape == (1, *lf.shape)
    with pytest.raises(LFStreamError, match="no trained weights"):
        lfstream.decode(data, depth="net", preset="paper")
    with pytest.raises(LFValueError):
        lfstream.decode(data, depth="magic")


def test_cli_decodes_to_a_video_frame_by_frame_at_the_streams_rate(tmp_path, capsys):
    """``decode -o clip.mp4`` writes each frame as it is decoded (the frames equal the
    ``.npy`` output's), at the stream's frame rate (the video was 30 fps whatever the
    stream said); a truncated stream leaves a complete, playable video of the frames
    before the damage."""
    from lfstream.io import load_lf

    src = tmp_path / "clip.npz"
    lfstream.write_lf(src, synth_clip(3, 5, (32, 40), seed=1).lf)
    assert main(["encode", str(src), "-o", str(tmp_path / "a.lfs"), "--fps", "24"]) == 0
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "a.npy")]) == 0
    capsys.readouterr()
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "a.mp4"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 3
    video = load_lf(tmp_path / "a.mp4")
    assert video.fps == pytest.approx(24)
    np.testing.assert_array_equal(video.lf, np.load(tmp_path / "a.npy"))
    data = (tmp_path / "a.lfs").read_bytes()
    (tmp_path / "cut.lfs").write_bytes(data[: len(data) - 100])
    assert main(["decode", str(tmp_path / "cut.lfs"), "-o", str(tmp_path / "cut.mp4")]) == 2
    assert "frame 2" in capsys.readouterr().err
    np.testing.assert_array_equal(load_lf(tmp_path / "cut.mp4").lf, video.lf[:2])
    # a .npz takes the frames together (decoded into one array): the same frames, and the
    # complete frames of a damaged stream
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "a.npz")]) == 0
    np.testing.assert_array_equal(load_lf(tmp_path / "a.npz").lf, video.lf)
    assert main(["decode", str(tmp_path / "cut.lfs"), "-o", str(tmp_path / "cut.npz")]) == 2
    np.testing.assert_array_equal(load_lf(tmp_path / "cut.npz").lf, video.lf[:2])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_cli_encode_decode_and_damaged_stream(tmp_path, capsys):
    src = tmp_path / "clip.npz"
    lfstream.write_lf(src, synth_clip(3, 5, (32, 40), seed=1).lf)
    assert main(["encode", str(src), "-o", str(tmp_path / "a.lfs"), "--quality", "70", "--json"]) == 0
    enc = json.loads(capsys.readouterr().out)
    assert {"bytes", "bpp", "encode_s"} <= set(enc) and enc["frames"] == 3
    assert enc["bpp"] == pytest.approx(8 * enc["bytes"] / (3 * 25 * 32 * 40))
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "a.npy"), "--json",
                 "--disparity-out", str(tmp_path / "disp")]) == 0
    dec = json.loads(capsys.readouterr().out)
    assert dec["frames"] == 3 and "decode_s" in dec
    out = np.load(tmp_path / "a.npy")
    assert out.shape == (3, 5, 5, 32, 40, 3) and out.dtype == np.uint8
    assert sorted(p.name for p in (tmp_path / "disp").iterdir()) == [f"frame_{k:06d}.pfm" for k in range(3)]
    # the same input and flags give the same bitstream
    assert main(["encode", str(src), "-o", str(tmp_path / "b.lfs"), "--quality", "70"]) == 0
    assert (tmp_path / "a.lfs").read_bytes() == (tmp_path / "b.lfs").read_bytes()
    # a truncated stream: one-line error, and the complete frames are written
    data = (tmp_path / "a.lfs").read_bytes()
    (tmp_path / "cut.lfs").write_bytes(data[: len(data) - 100])
    capsys.readouterr()
    assert main(["decode", str(tmp_path / "cut.lfs"), "-o", str(tmp_path / "cut.npy")]) == 2
    err = capsys.readouterr().err
    assert "frame 2" in err and len(err.strip().splitlines()) == 1
    assert np.load(tmp_path / "cut.npy").shape[0] == 2
    # info reads .lfs too
    assert main(["info", str(tmp_path / "a.lfs"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 3


def test_gains_gains_fix_vignetted_views():
    from lfstream.codec.gains import decode_gains, encode_gains, measure_gains, shading_present

    vig = synth_clip(1, 5, (64, 96), seed=8, vignetting=0.6, motion=0, camera_pan=0).lf[0]
    clean = synth_clip(1, 5, (64, 96), seed=8, motion=0, camera_pan=0).lf[0]
    g = measure_gains(vig)
    assert shading_present(g) and not shading_present(measure_gains(clean))
    back = decode_gains(encode_gains(g), (5, 5))
    assert np.abs(np.log2(back) - np.log2(np.clip(g, 0.25, 3.9))).max() <= 1 / 128 + 1e-6
    # the fast preset named: without gains the default's check of its own prediction would
    # (rightly) code these views instead of warping them
    with_gain = lfstream.decode(lfstream.encode(vig, quality=90, preset="fast"))[0]
    without = lfstream.decode(lfstream.encode(vig, quality=90, gain_grid=0, preset="fast"))[0]
    assert mean_psnr(vig, with_gain) > mean_psnr(vig, without) + 2
    # a clean light field sends no gain maps
    from lfstream.codec.bitstream import split_stream

    assert all(p.gain == b"" for p in split_stream(lfstream.encode(clean))[1])
    assert all(p.gain != b"" for p in split_stream(lfstream.encode(vig))[1])


def test_baselines_round_trip_and_rate_search():
    import av

    from lfstream.codec.baseline import ENCODER_MIN_SIDE, coded_size, decode_views, encode_at_bpp, encode_views, view_order

    assert view_order(3, 3, "spiral")[0] == (1, 1) and sorted(view_order(3, 3, "spiral")) == view_order(3, 3)
    assert view_order(2, 3, "serpentine") == [(0, 0), (0, 1), (0, 2), (1, 2), (1, 1), (1, 0)]
    # small views are coded padded to one CTU / superblock (the encoders' small-frame paths are
    # unsafe), odd ones to even size; decoding crops back
    assert coded_size((33, 47)) == (ENCODER_MIN_SIDE, ENCODER_MIN_SIDE) and coded_size((375, 541)) == (376, 542)
    lf = synth_clip(1, 3, (33, 47), seed=2).lf[0]
    with av.open(io.BytesIO(encode_views(lf, "hevc", 30, constant_qp=False)), format="hevc") as container:
        assert (container.streams.video[0].height, container.streams.video[0].width) == (64, 64)
    for codec in ("hevc", "av1"):
        fine = decode_views(encode_views(lf, codec, 12, "spiral"), codec, (3, 3), (33, 47), "spiral")
        coarse = decode_views(encode_views(lf, codec, 51 if codec == "hevc" else 63, "spiral"), codec, (3, 3),
                              (33, 47), "spiral")
        # these synthetic textures carry saturated colour detail that the 4:2:0 conversion
        # alone caps near 24.5 dB (measured: RGB -> yuv420p -> RGB without coding)
        assert fine.shape == lf.shape and mpsnr(lf, fine) > 23 and mpsnr(lf, fine) > mpsnr(lf, coarse) + 2
    for size in ((33, 47), (64, 96)):
        lf = synth_clip(1, 3, size, seed=2).lf[0]
        target = 8 * len(encode_views(lf, "hevc", 30)) / (9 * size[0] * size[1])
        res = encode_at_bpp(lf, "hevc", target)
        # x265's fractional CRF at every size, within the default 2 % tolerance
        assert not res.constant_qp and abs(res.bpp - target) <= 0.02 * target
    with pytest.raises(LFValueError):
        view_order(3, 3, "zigzag")


def test_the_centre_coding_beside_the_hint_gives_the_serial_bytes_and_errors(monkeypatch):
    """With the hint, the centre view is coded on a worker thread beside the sweep: the
    packets are those of the same work done in turn (frame by frame, the post-filter
    choice's state included), and what the centre coding raises reaches the caller."""
    import lfstream.codec.encoder as encoder_module
    from lfstream.codec import Encoder

    clip = synth_clip(4, 5, (48, 64), seed=3, noise=2.0, motion=0.5)
    overlapped = Encoder(hint_options=HintOptions(key_interval=2))
    serial = Encoder(hint_options=HintOptions(key_interval=2))
    for t, frame in enumerate(clip.lf):
        got = overlapped.encode_frame(frame, t, t)
        image = serial._code_centre(frame[2, 2])
        assert got.image == image and got.hint == serial._hints.encode(frame, t)

    def broken(*args, **kwargs):
        raise LFValueError("centre coding failed")

    monkeypatch.setattr(encoder_module, "encode_centre", broken)
    with pytest.raises(LFValueError, match="centre coding failed"):
        Encoder().encode_frame(clip.lf[0], 0, 0)


def test_encode_star_light_field_with_missing_views():
    """An HCI "star" (33 of 81 views): the codec needs only the centre view (the hint uses
    the views present) and the decoder reconstructs all 81; with the hint the present
    views come back better than with flat disparity."""
    from tests.conftest import shared

    lf, present = lfstream.read_lf(shared("hci_star", "cotton"), return_mask=True)
    lf, present = lf[:, :, 128:320, 128:384], present
    flat = lfstream.decode(lfstream.encode(lf, present=present, depth_hint=False))[0]
    hint = lfstream.decode(lfstream.encode(lf, present=present))[0]  # the hint is the default
    assert hint.shape == (9, 9, 192, 256, 3)
    idx = [(u, v) for u, v in zip(*np.nonzero(present)) if (u, v) != (4, 4)]
    p_flat = np.mean([psnr(lf[u, v], flat[u, v]) for u, v in idx])
    p_hint = np.mean([psnr(lf[u, v], hint[u, v]) for u, v in idx])
    assert p_hint > p_flat + 2
    no_centre = present.copy()
    no_centre[4, 4] = False
    with pytest.raises(LFValueError, match="centre view is missing"):
        lfstream.encode(lf, present=no_centre)


def test_hance_auto_on_cpu_leaves_the_fast_network_off_and_on_filters_first(monkeypatch):
    """``hance="auto"`` runs JPEG-Hance (fast or paper) only on a GPU (on CPU it costs more
    than the rest of the decode); ``"on"`` feeds it the centre view post-filtered as it was trained,
    with the filter the stream names (here the wider one, not the default)."""
    from dataclasses import replace

    from lfstream.codec import Decoder
    from lfstream.codec.bitstream import iter_packets, read_header
    from lfstream.codec.centre.jpeg import PostFilterChoice, decode_jpeg, post_filter_jpeg, with_post_filter

    clip = synth_clip(1, 3, (64, 80), seed=4, motion=0)
    data = lfstream.encode(clip.lf, depth_hint=False)
    header = read_header(io.BytesIO(data))
    assert header.quality <= 60 and not Decoder(header, hance="auto").uses_hance
    assert not Decoder(header, hance="auto", preset="paper").uses_hance  # 0.6 s a view on the CPU
    assert Decoder(header, hance="on", preset="paper").uses_hance
    fh = io.BytesIO(data)
    read_header(fh)
    packet = next(iter_packets(fh, header))
    packet = replace(packet, image=with_post_filter(packet.image, PostFilterChoice(2)))
    seen = []
    import lfstream.models.jpeg_hance as jh

    real = jh.restore_images
    monkeypatch.setattr(jh, "restore_images", lambda images, model, device="cpu", precision="auto": seen.append(images.copy())
                        or real(images, model, device))
    Decoder(header, hance="on", deblock=False).decode_centres([packet])
    raw = decode_jpeg(packet.image, header.size)
    assert (seen[0] == post_filter_jpeg(raw, packet.image)).all()
    assert not (seen[0] == post_filter_jpeg(raw, with_post_filter(packet.image, PostFilterChoice()))).all()
    assert (Decoder(header, hance="off").decode_centres([packet])[0] == post_filter_jpeg(raw, packet.image)).all()


def test_depth_net_frames_keep_their_own_disparity_though_the_maps_array_is_reused():
    """The decoder reuses one array for Depth-Net's per-view maps from batch to batch; each
    frame's disparity (the centre's map) is its own: frames kept from an iterator equal
    copies taken as they came, and differ between frames of a moving scene. view_disparities
    writes into a given array and refuses one it cannot write (the warp's check of its `out`)."""
    import io

    from lfstream.codec.api import iter_decode
    from lfstream.codec.warp.cpu import view_disparities

    clip = synth_clip(3, 5, (48, 64), seed=12, motion=0.8, camera_pan=0.3)
    data = lfstream.encode(clip.lf, depth_hint=True)
    kept, copies = [], []
    for f in iter_decode(io.BytesIO(data), depth="net", hance="off"):
        kept.append(f)
        copies.append((f.disparity.copy(), f.lf.copy()))
    for f, (d, lf) in zip(kept, copies):
        assert np.array_equal(f.disparity, d) and np.array_equal(f.lf, lf)
    assert not np.array_equal(copies[0][0], copies[-1][0])
    d = kept[0].disparity
    buf = np.full((5, 5, *d.shape), np.nan, np.float32)
    assert view_disparities(d, (5, 5), out=buf) is buf and np.array_equal(buf, view_disparities(d, (5, 5)))
    with pytest.raises(LFValueError, match="out: a writeable C-contiguous float32 array"):
        view_disparities(d, (5, 5), out=buf[:, :, :, ::2])


def test_decode_with_networks_and_switches(tmp_path):
    clip = synth_clip(2, 5, (48, 64), seed=8, motion=0.5)
    data = lfstream.encode(clip.lf, depth_hint=True)
    net = lfstream.decode(data, depth="net", hance="on")
    hint = lfstream.decode(data, depth="hint", hance="off")
    assert net.shape == hint.shape == clip.lf.shape and net.dtype == np.uint8
    # deterministic, and the centre view of the net path is the (restored) centre view
    assert (lfstream.decode(data, depth="net", hance="on") == net).all()
    flat = lfstream.decode(data, depth="flat", hance="off")
    assert np.mean(mpsnr(clip.lf[0], net[0])) > np.mean(mpsnr(clip.lf[0], flat[0]))
    with pytest.raises(LFValueError, match="no CUDA|cpu or cuda|'cpu' or 'cuda'") if not torch.cuda.is_available() else \
            pytest.raises(LFValueError, match="'cpu' or 'cuda'"):
        lfstream.decode(data, device="cuda" if not torch.cuda.is_available() else "tpu")
    with pytest.raises(LFValueError, match="depth hint"):  # the hint asked of a stream without one
        lfstream.decode(lfstream.encode(clip.lf, depth_hint=False), depth="hint")
    src = tmp_path / "c.lfs"
    src.write_bytes(data)
    out = tmp_path / "out.npy"
    assert main(["decode", str(src), "-o", str(out), "--depth", "net", "--hance", "off", "--batch", "2", "--json"]) == 0
    dec = np.load(out)
    # batched network inference may differ in the last float bit, so by at most one level
    assert np.abs(dec.astype(int) - lfstream.decode(data, depth="net", hance="off")).max() <= 1


def test_decode_of_one_frame_is_the_decoded_frame_without_a_copy():
    from lfstream.codec.api import iter_decode, stack_frames

    clip = synth_clip(2, 3, (24, 32), seed=5).lf
    one = lfstream.encode(clip[0])
    out = lfstream.decode(one)
    frame = next(iter_decode(io.BytesIO(one))).lf
    assert out.shape == (1, *frame.shape) and out.flags.c_contiguous
    np.testing.assert_array_equal(out[0], frame)
    frames = [frame, frame + 1]
    assert np.shares_memory(stack_frames(frames[:1]), frames[0])
    both = stack_frames(frames)
    assert both.shape == (2, *frame.shape) and not np.shares_memory(both, frames[0])
    two = lfstream.decode(lfstream.encode(clip))
    assert two.shape == (2, *frame.shape)
    np.testing.assert_array_equal(two[0], frame)


def test_an_lfs_file_reads_as_the_light_field_it_decodes_to(tmp_path):
    """``load_lf`` of an ``.lfs`` (what ``refocus``, ``stream`` and ``view`` read) is the
    stream decoded as ``lfstream.decode`` decodes it, parallax included: it was the centre
    view copied to every view (flat disparity), so refocusing an encoded file only blurred
    its centre view."""
    from lfstream.io import load_lf

    clip = synth_clip(2, 5, (32, 40), seed=1).lf
    data = lfstream.encode(clip, fps=12)
    (tmp_path / "a.lfs").write_bytes(data)
    loaded = load_lf(tmp_path / "a.lfs")
    assert loaded.format == "lfs" and loaded.fps == pytest.approx(12)
    np.testing.assert_array_equal(loaded.lf, lfstream.decode(data))
    assert not (loaded.lf[:, 0, 0] == loaded.lf[:, 2, 2]).all()


@pytest.mark.parametrize("options", [{}, {"residual": 40}, {"preset": "balanced", "residual": 40, "residual_mode": "views"}])
def test_decoding_from_a_later_frame_gives_that_frames_bytes(options, tmp_path, capsys):
    """``first_frame`` (``lfstream.decode``, ``decode --first-frame``, an ``.lfs`` read with
    ``ReadOptions.first_frame``): the packets before it are only followed (their hint and
    gain deltas read), and the frames decoded are byte for byte a whole decode's, for a
    clip whose hints and gains are deltas (key interval 3: ranges start before, at and
    after a key frame); ``max_frames`` counts from it; a start past the end is one line."""
    from lfstream.io import ReadOptions, load_lf

    clip = synth_clip(7, 3, (48, 64), seed=3, noise=2.0, vignetting=0.3, motion=1.0, camera_pan=0.5).lf
    data = lfstream.encode(clip, hint_options=HintOptions(key_interval=3), **options)
    whole = lfstream.decode(data)
    for first in (1, 3, 4, 6):
        np.testing.assert_array_equal(lfstream.decode(data, first_frame=first), whole[first:])
    np.testing.assert_array_equal(lfstream.decode(data, first_frame=2, max_frames=2), whole[2:4])
    with pytest.raises(LFValueError, match="first_frame 7: it holds 7 frame"):
        lfstream.decode(data, first_frame=7)
    (tmp_path / "a.lfs").write_bytes(data)
    np.testing.assert_array_equal(load_lf(tmp_path / "a.lfs", ReadOptions(first_frame=5)).lf, whole[5:])
    if options:
        return
    capsys.readouterr()
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "part.npy"), "--first-frame", "4",
                 "--max-frames", "2", "--json", "--disparity-out", str(tmp_path / "disp")]) == 0
    assert json.loads(capsys.readouterr().out) | {"decode_s": 0} == {
        "frames": 2, "first_frame": 4, "decode_s": 0, "output": str(tmp_path / "part.npy"), "missing_views": [],
        "synthesized_views": []}
    np.testing.assert_array_equal(np.load(tmp_path / "part.npy"), whole[4:6])
    # the maps keep the stream's frame numbers
    assert sorted(p.name for p in (tmp_path / "disp").iterdir()) == ["frame_000004.pfm", "frame_000005.pfm"]
    assert main(["decode", str(tmp_path / "a.lfs"), "-o", str(tmp_path / "late.mp4"), "--first-frame", "9"]) == 2
    err = capsys.readouterr().err
    assert "first_frame 9: it holds 7 frame(s)" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "late.mp4").exists()


def test_an_lfs_cut_short_reads_as_its_frames_before_the_damage(tmp_path, capsys):
    """A stream cut short (a recording interrupted) is read lazily up to the damage, as a
    damaged video is: ``convert`` writes the complete frames before it (exit 2, one line
    naming the frame), ``info`` names the damage and the complete frames; a stream damaged
    before its first complete frame is refused before anything is decoded."""
    from lfstream.errors import BitstreamError
    from lfstream.io import open_video_lf

    clip = synth_clip(4, 3, (32, 40), seed=1).lf
    data = lfstream.encode(clip)
    (tmp_path / "cut.lfs").write_bytes(data[:-100])
    video = open_video_lf(tmp_path / "cut.lfs")
    assert video.count == 3 and isinstance(video.damage, BitstreamError) and "frame 3" in str(video.damage)
    capsys.readouterr()
    assert main(["convert", str(tmp_path / "cut.lfs"), str(tmp_path / "cut.avi")]) == 2
    err = capsys.readouterr().err
    assert "frame 3" in err and "3 complete frame(s) before it written" in err and len(err.strip().splitlines()) == 1
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / "cut.avi"), lfstream.decode(data)[:3])
    assert main(["info", str(tmp_path / "cut.lfs")]) == 2
    err = capsys.readouterr().err
    assert "frame 3" in err and "3 complete frame(s) before it" in err
    (tmp_path / "first.lfs").write_bytes(data[:60])
    with pytest.raises(BitstreamError, match="first.lfs"):
        open_video_lf(tmp_path / "first.lfs")
