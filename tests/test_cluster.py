"""lfstream.batch: the local and Ray engines give the same bytes, a killed worker loses no
frames, a bad input fails alone, and the .lfs it writes decodes like a sequential encode."""

import importlib.util
import json

import numpy as np
import pytest

import lfstream
from lfstream.cli import main
from lfstream.cluster import DecodeOptions, EncodeOptions, batch
from lfstream.errors import LFValueError
from lfstream.synth import synth_clip

HAS_RAY = importlib.util.find_spec("ray") is not None
needs_ray = pytest.mark.skipif(not HAS_RAY, reason="Ray is not installed (pip install 'lfstream[ray]')")


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("videos")
    paths = []
    for k, frames in enumerate((7, 3)):
        p = folder / f"clip{k}.npy"
        np.save(p, synth_clip(frames, 5, (40, 48), seed=k, motion=0.5).lf)
        paths.append(p)
    bad = folder / "broken.npy"
    bad.write_bytes(b"\x93NUMPY garbage")
    return paths, bad


def test_local_batch_encodes_every_input_and_the_streams_decode(videos, tmp_path):
    paths, _ = videos
    report = batch(paths, tmp_path / "out", group_frames=3)
    assert report.ok and report.frames == 10 and [f.frames for f in report.files] == [7, 3]
    for p, f in zip(paths, report.files):
        data = open(f.output, "rb").read()
        assert f.bytes == len(data)
        assert lfstream.decode(data).shape == np.load(p).shape
    # one group per input: exactly the bytes of a sequential lfstream.encode
    whole = batch(paths, tmp_path / "whole", group_frames=100)
    for p, f in zip(paths, whole.files):
        assert open(f.output, "rb").read() == lfstream.encode(np.load(p))


def test_a_broken_input_fails_alone_and_nothing_is_overwritten(videos, tmp_path, capsys):
    paths, bad = videos
    out = tmp_path / "out"
    code = main(["batch", str(paths[1]), str(bad), "-o", str(out), "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 2
    status = {f["input"]: f for f in result["files"]}
    assert status[str(paths[1])]["status"] == "ok" and status[str(bad)]["status"] == "failed"
    assert "broken.npy" in status[str(bad)]["error"]
    assert sorted(p.name for p in out.iterdir()) == ["clip1.lfs"]  # no partial file for the broken one
    again = batch([paths[1]], out)
    assert not again.ok and "already exists" in again.files[0].error
    assert (out / "clip1.lfs").exists()  # the folder it did not make, and what is in it, stay
    # every input failed: the folder the call made is removed (nothing in it); one the user made stays
    assert not batch([bad], tmp_path / "none").ok and not (tmp_path / "none").exists()
    (tmp_path / "mine").mkdir()
    assert not batch([bad], tmp_path / "mine").ok and (tmp_path / "mine").is_dir()


def test_decode_mode_reassembles_frames_in_order(videos, tmp_path):
    paths, _ = videos
    enc = batch([paths[0]], tmp_path / "lfs", group_frames=2, encode=EncodeOptions(quality=60))
    lfs = enc.files[0].output
    dec = batch([lfs], tmp_path / "dec", mode="decode", group_frames=2)
    assert dec.ok and dec.files[0].frames == 7
    assert np.array_equal(np.load(dec.files[0].output), lfstream.decode(open(lfs, "rb").read()))


def test_decode_mode_runs_the_networks_named(videos, tmp_path):
    """``DecodeOptions(networks="paper")`` with JPEG-Hance on: the frames of
    ``lfstream.decode(..., hance="on", preset="paper")``."""
    paths, _ = videos
    lfs = batch([paths[0]], tmp_path / "lfs", group_frames=4, encode=EncodeOptions(quality=60)).files[0].output
    dec = batch([lfs], tmp_path / "dec", mode="decode", group_frames=4,
                decode=DecodeOptions(hance="on", networks="paper"))
    assert dec.ok
    assert np.array_equal(np.load(dec.files[0].output),
                          lfstream.decode(open(lfs, "rb").read(), hance="on", preset="paper"))


def test_decode_mode_takes_a_frame_range(videos, tmp_path):
    """``first_frame`` / ``max_frames`` in decode mode (they were ignored: every frame was
    decoded): the frames of the range, whichever groups and key hints they fall in, the same
    as lfstream.decode's; a folder's frames keep the stream's numbers; a start past the end
    fails that input alone; the options that shape light fields read for an encode are
    refused before any folder is made."""
    from lfstream.io import ReadOptions

    paths, _ = videos
    enc = batch([paths[0]], tmp_path / "lfs", group_frames=2, encode=EncodeOptions(quality=60))
    lfs = enc.files[0].output
    whole = lfstream.decode(open(lfs, "rb").read())
    for first, most in ((3, 2), (1, None), (6, 5), (0, 1)):
        out = tmp_path / f"dec{first}"
        dec = batch([lfs], out, mode="decode", group_frames=2, read=ReadOptions(first_frame=first, max_frames=most))
        stop = len(whole) if most is None else min(len(whole), first + most)
        assert dec.ok and dec.files[0].frames == stop - first
        np.testing.assert_array_equal(np.load(dec.files[0].output), whole[first:stop])
    dec = batch([lfs], tmp_path / "folders", mode="decode", group_frames=3, output_format="",
                read=ReadOptions(first_frame=4, max_frames=2))
    assert sorted(p.name for p in (tmp_path / "folders" / "clip0").iterdir()) == ["frame_000004", "frame_000005"]
    late = batch([lfs], tmp_path / "late", mode="decode", read=ReadOptions(first_frame=7))
    assert not late.ok and "first_frame 7: it holds 7 frame(s)" in late.files[0].error
    with pytest.raises(LFValueError, match="a decode takes first_frame and max_frames"):
        batch([lfs], tmp_path / "cropped", mode="decode", read=ReadOptions(crop=3))
    assert not (tmp_path / "cropped").exists()
    # the output format: "folder" is folders of views, "avi" its extension; an unknown one
    # is refused (it was appended to the name: --format folder wrote clip0folder/)
    named = batch([lfs], tmp_path / "named", mode="decode", output_format="folder", read=ReadOptions(max_frames=1))
    assert named.ok and (tmp_path / "named" / "clip0" / "frame_000000").is_dir()
    assert batch([lfs], tmp_path / "avi", mode="decode", output_format="avi").files[0].output.endswith("clip0.avi")
    with pytest.raises(LFValueError, match="output_format: .npy, .npz"):
        batch([lfs], tmp_path / "odd", mode="decode", output_format="xyz")
    assert not (tmp_path / "odd").exists()


def test_batch_encode_with_an_av1_preset_equals_a_single_encode(videos, tmp_path):
    paths, _ = videos
    rep = batch([paths[0]], tmp_path / "av1", group_frames=100, encode=EncodeOptions(quality=60, preset="balanced"))
    assert rep.ok
    data = open(rep.files[0].output, "rb").read()
    lf = np.load(paths[0])
    # one group: the same bytes as encoding the video in one call with the same options
    assert data == lfstream.encode(lf, quality=60, preset="balanced")
    with pytest.raises(LFValueError):
        EncodeOptions(preset="slowest")


def test_batch_encode_takes_the_default_choice_whole(tmp_path):
    """One group per input gives lfstream.encode's bytes also where the default's choice
    sends the hint at 1/8 (the batch coded it at 1/4 before: 25 % more bytes on the built-in
    clip's scene) and with JPEG-Hance strength maps (sent with a JPEG centre, dropped where
    the default codes the views with AV1, as lfstream encode does)."""
    import io

    from lfstream.codec.bitstream import read_header

    coarse = synth_clip(2, 5, (128, 160), seed=1, motion=0.5, noise=2.0, vignetting=0.3).lf
    mapped = synth_clip(2, 7, (64, 80), seed=2, motion=0.5, noise=2.0).lf
    small = synth_clip(2, 5, (40, 48), seed=0, motion=0.5).lf  # the default: an AV1 centre
    for name, lf, options, kwargs in (("coarse", coarse, EncodeOptions(), {}),
                                      ("mapped", mapped, EncodeOptions(hance_map=True), {"hance_map": True}),
                                      ("small", small, EncodeOptions(hance_map=True), {"hance_map": True})):
        path = tmp_path / f"{name}.npy"
        np.save(path, lf)
        rep = batch([path], tmp_path / name, group_frames=100, encode=options)
        assert rep.ok
        data = open(rep.files[0].output, "rb").read()
        assert data == lfstream.encode(lf, **kwargs), name
        meta = read_header(io.BytesIO(data)).meta
        if name == "coarse":
            assert meta["hint"]["hint_scale"] == 8
        assert ("hance_map" in meta) == (name == "mapped")
    with pytest.raises(LFValueError, match="hance_map"):
        EncodeOptions(preset="balanced", hance_map=True)


@needs_ray
def test_ray_engine_gives_byte_identical_outputs_and_survives_a_killed_worker(videos, tmp_path):
    paths, _ = videos
    local = batch(paths, tmp_path / "local", group_frames=3)
    marker = tmp_path / "killed-once"
    ray_report = batch(paths, tmp_path / "ray", engine="ray", workers=2, group_frames=3, _fail_once=marker)
    assert marker.exists()  # the first job's worker was killed, and Ray ran the job again
    assert ray_report.ok and ray_report.engine == "ray" and ray_report.workers == 2
    assert ray_report.frames == local.frames == 10
    for a, b in zip(local.files, ray_report.files):
        assert open(a.output, "rb").read() == open(b.output, "rb").read()
    dec_local = batch([local.files[0].output], tmp_path / "dl", mode="decode", group_frames=2)
    dec_ray = batch([local.files[0].output], tmp_path / "dr", mode="decode", engine="ray", workers=2, group_frames=2)
    assert np.array_equal(np.load(dec_local.files[0].output), np.load(dec_ray.files[0].output))


def test_without_ray_the_engine_says_how_to_install_it(monkeypatch, tmp_path):
    import builtins

    real_import = builtins.__import__

    def no_ray(name, *args, **kwargs):
        if name == "ray":
            raise ImportError("no ray here")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    with pytest.raises(lfstream.LFValueError, match=r"pip install 'lfstream\[ray\]'"):
        batch([tmp_path / "x.npy"], tmp_path / "out", engine="ray")


def test_frame_groups_stack_frames_as_they_come():
    from lfstream.cluster.jobs import frame_groups

    frames = (np.full((1, 1, 2, 2, 3), k, np.uint8) for k in range(7))
    groups = list(frame_groups(frames, 3))
    assert [start for start, _ in groups] == [0, 3, 6] and [len(g) for _, g in groups] == [3, 3, 1]
    assert [int(g[0, 0, 0, 0, 0, 0]) for _, g in groups] == [0, 3, 6]


def test_batch_reads_an_lf_video_a_group_at_a_time_and_a_damaged_one_fails_alone(tmp_path, monkeypatch):
    """An LF video input is read as its groups are encoded (the first group is encoded
    before the last frames are read: the video is never all in memory), the stream equals a
    sequential encode with one group, and an input damaged part way fails alone: its groups
    dropped, no file for it, the others written."""
    import dataclasses

    import lfstream.cluster.run as run_mod
    import lfstream.io as io_pkg

    clip = synth_clip(6, 3, (40, 48), seed=3, motion=0.5).lf
    lfstream.write_lf(tmp_path / "clip.avi", clip)
    data = (tmp_path / "clip.avi").read_bytes()
    (tmp_path / "cut.avi").write_bytes(data[: int(len(data) * 0.7)])
    events = []
    real_frames, real_encode = io_pkg.open_lf_frames, run_mod.encode_group

    def frames_spy(path, read):
        video = real_frames(path, read)

        def counted():
            for k, f in enumerate(video.frames):
                events.append(("read", k))
                yield f
        return dataclasses.replace(video, frames=counted())

    def encode_spy(frames, start, *args):
        events.append(("encode", start))
        return real_encode(frames, start, *args)

    monkeypatch.setattr(io_pkg, "open_lf_frames", frames_spy)
    monkeypatch.setattr(run_mod, "encode_group", encode_spy)
    report = batch([tmp_path / "clip.avi"], tmp_path / "grouped", group_frames=2)
    assert report.ok and report.frames == 6
    assert events.index(("encode", 0)) < events.index(("read", 5))
    whole = batch([tmp_path / "clip.avi"], tmp_path / "whole", group_frames=100)
    assert open(whole.files[0].output, "rb").read() == lfstream.encode(clip)
    mixed = batch([tmp_path / "cut.avi", tmp_path / "clip.avi"], tmp_path / "mixed", group_frames=2)
    status = {f.input: f for f in mixed.files}
    assert status[str(tmp_path / "cut.avi")].status == "failed" and "cut.avi" in status[str(tmp_path / "cut.avi")].error
    assert status[str(tmp_path / "clip.avi")].status == "ok"
    assert sorted(p.name for p in (tmp_path / "mixed").iterdir()) == ["clip.lfs"]


def test_batch_decode_writes_each_group_as_it_comes_and_drops_a_failed_output(videos, tmp_path, monkeypatch):
    """Decoding, every group's frames go into the output as their job finishes (the first
    group written before the last is decoded: a decoded video is never all in memory), in
    every format the same frames as lfstream.decode; a job that fails part way leaves no
    output for its input (no partial file), the others complete."""
    import lfstream.cluster.run as run_mod
    from lfstream.io import FrameWriter

    paths, _ = videos
    enc = batch([paths[0]], tmp_path / "lfs", group_frames=2)
    lfs = enc.files[0].output
    want = lfstream.decode(open(lfs, "rb").read())
    events = []
    real_decode, real_write = run_mod.decode_group, FrameWriter.write

    def decode_spy(header, packets, start, options):
        events.append(("decode", start))
        return real_decode(header, packets, start, options)

    def write_spy(self, lf):
        events.append(("write", self.frames))
        return real_write(self, lf)

    monkeypatch.setattr(run_mod, "decode_group", decode_spy)
    monkeypatch.setattr(FrameWriter, "write", write_spy)
    for fmt in (".avi", ".npy", ".npz", ""):
        events.clear()
        rep = batch([lfs], tmp_path / f"dec{fmt or 'dir'}", mode="decode", group_frames=2, output_format=fmt)
        assert rep.ok and rep.files[0].frames == 7
        np.testing.assert_array_equal(lfstream.read_lf(rep.files[0].output), want)
        if fmt != ".npz":
            assert events.index(("write", 0)) < events.index(("decode", 6))

    def failing(header, packets, start, options):
        if start >= 4:
            raise LFValueError("a decode that fails part way")
        return real_decode(header, packets, start, options)

    monkeypatch.setattr(run_mod, "decode_group", failing)
    rep = batch([lfs, lfs], tmp_path / "failed", mode="decode", group_frames=2, output_format=".avi")
    assert [f.status for f in rep.files] == ["failed", "failed"] and "part way" in rep.files[0].error
    assert not (tmp_path / "failed").exists()  # nothing written, the folder it made removed
