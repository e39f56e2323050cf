"""The command line, called through main(argv) as users' scripts would."""

import json

import numpy as np
import pytest

from lfstream.cli import build_parser, main
from lfstream.synth import synth_clip
from tests.conftest import random_lf, shared


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


def test_help_lists_every_command(capsys):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    names = set(sub.choices)
    assert {"info", "refocus", "synth", "demo"} <= names
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for name in names:
        assert name in text
        with pytest.raises(SystemExit) as e:
            main([name, "--help"])
        assert e.value.code == 0
        assert "usage: lfstream " + name in capsys.readouterr().out


def test_info_json_on_seahorse(capsys):
    code, out, _ = run(capsys, "info", shared("seahorse5x5", "camImagesFlat"), "--json")
    assert code == 0
    info = json.loads(out)
    assert info["format"] == "sai-folder" and info["frames"] == 1
    assert info["views"] == [5, 5] and info["size"] == [500, 500]
    assert info["dtype"] == "uint8" and info["bytes"] == 25 * 500 * 500 * 3


def test_info_hci_missing_views_is_one_line_error(capsys):
    code, out, err = run(capsys, "info", shared("hci_star", "cotton"))
    assert code != 0 and out == ""
    assert len(err.strip().splitlines()) == 1 and "missing" in err and "cotton" in err
    code, out, _ = run(capsys, "info", shared("hci_star", "cotton"), "--allow-missing", "--json")
    assert code == 0 and len(json.loads(out)["missing_views"]) == 48


@pytest.mark.parametrize("bad", ["nonexistent.npy", "."])
def test_bad_input_one_line(capsys, tmp_path, bad):
    path = tmp_path / bad if bad != "." else tmp_path
    code, _, err = run(capsys, "info", path)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_float_light_field_in_8_bit_units_is_refused_in_one_line(capsys, tmp_path):
    """A float light field with values 0..255 (uint8 data converted without scaling) would
    code as a white frame: encode refuses it, naming the frame and the range, and writes
    nothing; the same data in [0, 1] encodes."""
    from lfstream.synth import synth_clip

    lf = synth_clip(1, 3, (32, 40), seed=1).lf[0]
    path = tmp_path / "lf255.npy"
    np.save(path, lf.astype(np.float32))
    out = tmp_path / "out.lfs"
    code, _, err = run(capsys, "encode", path, "-o", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "frame 0" in err and "float values span 0 .. 2" in err and "divide by 255" in err and not out.exists()
    np.save(path, lf.astype(np.float32) / 255.0)
    assert run(capsys, "encode", path, "-o", out)[0] == 0 and out.exists()


def test_refocus_reorders_a_grid_whose_rows_of_views_run_the_other_way(capsys, tmp_path):
    """A light field stored with its rows of views reversed: `refocus` detects the view axes
    and renders the focal stack of the grid in the convention's order (the planes equal the
    unflipped input's), and says so; `--axes standard` renders the order as stored."""
    from lfstream.io import read_image
    from lfstream.metrics import psnr
    from lfstream.synth import synth_clip

    lf = synth_clip(1, 7, (192, 256), seed=0).lf[0]
    own, flipped = tmp_path / "own.npy", tmp_path / "flipped.npy"
    np.save(own, lf)
    np.save(flipped, np.ascontiguousarray(lf[::-1]))
    planes = {}
    for name, path, extra in (("own", own, ()), ("auto", flipped, ()), ("stored", flipped, ("--axes", "standard"))):
        out = tmp_path / name
        code, text, _ = run(capsys, "refocus", path, "-o", out, "--slopes=-1,0.5", "--no-sweep", "--no-viewer",
                            "--json", *extra)
        assert code == 0
        summary = json.loads(text)
        assert (summary["view_axes"] is None) == (name != "auto")
        planes[name] = np.stack([read_image(out / f"plane_0{k}.png") for k in range(2)])
    assert summary is not None and float(np.mean(psnr(planes["own"], planes["auto"]))) > 45.0
    assert float(np.mean(psnr(planes["own"], planes["stored"]))) < 35.0


def test_info_of_a_stream_reports_the_view_axes_its_hint_carries(capsys, tmp_path):
    import lfstream
    from lfstream.synth import synth_clip

    lf = synth_clip(1, 7, (256, 256), seed=0).lf[0]
    for name, grid, flipped in (("own", lf, False), ("flipped", np.ascontiguousarray(lf[::-1]), True)):
        path = tmp_path / f"{name}.lfs"
        path.write_bytes(lfstream.encode(grid))
        code, out, _ = run(capsys, "info", path, "--json")
        axes = json.loads(out)["stream"]["view_axes"]
        assert code == 0 and (axes is None) != flipped
        if flipped:  # measured [[-1.027, 0.013], [-0.021, 1]]
            assert np.abs(np.array(axes) - np.diag([-1.0, 1.0])).max() < 0.06
            assert "axes    the views move along" in run(capsys, "info", path)[1]


def test_synth_then_info_then_refocus(capsys, tmp_path):
    clip = tmp_path / "clip.npz"
    code, _, _ = run(capsys, "synth", clip, "--frames", 2, "--views", 5, "--size", "32x40", "--seed", 3)
    assert code == 0
    code, out, _ = run(capsys, "info", clip, "--json")
    info = json.loads(out)
    assert info["frames"] == 2 and info["views"] == [5, 5] and info["size"] == [32, 40] and info["has_disparity"]
    out_dir = tmp_path / "stack"
    code, out, _ = run(capsys, "refocus", clip, "-o", out_dir, "--alphas", "0.8,1,1.25", "--json")
    assert code == 0
    summary = json.loads(out)
    assert summary["frames"] == 2 and [p["alpha"] for p in summary["planes"]] == pytest.approx([0.8, 1.0, 1.25])
    assert sorted(p.name for p in (out_dir / "frame_000001").iterdir()) == ["plane_00.png", "plane_01.png", "plane_02.png"]
    assert (out_dir / "plane_02.mp4").stat().st_size > 0
    # refusing to write into a non-empty folder keeps what is there
    code, _, err = run(capsys, "refocus", clip, "-o", out_dir)
    assert code == 2 and "already exists" in err
    # synth never overwrites
    code, _, err = run(capsys, "synth", clip)
    assert code == 2 and "exists" in err


def test_refocus_single_frame_writes_sweeps(capsys, tmp_path, rng):
    from lfstream import write_lf

    lf = random_lf(rng, (3, 3, 24, 30, 3))
    write_lf(tmp_path / "lf.npy", lf)
    code, _, _ = run(capsys, "refocus", tmp_path / "lf.npy", "-o", tmp_path / "o", "--slope-range", "-1", "1", "5",
                     "--method", "fourier")
    assert code == 0
    names = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert names == ["disparity.json", "index.html"] + [f"plane_{k:02d}.png" for k in range(5)] + \
        ["planes.json", "sweep.gif", "sweep.mp4", "viewer"]  # the planes, sweeps and the click-to-focus page
    assert [p["slope"] for p in json.loads((tmp_path / "o" / "planes.json").read_text())["planes"]] == \
        pytest.approx([-1, -0.5, 0, 0.5, 1])
    from lfstream.io import iter_video_frames

    assert len(list(iter_video_frames(tmp_path / "o" / "sweep.mp4"))) == 5


def test_refocus_default_planes_are_the_streams_auto_and_seed_is_kept(capsys, tmp_path, rng):
    """``refocus`` takes the stream's focal-plane default, ``--alphas auto`` (planes fitted to
    the scene's disparity), and ``--alphas seed`` gives the seed's sixteen alphas."""
    from lfstream import write_lf
    from lfstream.optics import SEED_ALPHAS, slope_from_alpha

    write_lf(tmp_path / "lf.npy", random_lf(rng, (3, 3, 16, 20, 3)))
    slopes = {}
    for name, extra in (("seed", ["--alphas", "seed"]), ("auto", ["--alphas", "auto"]), ("default", [])):
        code, _, _ = run(capsys, "refocus", tmp_path / "lf.npy", "-o", tmp_path / name, "--no-viewer", *extra)
        assert code == 0
        slopes[name] = [p["slope"] for p in json.loads((tmp_path / name / "planes.json").read_text())["planes"]]
    assert slopes["seed"] == pytest.approx([slope_from_alpha(a) for a in SEED_ALPHAS], abs=1e-5)
    assert slopes["default"] == slopes["auto"] != slopes["seed"]
    assert 4 <= len(slopes["auto"]) <= 16 and slopes["auto"] == sorted(slopes["auto"])


def test_demo_runs_and_never_overwrites(capsys, tmp_path):
    out = tmp_path / "demo"
    code, out_text, _ = run(capsys, "demo", "-o", out, "--size", "48x64", "--json")
    assert code == 0
    first = json.loads(out_text)
    assert first["lightfield"]["views"] == [7, 7] and (out / "focal_sweep.mp4").exists()
    assert min(p for p in first["fourier_vs_sas_psnr_db"] if p is not None) > 25
    code, out_text, _ = run(capsys, "demo", "-o", out, "--size", "48x64", "--json")
    assert json.loads(out_text)["output"] == str(tmp_path / "demo-2")


@pytest.mark.parametrize("argv, flag", [
    (["encode", "x.npy", "-o", "y.lfs", "--quality", "0"], "--quality"),
    (["encode", "x.npy", "-o", "y.lfs", "--quality", "101"], "--quality"),
    (["stream", "--quality", "200"], "--quality"),
    (["stream", "--batch", "0"], "--batch"),
    (["decode", "x.lfs", "-o", "y.npy", "--batch", "999"], "--batch"),
    (["serve", "--port", "99999"], "--port"),
    (["info", "x.npy", "--views", "0"], "--views"),
])
def test_numeric_options_are_range_checked_by_the_parser(capsys, argv, flag):
    """Ranges come from the library's constants (QUALITY_RANGE, BATCH_RANGE, ...)."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert flag in err and "Traceback" not in err


def test_baseline_qp_outside_the_codecs_range_is_one_line(capsys, tmp_path, rng):
    np.save(tmp_path / "lf.npy", random_lf(rng, (3, 3, 16, 16, 3)))
    code, out, err = run(capsys, "baseline", tmp_path / "lf.npy", "--codec", "hevc", "--qp", "55")
    assert code == 2 and "--qp" in err and "0..51" in err and len(err.strip().splitlines()) == 1


def test_usage_errors_are_one_line_without_the_usage_block(capsys):
    with pytest.raises(SystemExit) as e:
        main(["refocus", "x", "-o", "y", "--method", "nope"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and len(err.strip().splitlines()) == 1
    assert "usage:" not in err and "--help" in err


def test_demo_json_is_strict_and_lands_in_its_own_folder(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, _ = run(capsys, "demo", "--size", "32x48", "--json")
    assert code == 0
    result = json.loads(out, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert result["output"] == "lfstream-demo"  # its own default folder, not a stream's
    assert (tmp_path / "lfstream-demo" / "focal_sweep.mp4").exists()
    # the planes that equal the input exactly have infinite PSNR: null, with the reason beside it
    psnrs = result["fourier_vs_sas_psnr_db"]
    assert all(p is None or np.isfinite(p) for p in psnrs)
    if None in psnrs:
        assert "infinite" in result["fourier_vs_sas_psnr_db_note"]
    code, out, _ = run(capsys, "demo", "--size", "32x48", "--json")
    assert json.loads(out)["output"] == "lfstream-demo-2"  # never overwritten


def test_bad_files_say_what_is_wrong(capsys, tmp_path):
    (tmp_path / "text.npy").write_text("hello")
    code, _, err = run(capsys, "info", tmp_path / "text.npy")
    assert code == 2 and "not a NumPy .npy file" in err and "pickle" not in err
    (tmp_path / "empty.lfs").write_bytes(b"")
    code, _, err = run(capsys, "decode", tmp_path / "empty.lfs", "-o", tmp_path / "out.npy")
    assert code == 2 and "truncated" in err and "nothing written" in err
    assert not (tmp_path / "out.npy").exists()


def test_stream_output_with_an_extension_is_refused(capsys, tmp_path):
    code, _, err = run(capsys, "stream", "-o", tmp_path / "out.xyz")
    assert code == 2 and "-o" in err and ".xyz" in err
    assert not (tmp_path / "out.xyz").exists()


def test_stream_refusing_its_input_leaves_no_output_folder(capsys, tmp_path, monkeypatch):
    """An input refused before the pipeline runs removes the folder that run made (empty);
    a folder the user named and made stays."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "nothing").mkdir()
    code, _, err = run(capsys, "stream", "nothing")
    assert code == 2 and "empty folder" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "lfstream-out").exists()
    (tmp_path / "mine").mkdir()
    code, _, err = run(capsys, "stream", "nothing", "-o", "mine")
    assert code == 2 and (tmp_path / "mine").is_dir()
    # options refused together (checked once the input is known) leave no folder either
    for options in (["--bpp", "0.02", "--residual", "40"], ["--hance-map", "--preset", "best"]):
        code, _, err = run(capsys, "stream", "--frames", "1", "-o", "refused", *options)
        assert code == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "refused").exists(), options


def test_baseline_metrics_count_present_views_only(capsys, tmp_path):
    """A folder with missing views: the zero-filled stand-ins code perfectly (56 dB measured
    before) and must not count; the score is the one over the views that exist."""
    from lfstream.io import read_lf

    star = shared("hci_star", "cotton")
    if not star.exists():
        pytest.skip("HCI sample not present")
    code, out, _ = run(capsys, "baseline", star, "--allow-missing", "--views", "5", "--codec", "hevc", "--qp", "30",
                       "--json")
    assert code == 0
    result = json.loads(out)
    from lfstream.codec.baseline import decode_views, encode_views
    from lfstream.metrics import psnr

    lf, present = read_lf(star, crop=5, return_mask=True)
    rec = decode_views(encode_views(lf, "hevc", 30), "hevc", (5, 5), lf.shape[2:4])
    per_view = psnr(lf, rec)
    assert result["views_measured"] == int(present.sum()) < 25
    assert result["mpsnr"][0] == pytest.approx(float(per_view[present].mean()), abs=1e-6)
    assert float(np.minimum(per_view, 100).mean()) > result["mpsnr"][0] + 3  # what counting all views gave


def test_ctrl_c_during_stream_exits_130_with_finalised_outputs(tmp_path):
    """SIGINT mid-stream: exit status 130 within seconds, no abort, summary.json says
    interrupted with the frames done, and every plane video is complete and playable."""
    import signal
    import subprocess
    import sys
    import time

    from lfstream.io import iter_video_frames
    from lfstream.synth import synth_clip

    clip = tmp_path / "clip.npy"
    np.save(clip, synth_clip(600, 5, (48, 64), seed=1).lf)  # long enough that SIGINT lands mid-stream
    out = tmp_path / "out"
    cmd = [sys.executable, "-c", "import sys; from lfstream.cli import main; sys.exit(main())",
           "stream", str(clip), "-o", str(out), "--refocus", "sas", "--mssim-every", "0"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline and not any(out.glob(".plane_00.*")):  # the stream is under way
        time.sleep(0.05)
    time.sleep(0.1)
    t0 = time.time()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err[-2000:]
    assert time.time() - t0 < 15
    assert "terminate called" not in err and "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 0 < summary["frames"] < 600
    videos = sorted(out.glob("plane_*.mp4"))
    assert len(videos) == len(summary["planes"]) >= 4 and not list(out.glob(".*"))  # no temporary left behind
    counts = {len(list(iter_video_frames(v))) for v in videos}
    assert counts == {summary["frames"]}  # every plane holds every frame the summary counts


def test_stream_honours_allow_missing(capsys, tmp_path):
    star = shared("hci_star", "cotton")
    if not star.exists():
        pytest.skip("HCI sample not present")
    code, _, err = run(capsys, "stream", star, "-o", tmp_path / "a")
    assert code == 2 and "missing" in err and "--allow-missing" in err
    code, out, _ = run(capsys, "stream", star, "--allow-missing", "--views", "5", "-o", tmp_path / "b", "--json",
                       "--refocus", "sas", "--mssim-every", "0")
    assert code == 0
    summary = json.loads(out)
    import lfstream
    from lfstream.metrics import mpsnr

    lf, present = lfstream.read_lf(star, crop=5, return_mask=True)
    rec = lfstream.decode(lfstream.encode(lf, present=present))[0]
    assert summary["frames"] == 1
    assert summary["mpsnr"] == pytest.approx(float(mpsnr(lf, rec, present=present)), abs=1e-6)


@pytest.mark.parametrize("argv, flag", [
    (["synth", "x.npz", "--vignetting", "2"], "--vignetting"),
    (["synth", "x.npz", "--views", "0"], "--views"),
    (["refocus", "x", "-o", "y", "--aperture", "-1"], "--aperture"),
    (["optics", "--focal-length", "-1", "--f-number", "2", "--microlenses", "5", "--pixels-per-lens", "5"],
     "--focal-length"),
    (["--threads", "0", "info", "x"], "--threads"),
    (["baseline", "x", "--bpp", "0"], "--bpp"),
])
def test_more_numeric_options_are_range_checked(capsys, argv, flag):
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and flag in err and len(err.strip().splitlines()) == 1


def test_progress_is_shown_on_a_terminal_unless_json(monkeypatch):
    import argparse
    import sys

    from lfstream.cli._pipeline import progress_callback

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert progress_callback(argparse.Namespace(progress=False, json=False)) is not None
    assert progress_callback(argparse.Namespace(progress=False, json=True)) is None
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False)
    assert progress_callback(argparse.Namespace(progress=False, json=False)) is None
    assert progress_callback(argparse.Namespace(progress=True, json=False)) is not None


def test_planes_record_their_refocus_distance_when_the_camera_is_given(capsys, tmp_path):
    """The seahorse sample's camera (100 mm, 50 mm aperture = f/2, 500 microlenses, 5 px
    each): every plane records its refocus distance and depth of field, as lfstream
    optics computes them for the same slope."""
    from lfstream.optics import PlenopticCamera, refocus_plane

    sea = shared("seahorse5x5", "camImagesFlat")
    if not sea.exists():
        pytest.skip("seahorse sample not present")
    code, _, err = run(capsys, "stream", sea, "-o", tmp_path / "x", "--focal-length", "100")
    assert code == 2 and "go together" in err
    code, out, _ = run(capsys, "stream", sea, "-o", tmp_path / "s", "--json", "--refocus", "sas", "--mssim-every", "0",
                       "--focal-length", "100", "--f-number", "2", "--microlenses", "500", "--pixels-per-lens", "5")
    assert code == 0
    planes = json.loads(out)["planes"]
    cam = PlenopticCamera(focal_length_mm=100, f_number=2, microlenses=500, pixels_per_lens=5)
    for p in planes:
        ref = refocus_plane(cam, p["slope"])
        assert p["distance_m"] is None or p["distance_m"] == pytest.approx(ref.focus_m, rel=1e-4)
    finite = [p["distance_m"] for p in planes if p["distance_m"] is not None]
    assert len(finite) >= 2 and all(a > b for a, b in zip(finite, finite[1:]))  # nearer planes: shorter distances


def test_stream_runs_opencv_single_threaded_and_restores_it(capsys, tmp_path, monkeypatch):
    import cv2

    from lfstream.stream import pipeline

    seen = []
    original = pipeline.Pipeline.run

    def run_and_record(self):
        seen.append(cv2.getNumThreads())
        return original(self)

    monkeypatch.setattr(pipeline.Pipeline, "run", run_and_record)
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        code, out_text, _ = run(capsys, "stream", "--frames", "1", "--save", "", "-o", tmp_path / "s", "--json")
        assert code == 0 and json.loads(out_text)["frames"] == 1
        assert seen == [1]  # the pipeline's stages are the parallelism (lfstream.cli._pipeline)
        assert cv2.getNumThreads() == 2  # and the process's setting comes back
    finally:
        cv2.setNumThreads(before)


def test_info_on_a_stream_says_what_it_carries(capsys, tmp_path):
    """``lfstream info`` on an .lfs file reports the header's codec, preset, layers and size."""
    import lfstream

    lf = synth_clip(2, 7, (64, 96), seed=2, noise=1.0).lf
    data = lfstream.encode(lf, quality=40)
    (tmp_path / "a.lfs").write_bytes(data)
    assert main(["info", str(tmp_path / "a.lfs"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)["stream"]
    assert s == {"version": 4, "centre_codec": "jpeg", "preset": "fast", "quality": 40, "depth_hint": True,
                 "hint_scale": 4, "view_axes": None, "hance_map": None, "residual": None, "residual_mode": None,
                 "file_bytes": len(data),
                 "bpp": pytest.approx(8 * len(data) / (2 * 7 * 7 * 64 * 96))}
    (tmp_path / "b.lfs").write_bytes(lfstream.encode(lf, quality=40, preset="best", residual=30))
    assert main(["info", str(tmp_path / "b.lfs")]) == 0
    assert "version 4, best (av1 centre) q40 + hint 1/4 + residual q30 (prediction)" in capsys.readouterr().out


def test_the_stream_summary_text_says_what_was_coded():
    from lfstream.cli._pipeline import _text

    summary = {"frames": 1, "fps": 1.0, "bpp": 0.28, "mpsnr": 32.9, "mssim": 0.947, "lost": 0, "stages": {},
               "coding": {"preset": "balanced", "quality": 50, "depth_hint": True, "residual": 50,
                          "residual_mode": "views", "prediction_db": 18.99}}
    text = _text(summary, None)
    assert "coding: balanced q50 + hint + residual q50 (views); the prediction checked at 19.0 dB" in text
    summary["coding"] = {"preset": "fast", "quality": 50, "depth_hint": True, "residual": None, "residual_mode": None,
                         "prediction_db": None}
    assert "coding: fast q50 + hint\n" in _text(summary, None) + "\n"
    summary["coding"]["hint_scale"] = 8  # the hint's resolution, where the summary has it
    assert "coding: fast q50 + hint 1/8\n" in _text(summary, None) + "\n"


def test_the_stream_summary_text_points_to_avi_where_reading_was_the_bottleneck():
    """Where reading a (lossless x264, FFV1, VP9) mosaic video was the slowest stage, the
    text says that an .avi reads faster and how to make one; not where another stage was
    slower, nor for other inputs."""
    from pathlib import Path

    from lfstream.cli._pipeline import _text

    def summary(producer_ms):
        stages = {name: {"frames": 4, "ms_per_frame": ms} for name, ms in
                  (("producer", producer_ms), ("encoder", 25.0), ("decoder", 40.0), ("sink", 30.0))}
        return {"frames": 4, "fps": 4.0, "lost": 0, "stages": stages}

    note = "lfstream convert clip.mp4 clip.avi"
    assert note in _text(summary(300.0), None, Path("clip.mp4"))
    assert note not in _text(summary(20.0), None, Path("clip.mp4"))
    for source in (Path("clip.avi"), Path("clip.npy"), None):
        assert "lfstream convert" not in _text(summary(300.0), None, source)


def test_encode_reads_a_video_frame_by_frame_into_the_streams_bytes(capsys, tmp_path, monkeypatch):
    """``lfstream encode`` of a mosaic video holds one frame at a time (its frames come from
    open_video_lf's iterator, not an array of the video) and writes what lfstream.encode
    makes of the video read whole; --flip-u and --views apply to each frame."""
    import lfstream
    import lfstream.io as lio
    from lfstream.io import ReadOptions, load_lf

    clip = synth_clip(3, 5, (48, 64), seed=4).lf
    lfstream.write_lf(tmp_path / "clip.mp4", clip, fps=24)
    opened = []
    real = lio.open_video_lf

    def spy(path, options=None, **kwargs):
        opened.append(real(path, options, **kwargs))
        return opened[-1]

    monkeypatch.setattr(lio, "open_video_lf", spy)
    code, out, _ = run(capsys, "encode", tmp_path / "clip.mp4", "-o", tmp_path / "a.lfs", "--flip-u", "--views", "3",
                       "--json")
    assert code == 0 and len(opened) == 1 and json.loads(out)["frames"] == 3
    assert next(opened[0].frames, None) is None  # consumed as an iterator
    whole = load_lf(tmp_path / "clip.mp4", ReadOptions(flip_u=True, crop=3)).lf
    assert (tmp_path / "a.lfs").read_bytes() == lfstream.encode(whole, fps=24)


@pytest.mark.parametrize("name", ["clip.mp4", "clip.npy", "clipdir"])
def test_synth_writes_frame_by_frame_what_it_renders(capsys, tmp_path, name):
    """``lfstream synth`` writes a video, a .npy or a folder as each frame is rendered, the
    disparity into a .npy beside it: the same frames and disparity as render_clip."""
    from lfstream import read_lf
    from lfstream.synth import SynthConfig, render_clip

    code, out, _ = run(capsys, "synth", tmp_path / name, "--frames", 3, "--views", 3, "--size", "24x32", "--seed", 5,
                       "--json")
    assert code == 0
    clip = render_clip(SynthConfig(frames=3, views=3, size=(24, 32), seed=5))
    info = json.loads(out)
    assert info["disparity_range"] == pytest.approx([float(clip.disparity.min()), float(clip.disparity.max())])
    np.testing.assert_array_equal(read_lf(tmp_path / name), clip.lf)
    stem = name.split(".")[0]
    np.testing.assert_array_equal(np.load(tmp_path / f"{stem}_disparity.npy"), clip.disparity[..., None])
    assert not [p for p in tmp_path.rglob(".*")]


@pytest.mark.parametrize("extra", [[], ["--views", "3"], ["--max-frames", "2"]])
def test_info_describes_videos_and_streams_without_decoding_them(capsys, tmp_path, monkeypatch, extra):
    """``info`` of a mosaic video or an .lfs stream reads the container or header and counts
    the frames; nothing is decoded, and the answer is what describing the loaded light
    field gives."""
    import lfstream
    import lfstream.codec.api as decoder
    import lfstream.io.readers as readers
    import lfstream.io.video as video
    from lfstream.cli.info import describe
    from lfstream.io import ReadOptions, load_lf

    clip = synth_clip(3, 5, (32, 40), seed=2).lf
    lfstream.write_lf(tmp_path / "clip.mp4", clip, fps=24)
    (tmp_path / "clip.lfs").write_bytes(lfstream.encode(clip, fps=24))
    opts = ReadOptions(crop=3 if "--views" in extra else None, max_frames=2 if "--max-frames" in extra else None)
    want = {name: describe(load_lf(tmp_path / name, opts)) for name in ("clip.mp4", "clip.lfs")}

    def refuse(*a, **k):
        raise AssertionError("decoded")

    for module in (video, readers):
        monkeypatch.setattr(module, "iter_video_frames", refuse)
    monkeypatch.setattr(decoder, "iter_decode", refuse)
    for name in ("clip.mp4", "clip.lfs"):
        code, out, _ = run(capsys, "info", tmp_path / name, "--json", *extra)
        assert code == 0 and json.loads(out) == json.loads(json.dumps(want[name]))


def test_interrupt_after_lets_a_block_finish_before_ctrl_c_takes_effect():
    """Ctrl-C inside ``interrupt_after`` raises KeyboardInterrupt when the block ends, not in
    the middle of it; Python's handler is back afterwards."""
    import os
    import signal

    from lfstream.cli._common import interrupt_after

    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupt_after():
            os.kill(os.getpid(), signal.SIGINT)
            done.append("rest of the block")
    assert done == ["rest of the block"] and signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_refocus_interrupted_keeps_whole_frames_and_their_index(capsys, tmp_path, monkeypatch):
    """Ctrl-C during ``refocus`` of a video: exit 130, and the frames refocused so far are
    complete (every plane's PNG, the plane videos, planes.json, the viewer's disparity)."""
    import lfstream
    import lfstream.refocus as refocus_pkg
    from lfstream.io import iter_video_frames

    lfstream.write_lf(tmp_path / "clip.mp4", synth_clip(5, 5, (32, 40), seed=2).lf, fps=10)
    real, calls = refocus_pkg.focal_stack, []

    def stack_then_stop(*a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(refocus_pkg, "focal_stack", stack_then_stop)
    code, out, _ = run(capsys, "refocus", tmp_path / "clip.mp4", "-o", tmp_path / "out", "--alphas", "0.8,1,1.25",
                       "--json")
    summary = json.loads(out)
    assert code == 130 and summary["interrupted"] and summary["frames"] == 2
    assert sorted(p.name for p in (tmp_path / "out").glob("frame_*")) == ["frame_000000", "frame_000001"]
    assert all(len(list(p.iterdir())) == 3 for p in (tmp_path / "out").glob("frame_*"))
    assert len(list(iter_video_frames(tmp_path / "out" / "plane_02.mp4"))) == 2
    assert json.loads((tmp_path / "out" / "planes.json").read_text())["planes"]
    assert len(json.loads((tmp_path / "out" / "disparity.json").read_text())["frames"]) == 2


@pytest.mark.parametrize("name", ["clip.mp4", "clip.npy"])
def test_synth_interrupted_keeps_the_frames_so_far_with_their_disparity(capsys, tmp_path, monkeypatch, name):
    """Ctrl-C during ``synth``: exit 130, the output and its disparity file hold the frames
    rendered so far (a .npy cut to them), the same as an uninterrupted run's first frames."""
    import lfstream.synth as synth
    from lfstream import read_lf

    real = synth.iter_clip

    def two_then_stop(cfg):
        for t, frame in enumerate(real(cfg)):
            if t == 2:
                raise KeyboardInterrupt
            yield frame

    monkeypatch.setattr(synth, "iter_clip", two_then_stop)
    code, out, _ = run(capsys, "synth", tmp_path / name, "--frames", 5, "--views", 3, "--size", "24x32", "--json")
    assert code == 130 and json.loads(out)["frames"] == 2 and json.loads(out)["interrupted"]
    clip = synth.render_clip(synth.SynthConfig(frames=5, views=3, size=(24, 32)))
    np.testing.assert_array_equal(read_lf(tmp_path / name), clip.lf[:2])
    np.testing.assert_array_equal(np.load(tmp_path / "clip_disparity.npy"), clip.disparity[:2, ..., None])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_video_whose_size_does_not_fit_the_grid_is_refused_before_streaming(capsys, tmp_path, monkeypatch):
    """A mosaic video whose frame size is not a multiple of the grid given is refused from
    its container's size, in one line, before a frame is read: no output folder is left
    (it was refused by the producer stage at frame 0, after the folder was made)."""
    import lfstream

    monkeypatch.chdir(tmp_path)
    lfstream.write_lf(tmp_path / "clip.mp4", synth_clip(2, 5, (32, 40), seed=1).lf)
    code, _, err = run(capsys, "stream", "clip.mp4", "--grid", "3x3")
    assert code == 2 and "not a multiple of the view grid 3x3" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "lfstream-out").exists()


def test_encode_hance_map_sends_strength_maps_and_refuses_rate_control(capsys, tmp_path):
    import lfstream
    from lfstream.codec.bitstream import split_stream
    from lfstream.codec.centre.jpeg import hance_map

    lf = synth_clip(2, 5, (48, 64), seed=6).lf
    np.save(tmp_path / "lf.npy", lf)
    code, out, _ = run(capsys, "encode", tmp_path / "lf.npy", "-o", tmp_path / "a.lfs", "--preset", "fast",
                       "--hance-map", "--json")
    assert code == 0 and json.loads(out)["frames"] == 2 and json.loads(out)["hance_map"] is True
    data = (tmp_path / "a.lfs").read_bytes()
    assert all(hance_map(p.image) is not None for p in split_stream(data)[1])
    assert data == lfstream.encode(lf, preset="fast", hance_map=True)  # the CLI writes what the library makes
    code, out, _ = run(capsys, "info", tmp_path / "a.lfs", "--json")
    assert code == 0 and json.loads(out)["stream"]["hance_map"] == [16, 16]
    code, out, _ = run(capsys, "info", tmp_path / "a.lfs")
    assert "strength map of 16 x 16 tiles" in out
    code, out, _ = run(capsys, "encode", tmp_path / "lf.npy", "-o", tmp_path / "plain.lfs", "--preset", "fast", "--json")
    assert code == 0 and json.loads(out)["hance_map"] is False
    code, out, _ = run(capsys, "info", tmp_path / "plain.lfs", "--json")
    assert code == 0 and json.loads(out)["stream"]["hance_map"] is None
    code, _, err = run(capsys, "encode", tmp_path / "lf.npy", "-o", tmp_path / "b.lfs", "--bpp", "0.05", "--hance-map")
    assert code == 2 and "--hance-map" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "b.lfs").exists()


def test_decode_networks_picks_the_shipped_weights(capsys, tmp_path):
    """``decode --networks paper`` runs JPEG-Hance paper (what ``lfstream.decode(...,
    preset="paper")`` gives, not the fast network's views); a preset without the network
    asked for (Depth-Net paper ships no weights) is one line and exit status 2, nothing
    written; an unknown preset is refused by the library too."""
    import lfstream
    from lfstream.errors import LFValueError

    lf = synth_clip(1, 3, (40, 56), seed=3).lf[0]
    data = lfstream.encode(lf, preset="fast")
    (tmp_path / "a.lfs").write_bytes(data)
    code, _, _ = run(capsys, "decode", tmp_path / "a.lfs", "-o", tmp_path / "paper.npy", "--hance", "on",
                     "--networks", "paper")
    assert code == 0
    paper = np.load(tmp_path / "paper.npy")
    # one frame decodes to one light field (U, V, H, W, 3); lfstream.decode keeps the frame axis
    assert np.array_equal(paper, lfstream.decode(data, hance="on", preset="paper")[0])
    assert not np.array_equal(paper, lfstream.decode(data, hance="on")[0])  # the fast network's
    code, _, err = run(capsys, "decode", tmp_path / "a.lfs", "-o", tmp_path / "net.npy", "--depth", "net",
                       "--networks", "paper")
    assert code == 2 and "depth_net/paper" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "net.npy").exists()
    with pytest.raises(LFValueError, match="preset"):
        lfstream.decode(data, preset="best")


def test_decode_precision_is_the_networks_inference(capsys, tmp_path):
    """``decode --precision float32|bfloat16`` gives ``lfstream.decode(..., precision=)``'s
    bytes, the two differing where JPEG-Hance runs (a level here and there); ``auto`` is one
    of them; anything else is refused by argparse (status 2) and by the library."""
    import lfstream
    from lfstream.errors import LFValueError
    from lfstream.models.device import native_bfloat16

    lf = synth_clip(1, 3, (40, 56), seed=3).lf[0]
    data = lfstream.encode(lf, preset="fast")
    (tmp_path / "a.lfs").write_bytes(data)
    got = {}
    for precision in ("float32", "bfloat16", "auto"):
        code, _, _ = run(capsys, "decode", tmp_path / "a.lfs", "-o", tmp_path / f"{precision}.npy", "--hance", "on",
                         "--depth", "net", "--precision", precision)
        assert code == 0
        got[precision] = np.load(tmp_path / f"{precision}.npy")
    for precision in ("float32", "bfloat16"):
        assert np.array_equal(got[precision], lfstream.decode(data, hance="on", depth="net", precision=precision)[0])
    assert not np.array_equal(got["float32"], got["bfloat16"])
    assert np.abs(got["float32"].astype(np.int16) - got["bfloat16"]).max() <= 2
    assert np.array_equal(got["auto"], got["bfloat16" if native_bfloat16("cpu") else "float32"])
    with pytest.raises(SystemExit) as exc:
        run(capsys, "decode", tmp_path / "a.lfs", "-o", tmp_path / "x.npy", "--precision", "half")
    assert exc.value.code == 2 and not (tmp_path / "x.npy").exists()
    with pytest.raises(LFValueError, match="precision"):
        lfstream.decode(data, precision="half")


@pytest.mark.parametrize("name", ["clip.avi", "clip.npy", "clip.npz", "clipdir", "clip.mkv"])
def test_convert_writes_the_same_frames_in_another_format(capsys, tmp_path, name):
    """``convert`` of a lossless .mp4 mosaic video (read frame by frame) to each format:
    the same frames bit for bit, the grid and the frame rate kept (where the format holds
    them); the output is never the input, and an existing one is kept without --overwrite."""
    import lfstream

    clip = synth_clip(3, 5, (24, 32), seed=5, noise=2.0).lf
    lfstream.write_lf(tmp_path / "src.mp4", clip, fps=12)
    code, out, _ = run(capsys, "convert", tmp_path / "src.mp4", tmp_path / name, "--json")
    result = json.loads(out)
    assert code == 0 and result["frames"] == 3 and result["views"] == [5, 5] and result["size"] == [24, 32]
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / name), clip)
    if name.endswith((".avi", ".mkv")):
        from lfstream.io import open_video_lf

        assert open_video_lf(tmp_path / name).fps == pytest.approx(12)
    code, _, err = run(capsys, "convert", tmp_path / "src.mp4", tmp_path / name)
    assert code == 2 and "already exists" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(capsys, "convert", tmp_path / "src.mp4", tmp_path / "src.mp4", "--overwrite")
    assert code == 2 and "is the input" in err
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / "src.mp4"), clip)


def test_convert_refuses_missing_views_and_keeps_frames_on_ctrl_c(capsys, tmp_path, monkeypatch):
    """A light field with missing views is refused in one line (nothing is filled in); Ctrl-C
    during a convert exits 130 with the frames written so far in a valid file."""
    import lfstream
    import lfstream.io as io_pkg

    code, _, err = run(capsys, "convert", shared("hci_star", "dino"), tmp_path / "dino.avi", "--allow-missing")
    assert code == 2 and "missing" in err and not (tmp_path / "dino.avi").exists()
    clip = synth_clip(4, 3, (24, 32), seed=6).lf
    lfstream.write_lf(tmp_path / "src.npy", clip)
    real = io_pkg.FrameWriter.write
    calls = []

    def write_then_stop(self, lf):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(self, lf)

    monkeypatch.setattr(io_pkg.FrameWriter, "write", write_then_stop)
    code, out, _ = run(capsys, "convert", tmp_path / "src.npy", tmp_path / "part.avi", "--json")
    assert code == 130 and json.loads(out)["interrupted"] and json.loads(out)["frames"] == 2
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / "part.avi"), clip[:2])


def test_convert_of_a_video_damaged_part_way_keeps_the_frames_before_it(capsys, tmp_path):
    """A mosaic video cut off part way (a copy interrupted): convert writes the whole frames
    before the damage, valid and exact, and says so in one line with exit status 2."""
    import lfstream

    clip = synth_clip(4, 3, (40, 48), seed=7, noise=2.0).lf
    lfstream.write_lf(tmp_path / "src.avi", clip)
    data = (tmp_path / "src.avi").read_bytes()
    (tmp_path / "cut.avi").write_bytes(data[: int(len(data) * 0.7)])
    code, _, err = run(capsys, "convert", tmp_path / "cut.avi", tmp_path / "out.npy")
    assert code == 2 and "frame(s) before it written" in err and len(err.strip().splitlines()) == 1
    kept = lfstream.read_lf(tmp_path / "out.npy")
    assert 1 <= len(kept) < 4
    np.testing.assert_array_equal(kept, clip[: len(kept)])


def test_stream_renders_a_short_builtin_clip_during_the_warm_up_only(capsys, tmp_path, monkeypatch):
    """``lfstream stream`` gives the pipeline the built-in clip's render as ``prepare`` up to
    PRERENDER_MAX_FRAMES frames (a longer clip renders as it streams, its frames flowing at
    once), and never for an input file."""
    from lfstream.stream import pipeline
    from lfstream.stream.sources import PRERENDER_MAX_FRAMES

    seen = []

    def capture(self):
        seen.append(self.prepare)
        raise KeyboardInterrupt  # nothing runs: the stopped summary, exit 130

    monkeypatch.setattr(pipeline.Pipeline, "run", capture)
    np.save(tmp_path / "clip.npy", synth_clip(1, 3, (16, 16), seed=1).lf)
    for k, argv in enumerate((["--frames", str(PRERENDER_MAX_FRAMES)], ["--frames", str(PRERENDER_MAX_FRAMES + 1)],
                              [str(tmp_path / "clip.npy")])):
        code, _, _ = run(capsys, "stream", *argv, "-o", tmp_path / f"s{k}", "--json")
        assert code == 130
    assert callable(seen[0]) and seen[1] is None and seen[2] is None


def test_info_names_a_videos_codec_and_pixel_format(capsys, tmp_path):
    """``info`` of a mosaic video says how it is coded (what decides how fast it reads)."""
    import lfstream

    clip = synth_clip(1, 3, (24, 32), seed=8).lf
    for name, codec, pix in (("a.avi", "utvideo", "gbrp"), ("a.mp4", "h264", "gbrp"), ("a.mkv", "ffv1", "bgr0")):
        lfstream.write_lf(tmp_path / name, clip)
        code, out, _ = run(capsys, "info", tmp_path / name, "--json")
        video = json.loads(out)["video"]
        assert code == 0 and video["codec"] == codec and video["pixel_format"] == pix
        assert video["file_bytes"] == (tmp_path / name).stat().st_size
        code, out, _ = run(capsys, "info", tmp_path / name)
        assert f"coded   {codec} ({pix})" in out


def test_decode_disparity_out_is_a_new_or_empty_folder(capsys, tmp_path):
    """``decode --disparity-out``: a file there is one line (it was a FileExistsError
    traceback), a folder holding an earlier decode's maps is kept unless --overwrite."""
    import lfstream

    (tmp_path / "c.lfs").write_bytes(lfstream.encode(synth_clip(2, 3, (24, 32), seed=9).lf))
    (tmp_path / "afile").write_text("mine")
    code, _, err = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "a.npy", "--disparity-out",
                       tmp_path / "afile")
    assert code == 2 and "afile" in err and len(err.strip().splitlines()) == 1
    assert (tmp_path / "afile").read_text() == "mine"
    code, _, _ = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "b.npy", "--disparity-out", tmp_path / "d")
    assert code == 0 and sorted(p.name for p in (tmp_path / "d").iterdir()) == ["frame_000000.pfm", "frame_000001.pfm"]
    code, _, err = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "c.npy", "--disparity-out", tmp_path / "d")
    assert code == 2 and "already exists" in err
    code, _, _ = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "c.npy", "--disparity-out", tmp_path / "d",
                     "--overwrite")
    assert code == 0


def test_a_bad_size_says_size(capsys):
    with pytest.raises(SystemExit) as e:
        main(["demo", "--size", "0x0"])
    assert e.value.code == 2 and "size (HxW) must look like 375x540" in capsys.readouterr().err


def test_convert_rounds_a_float_light_field_for_8_bit_formats(capsys, tmp_path):
    """A float light field in [0, 1] goes into a video as lfstream's to_uint8 rounds it (a
    .npy keeps the floats); one in 8-bit units is refused in one line, nothing written."""
    import lfstream
    from lfstream.lightfield import to_uint8

    lf = np.random.default_rng(3).random((2, 3, 3, 16, 16, 3)).astype(np.float32)
    np.save(tmp_path / "f.npy", lf)
    assert run(capsys, "convert", tmp_path / "f.npy", tmp_path / "f.avi")[0] == 0
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / "f.avi"), to_uint8(lf))
    assert run(capsys, "convert", tmp_path / "f.npy", tmp_path / "g.npy")[0] == 0
    np.testing.assert_array_equal(np.load(tmp_path / "g.npy"), lf)
    np.save(tmp_path / "units.npy", lf * 255)
    code, _, err = run(capsys, "convert", tmp_path / "units.npy", tmp_path / "u.avi")
    assert code == 2 and "divide by 255" in err and not (tmp_path / "u.avi").exists()


def test_a_folder_of_view_videos_streams_and_is_described_without_decoding(capsys, tmp_path, monkeypatch):
    """A camera array's video (one file per view): ``info`` reads the containers only (the
    missing views too, with --allow-missing), ``stream`` and ``convert`` take it frame by
    frame, and a folder without the centre view is refused in one line."""
    import lfstream.io.readers as readers
    from lfstream.io import write_video

    clip = synth_clip(3, 3, (24, 32), seed=10).lf
    folder = tmp_path / "array"
    folder.mkdir()
    for u in range(3):
        for v in range(3):
            if (u, v) != (0, 1):
                write_video(folder / f"{u}_{v}.mp4", list(clip[:, u, v]))
    real = readers.iter_video_frames
    monkeypatch.setattr(readers, "iter_video_frames", lambda *a, **k: (_ for _ in ()).throw(AssertionError("decoded")))
    code, out, _ = run(capsys, "info", folder, "--allow-missing", "--json")
    info = json.loads(out)
    assert code == 0 and info["format"] == "view-videos" and info["frames"] == 3 and info["missing_views"] == [[0, 1]]
    assert info["video"]["codec"] == "h264" and info["video"]["files"] == 8
    assert info["video"]["file_bytes"] == sum(p.stat().st_size for p in folder.iterdir())
    monkeypatch.setattr(readers, "iter_video_frames", real)
    code, out, _ = run(capsys, "stream", folder, "--allow-missing", "-o", tmp_path / "s", "--json")
    assert code == 0 and json.loads(out)["frames"] == 3
    code, _, err = run(capsys, "convert", folder, tmp_path / "c.avi", "--allow-missing")
    assert code == 2 and "missing" in err
    (folder / "1_1.mp4").unlink()
    code, _, err = run(capsys, "stream", folder, "--allow-missing", "-o", tmp_path / "t")
    assert code == 2 and "centre view is missing" in err and len(err.strip().splitlines()) == 1


def test_a_frame_range_of_a_video_through_the_commands(capsys, tmp_path):
    """``--first-frame`` with ``--max-frames`` cuts a clip out of an LF video: ``convert``
    writes exactly those frames, ``info`` counts them; past the end, or given to ``stream``
    without an input (the built-in clip takes ``--frames``), it is one line and exit 2,
    nothing left behind."""
    import lfstream

    clip = synth_clip(5, 3, (24, 32), seed=7, noise=2.0).lf
    lfstream.write_lf(tmp_path / "src.avi", clip, fps=10)
    whole = lfstream.read_lf(tmp_path / "src.avi")
    code, out, _ = run(capsys, "convert", tmp_path / "src.avi", tmp_path / "cut.avi", "--first-frame", "1",
                       "--max-frames", "3", "--json")
    assert code == 0 and json.loads(out)["frames"] == 3
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / "cut.avi"), whole[1:4])
    code, out, _ = run(capsys, "info", tmp_path / "src.avi", "--first-frame", "3", "--json")
    assert code == 0 and json.loads(out)["frames"] == 2
    code, _, err = run(capsys, "convert", tmp_path / "src.avi", tmp_path / "late.avi", "--first-frame", "5")
    assert code == 2 and "first_frame 5: it holds 5 frame(s)" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "late.avi").exists()
    code, _, err = run(capsys, "stream", "-o", tmp_path / "out", "--first-frame", "2")
    assert code == 2 and "--first-frame" in err and "--frames" in err and not (tmp_path / "out").exists()
    # and the other way round: --frames with an input file (it was ignored: every frame streamed)
    code, _, err = run(capsys, "stream", tmp_path / "src.avi", "-o", tmp_path / "out", "--frames", "1")
    assert code == 2 and "--max-frames" in err and not (tmp_path / "out").exists()


def test_a_frame_range_keeps_the_source_frame_numbers_in_every_output_of_a_run(capsys, tmp_path):
    """A range's frame folders are named by the source's frame numbers (``decode -o FOLDER``
    with its ``--disparity-out`` maps, whose names they did not match: views of frame 3 in
    frame_000000/, its map frame_000003.pfm; ``convert`` to a folder; ``refocus``); the stream
    numbers its own frames from 0 and records the range's start in ``summary.json``. ``info``
    describes such a folder (it raised an IndexError looking for view videos), and it reads
    back as the frames it holds."""
    import lfstream

    clip = synth_clip(5, 3, (24, 32), seed=7, noise=2.0).lf
    (tmp_path / "c.lfs").write_bytes(lfstream.encode(clip))
    lfstream.write_lf(tmp_path / "src.npy", clip)
    code, _, _ = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "dec", "--first-frame", "3",
                     "--disparity-out", tmp_path / "maps")
    assert code == 0
    assert sorted(p.name for p in (tmp_path / "dec").iterdir()) == ["frame_000003", "frame_000004"]
    assert sorted(p.name for p in (tmp_path / "maps").iterdir()) == ["frame_000003.pfm", "frame_000004.pfm"]
    np.testing.assert_array_equal(lfstream.read_lf(tmp_path / "dec"), lfstream.decode((tmp_path / "c.lfs").read_bytes())[3:])
    code, out, _ = run(capsys, "info", tmp_path / "dec", "--json")
    assert code == 0 and json.loads(out)["format"] == "frames-folder" and json.loads(out)["frames"] == 2
    assert json.loads(out)["video"] is None  # the key is there for every input (null: not a video)
    code, _, _ = run(capsys, "convert", tmp_path / "src.npy", tmp_path / "cut", "--first-frame", "1", "--max-frames", "2")
    assert code == 0 and sorted(p.name for p in (tmp_path / "cut").iterdir()) == ["frame_000001", "frame_000002"]
    code, _, _ = run(capsys, "refocus", tmp_path / "src.npy", "-o", tmp_path / "rf", "--first-frame", "2",
                     "--max-frames", "2", "--no-viewer")
    assert code == 0 and sorted(p.name for p in (tmp_path / "rf").glob("frame_*")) == ["frame_000002", "frame_000003"]
    code, out, _ = run(capsys, "stream", tmp_path / "src.npy", "-o", tmp_path / "st", "--first-frame", "2",
                       "--save", "png", "--no-viewer", "--json")
    summary = json.loads(out)
    assert code == 0 and summary["first_frame"] == 2 and summary["frames"] == 3
    assert [row["frame"] for row in summary["per_frame"]] == [0, 1, 2]
    assert sorted(p.name for p in (tmp_path / "st" / "frames").iterdir()) == [f"frame_{k:06d}" for k in range(3)]


def test_a_float_input_streams_with_the_metrics_of_its_8_bit_levels(capsys, tmp_path):
    """A float light field in [0, 1] streamed: the metrics compare it with the uint8 decode on
    one scale (they compared the raw samples, about -41 dB; then, with mixed scales refused,
    the metrics stage failed): the same MPSNR and MSSIM as the same input in 8 bits."""
    import lfstream

    clip = synth_clip(2, 5, (48, 64), seed=3, noise=2.0).lf
    lfstream.write_lf(tmp_path / "u8.npy", clip)
    np.save(tmp_path / "f32.npy", clip.astype(np.float32) / np.float32(255.0))
    results = []
    for name in ("u8.npy", "f32.npy"):
        code, out, _ = run(capsys, "stream", tmp_path / name, "-o", tmp_path / name.replace(".", "_"), "--no-viewer",
                           "--json")
        assert code == 0
        results.append(json.loads(out))
    assert results[1]["mpsnr"] == pytest.approx(results[0]["mpsnr"], abs=1e-4) and results[0]["mpsnr"] > 20
    assert results[1]["mssim"] == pytest.approx(results[0]["mssim"], abs=1e-5)


def test_convert_to_npz_keeps_the_ground_truth_disparity_of_the_frames_it_writes(capsys, tmp_path):
    """A .npz with ground-truth disparity (lfstream synth's) converted to a .npz: the
    disparity goes with the frames, a range's maps with the range's frames, every view's or
    the centre view's (it was dropped); the JSON says so; a format holding none says not."""
    import lfstream

    clip = synth_clip(3, 3, (24, 32), seed=5)
    lfstream.write_lf(tmp_path / "views.npz", clip.lf, disparity=clip.disparity)
    centre = clip.disparity[:, 1, 1]
    lfstream.write_lf(tmp_path / "centre.npz", clip.lf, disparity=centre)
    for src, truth in (("views.npz", clip.disparity), ("centre.npz", centre)):
        code, out, _ = run(capsys, "convert", tmp_path / src, tmp_path / f"cut-{src}", "--first-frame", "1", "--json")
        assert code == 0 and json.loads(out)["disparity"] is True
        loaded = lfstream.load_lf(tmp_path / f"cut-{src}")
        np.testing.assert_array_equal(loaded.lf, clip.lf[1:])
        np.testing.assert_array_equal(loaded.disparity, truth[1:])
    code, out, _ = run(capsys, "convert", tmp_path / "views.npz", tmp_path / "plain.npy", "--json")
    assert code == 0 and json.loads(out)["disparity"] is False
    # a still is written as a one-frame video, its map with a frame axis
    lfstream.write_lf(tmp_path / "still.npz", clip.lf[0], disparity=centre[0])
    assert run(capsys, "convert", tmp_path / "still.npz", tmp_path / "still-out.npz")[0] == 0
    still = lfstream.load_lf(tmp_path / "still-out.npz")
    assert still.lf.shape == (1, *clip.lf.shape[1:]) and still.disparity.shape == (1, *centre.shape[1:])
    np.testing.assert_array_equal(still.disparity[0], centre[0])


def test_a_stream_of_an_input_cut_short_ends_there_with_its_outputs(capsys, tmp_path):
    """An input damaged after its first frames (an .lfs cut short) ends the stream there:
    the frames before it go through every stage, the outputs and summary.json are written
    (the summary names the damage, ``input_error``), then one line and exit 2; damage before
    any frame is the stage's error as before."""
    import lfstream

    data = lfstream.encode(synth_clip(4, 3, (32, 40), seed=1).lf)
    (tmp_path / "cut.lfs").write_bytes(data[:-100])
    code, out, err = run(capsys, "stream", tmp_path / "cut.lfs", "-o", tmp_path / "out", "--json")
    summary = json.loads(out)
    assert code == 2 and summary["frames"] == 3 and "frame 3" in summary["input_error"]
    assert "3 frame(s) before it streamed" in err and len(err.strip().splitlines()) == 1
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["frames"] == 3
    from lfstream.io import ReadOptions, open_video_lf

    assert open_video_lf(tmp_path / "out" / "plane_00.mp4", ReadOptions(grid=(1, 1))).count == 3


def test_a_stream_failing_before_any_output_leaves_no_folder_it_made(capsys, tmp_path):
    """A stage that fails before anything is written (the hint's disparity asked of a stream
    without a hint) is one line and exit 2, and the output folder this run made is removed;
    one the user made stays."""
    code, _, err = run(capsys, "stream", "--no-depth-hint", "--depth", "hint", "--frames", "2", "-o", tmp_path / "made")
    assert code == 2 and "stage decoder failed" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "made").exists()
    (tmp_path / "mine").mkdir()
    code, _, _ = run(capsys, "stream", "--no-depth-hint", "--depth", "hint", "--frames", "2", "-o", tmp_path / "mine")
    assert code == 2 and (tmp_path / "mine").is_dir()


def test_no_hance_is_a_deprecated_spelling_of_hance_off(capsys, tmp_path):
    import lfstream

    (tmp_path / "c.lfs").write_bytes(lfstream.encode(synth_clip(1, 3, (24, 32), seed=9).lf, quality=20))
    code, _, err = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "a.npy", "--no-hance")
    assert code == 0 and "deprecated" in err and "--hance off" in err
    code, _, _ = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "b.npy", "--hance", "off")
    assert code == 0 and np.array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))
    code, _, err = run(capsys, "decode", tmp_path / "c.lfs", "-o", tmp_path / "c.npy", "--no-hance", "--hance", "on")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--no-hance" in err
    assert not (tmp_path / "c.npy").exists()


def test_frozen_garbage_collector_freezes_on_warm_and_unfreezes_after():
    """The stream command's ``on_warm`` collects and freezes what is alive; leaving the
    block unfreezes it, so a caller running commands in one process is left as it was."""
    import gc

    from lfstream.cli._pipeline import frozen_garbage_collector

    gc.unfreeze()
    with frozen_garbage_collector() as on_warm:
        assert gc.get_freeze_count() == 0  # nothing frozen before the warm-up ends
        on_warm()
        assert gc.get_freeze_count() > 1000
    assert gc.get_freeze_count() == 0
