import numpy as np
import pytest

from lfstream import LFStreamError, load_lf, read_lf, read_pfm, write_lf, write_pfm
from lfstream.errors import LFFileError, LFFormatError, LFMissingViewsError, LFShapeError, LFValueError
from lfstream.io import write_image, write_video
from lfstream.lightfield import to_mosaic, to_sensor
from tests.conftest import random_lf, shared


def test_seahorse_folder_is_5x5_of_500():
    lf = read_lf(shared("seahorse5x5", "camImagesFlat"))
    assert lf.shape == (5, 5, 500, 500, 3) and lf.dtype == np.uint8
    # Neighbouring views differ (it is a real light field, not one image five times).
    assert np.abs(lf[2, 0].astype(int) - lf[2, 4].astype(int)).mean() > 1


@pytest.mark.parametrize("scene", ["cotton", "dino"])
def test_hci_star_missing_views_error_or_mask(scene):
    folder = shared("hci_star", scene)
    with pytest.raises(LFMissingViewsError) as info:
        read_lf(folder)
    assert len(info.value.missing) == 81 - 33
    assert str(folder) in str(info.value) and "(0,1)" in str(info.value)
    lf, present = read_lf(folder, return_mask=True)
    assert lf.shape == (9, 9, 512, 512, 3) and present.sum() == 33
    # the star: centre row, centre column, both diagonals
    assert present[4].all() and present[:, 4].all() and present.diagonal().all() and np.fliplr(present).diagonal().all()
    assert (lf[~present] == 0).all() and lf[present].max() > 0


def test_folder_naming_schemes(tmp_path, rng):
    lf = random_lf(rng, (3, 2, 8, 10, 3))
    rc = write_lf(tmp_path / "rc", lf)
    np.testing.assert_array_equal(read_lf(rc), lf)
    lytro = tmp_path / "lytro"
    lytro.mkdir()
    hci = tmp_path / "hci"
    hci.mkdir()
    sq = random_lf(rng, (3, 3, 8, 10, 3))
    for u in range(3):
        for v in range(3):
            write_image(lytro / f"scene_{u + 1:02d}_{v + 1:02d}.png", sq[u, v])
            write_image(hci / f"input_Cam{u * 3 + v:03d}.png", sq[u, v])
    np.testing.assert_array_equal(read_lf(lytro), sq)
    np.testing.assert_array_equal(read_lf(hci), sq)
    np.testing.assert_array_equal(read_lf(lytro, flip_u=True, flip_v=True), sq[::-1, ::-1])


def test_npy_npz_round_trip(tmp_path, rng):
    video = random_lf(rng, (2, 3, 3, 6, 7, 3))
    write_lf(tmp_path / "a.npy", video)
    np.testing.assert_array_equal(read_lf(tmp_path / "a.npy"), video)
    disp = rng.normal(size=video.shape[:-1]).astype(np.float32)
    write_lf(tmp_path / "a.npz", video, disparity=disp)
    loaded = load_lf(tmp_path / "a.npz")
    np.testing.assert_array_equal(loaded.lf, video)
    np.testing.assert_array_equal(loaded.disparity, disp)
    assert loaded.frames == 2 and loaded.views == (3, 3) and loaded.size == (6, 7)


def test_array_files_take_16_bit_samples_to_8_bits_and_refuse_other_integers(tmp_path, rng):
    """A uint16 array is 16-bit samples, taken to 8 bits as a 16-bit image is (round(x /
    257)), whole or a frame range at a time; any other integer or bool array is one clear
    error (a uint16 array was read as floats and saturated to white)."""
    video = random_lf(rng, (3, 2, 2, 5, 6, 3))
    # within 128 of a level's 16-bit value (v * 257) rounds to that level
    sixteen = video.astype(np.int64) * 257 + rng.integers(-128, 129, video.shape)
    np.save(tmp_path / "s.npy", sixteen.clip(0, 65535).astype(np.uint16))
    np.testing.assert_array_equal(read_lf(tmp_path / "s.npy"), video)
    np.testing.assert_array_equal(read_lf(tmp_path / "s.npy", first_frame=1, max_frames=1), video[1:2])
    for dtype in (np.int64, np.int16, np.uint32, bool):
        np.save(tmp_path / "bad.npy", video.astype(dtype))
        with pytest.raises(LFFormatError, match=rf"bad.npy: {np.dtype(dtype).name} samples; expected uint8, uint16"):
            read_lf(tmp_path / "bad.npy")


def test_a_disparity_that_does_not_describe_the_light_field_is_refused(tmp_path, rng):
    """write_lf's disparity: every view's map or the centre view's, per frame of a video
    (a (3, 3) map beside a 2-frame 5x5 video was written and read back as it came)."""
    video = random_lf(rng, (2, 3, 3, 6, 7, 3))
    for good in ((2, 3, 3, 6, 7), (2, 6, 7)):
        write_lf(tmp_path / f"ok{len(good)}.npz", video, disparity=np.zeros(good, np.float32))
        assert load_lf(tmp_path / f"ok{len(good)}.npz").disparity.shape == good
    write_lf(tmp_path / "still.npz", video[0], disparity=np.zeros((6, 7), np.float32))
    with pytest.raises(LFShapeError, match=r"bad.npz: disparity \(3, 3\) matches neither"):
        write_lf(tmp_path / "bad.npz", video, disparity=np.zeros((3, 3), np.float32))
    assert not (tmp_path / "bad.npz").exists()
    from lfstream.io import FrameWriter

    with pytest.raises(LFValueError, match="holds no disparity; write a .npz"):
        FrameWriter(tmp_path / "x.avi", disparity=np.zeros((2, 6, 7), np.float32))
    # frame by frame into a .npz: the maps of the frames written (closed part way: two of three)
    with FrameWriter(tmp_path / "part.npz", disparity=np.arange(3 * 6 * 7, dtype=np.float32).reshape(3, 6, 7)) as w:
        w.write(video[0])
        w.write(video[1])
    part = load_lf(tmp_path / "part.npz")
    assert part.lf.shape[0] == 2 and part.disparity.shape == (2, 6, 7) and part.disparity[1, 0, 0] == 42


def test_existing_output_is_not_overwritten(tmp_path, rng):
    lf = random_lf(rng)
    write_lf(tmp_path / "a.npy", lf)
    with pytest.raises(LFFileError, match="already exists"):
        write_lf(tmp_path / "a.npy", lf[::-1])
    np.testing.assert_array_equal(read_lf(tmp_path / "a.npy"), lf)


@pytest.mark.parametrize("name", ["clip.mkv", "clip.mp4"])
def test_mosaic_video_lossless_round_trip(tmp_path, rng, name):
    video = random_lf(rng, (3, 2, 3, 8, 10, 3))
    write_lf(tmp_path / name, video, fps=12)
    loaded = load_lf(tmp_path / name)
    assert loaded.format == "video" and loaded.fps == pytest.approx(12)
    np.testing.assert_array_equal(loaded.lf, video)


def test_video_without_grid_needs_grid(tmp_path, rng):
    video = random_lf(rng, (2, 2, 2, 8, 8, 3))
    write_video(tmp_path / "plain.mkv", [to_mosaic(f) for f in video])
    with pytest.raises(LFFormatError, match="grid"):
        read_lf(tmp_path / "plain.mkv")
    np.testing.assert_array_equal(read_lf(tmp_path / "plain.mkv", grid=(2, 2)), video)


def test_view_videos_and_frames_folders(tmp_path, rng):
    video = random_lf(rng, (3, 2, 2, 8, 8, 3))
    views = tmp_path / "views"
    views.mkdir()
    for u in range(2):
        for v in range(2):
            write_video(views / f"{u}_{v}.mkv", video[:, u, v])
    loaded = load_lf(views)
    assert loaded.format == "view-videos"
    np.testing.assert_array_equal(loaded.lf, video)
    frames = tmp_path / "frames"
    write_lf(frames, video)  # one sub-folder per frame
    loaded = load_lf(frames)
    assert loaded.format == "frames-folder"
    np.testing.assert_array_equal(loaded.lf, video)


def test_eslf_crop_and_alpha(tmp_path, rng):
    lf = random_lf(rng, (14, 14, 6, 5, 3))
    alpha = np.full((14, 14, 6, 5, 1), 255, np.uint8)
    alpha[0, 0] = 0  # a masked corner view
    sensor = to_sensor(np.concatenate([lf, alpha], axis=-1))
    import cv2

    cv2.imwrite(str(tmp_path / "lenslet.png"), cv2.cvtColor(sensor, cv2.COLOR_RGBA2BGRA))
    loaded = load_lf(tmp_path / "lenslet.png", angular=14)
    np.testing.assert_array_equal(loaded.lf, lf)
    assert loaded.weight.shape == (14, 14, 6, 5) and loaded.weight[0, 0].max() == 0 and loaded.weight[1, 1].min() == 1
    cropped = load_lf(tmp_path / "lenslet.png", angular=14, crop=7)
    np.testing.assert_array_equal(cropped.lf, lf[4:11, 4:11])
    with pytest.raises(LFShapeError):
        read_lf(tmp_path / "lenslet.png", angular=13)
    with pytest.raises(LFFormatError, match="angular"):
        read_lf(tmp_path / "lenslet.png")


def test_pfm_round_trip(tmp_path, rng):
    d = rng.normal(size=(7, 9)).astype(np.float32)
    write_pfm(tmp_path / "d.pfm", d)
    np.testing.assert_array_equal(read_pfm(tmp_path / "d.pfm"), d)
    # The file stores rows bottom to top, little-endian (negative scale), like HCI's files.
    raw = (tmp_path / "d.pfm").read_bytes()
    assert raw.startswith(b"Pf\n9 7\n-1.0\n")
    np.testing.assert_array_equal(np.frombuffer(raw[-36:], "<f4"), d[0])


def test_bad_inputs_name_the_file(tmp_path, rng):
    cases = {}
    cases["missing"] = tmp_path / "nope.npy"
    (tmp_path / "empty").mkdir()
    cases["empty"] = tmp_path / "empty"
    (tmp_path / "junk.png").write_bytes(b"not an image")
    cases["junk"] = tmp_path / "junk.png"
    (tmp_path / "bad.npy").write_bytes(b"\x93NUMPY garbage")
    cases["bad npy"] = tmp_path / "bad.npy"
    np.save(tmp_path / "wrongshape.npy", np.zeros((4, 4, 3), np.uint8))
    cases["wrong shape"] = tmp_path / "wrongshape.npy"
    (tmp_path / "x.xyz").write_text("?")
    cases["unknown"] = tmp_path / "x.xyz"
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    write_image(mixed / "0_0.png", random_lf(rng, (1, 1, 8, 8, 3))[0, 0])
    write_image(mixed / "0_1.png", random_lf(rng, (1, 1, 8, 9, 3))[0, 0])
    cases["mixed sizes"] = mixed
    notimg = tmp_path / "notimg"
    notimg.mkdir()
    (notimg / "0_0.png").write_bytes(b"\x89PNG broken")
    cases["broken view"] = notimg
    (tmp_path / "bad.mkv").write_bytes(b"\x1a\x45\xdf\xa3 nonsense")
    cases["bad video"] = tmp_path / "bad.mkv"
    (tmp_path / "bad.pfm").write_bytes(b"Pf\n99999999 2\n-1\n")
    for what, path in cases.items():
        with pytest.raises(LFStreamError) as info:
            read_lf(path)
        assert path.name in str(info.value), what
    with pytest.raises(LFStreamError, match="bad.pfm"):
        read_pfm(tmp_path / "bad.pfm")


@pytest.mark.parametrize("crop, flip_u, flip_v", [(None, False, False), (None, True, False), (3, True, True)])
def test_a_mosaic_video_read_frame_by_frame_is_what_load_lf_reads(tmp_path, rng, crop, flip_u, flip_v):
    """open_video_lf applies the crop and flips to each frame as it reads; load_lf reads a
    video through it, and both equal the whole video cropped and flipped afterwards."""
    from lfstream.io import ReadOptions, open_video_lf
    from lfstream.lightfield import crop_views

    video = random_lf(rng, (4, 5, 5, 8, 10, 3))
    write_lf(tmp_path / "clip.mp4", video, fps=12)
    opts = ReadOptions(crop=crop, flip_u=flip_u, flip_v=flip_v, max_frames=3)
    want = crop_views(video[:3], crop) if crop else video[:3]
    want = want[:, ::-1] if flip_u else want
    want = want[:, :, ::-1] if flip_v else want
    lazy = open_video_lf(tmp_path / "clip.mp4", opts)
    assert lazy.count == 3 and lazy.fps == pytest.approx(12)
    frames = list(lazy.frames)
    assert all(f.flags.c_contiguous for f in frames)
    np.testing.assert_array_equal(np.stack(frames), want)
    loaded = load_lf(tmp_path / "clip.mp4", opts)
    assert loaded.lf.flags.c_contiguous
    np.testing.assert_array_equal(loaded.lf, want)


def test_collecting_frames_survives_a_wrong_frame_count(tmp_path):
    """A container's frame count sizes the array up front; fewer or more frames than it
    says still give exactly the frames read."""
    from lfstream.io.video import collect_frames

    frames = [np.full((2, 3), k, np.uint8) for k in range(4)]
    for count in (None, 1, 2, 4, 9):
        np.testing.assert_array_equal(collect_frames(iter(frames), count, tmp_path), np.stack(frames))
    with pytest.raises(LFFormatError, match="no frames"):
        collect_frames(iter([]), 3, tmp_path)


@pytest.mark.parametrize("name", ["clip.mp4", "clip.npy", "folder"])
def test_frame_writer_writes_what_write_lf_writes(tmp_path, rng, name):
    """FrameWriter, one frame at a time, gives the output write_lf gives the whole video
    (a .npy byte for byte; a video or folder that reads back as the same frames)."""
    from lfstream.io import FrameWriter

    video = random_lf(rng, (3, 3, 3, 8, 10, 3))
    with FrameWriter(tmp_path / "a" / name if name == "folder" else tmp_path / name, 3, fps=12) as w:
        for frame in video:
            w.write(frame)
    got = tmp_path / "a" / name if name == "folder" else tmp_path / name
    write_lf(tmp_path / f"whole_{name}", video, fps=12)
    np.testing.assert_array_equal(read_lf(got), video)
    whole = tmp_path / f"whole_{name}"
    if name == "clip.npy":
        assert got.read_bytes() == whole.read_bytes()
    if name == "folder":
        assert sorted(p.relative_to(got) for p in got.rglob("*")) == sorted(p.relative_to(whole) for p in whole.rglob("*"))
    assert not [p for p in tmp_path.rglob(".*")]  # no temporary file left


def test_frame_writer_keeps_nothing_torn(tmp_path, rng):
    """A .npy short of its frame count, an error mid-way or a refused format leave no file;
    Ctrl-C (or ``close(partial=True)``: a damaged stream) keeps a video, .npy or .npz of the
    frames written so far."""
    from lfstream.io import FrameWriter

    video = random_lf(rng, (3, 3, 3, 8, 10, 3))
    with pytest.raises(LFStreamError, match="2 of 3 frames"):
        with FrameWriter(tmp_path / "short.npy", 3) as w:
            w.write(video[0])
            w.write(video[1])
    with pytest.raises(RuntimeError):
        with FrameWriter(tmp_path / "err.mp4") as w:
            w.write(video[0])
            raise RuntimeError("boom")
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(tmp_path / "stopped.mp4", fps=12) as w:
            w.write(video[0])
            w.write(video[1])
            raise KeyboardInterrupt
    np.testing.assert_array_equal(read_lf(tmp_path / "stopped.mp4"), video[:2])
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(tmp_path / "stopped.npy", 3) as w:
            w.write(video[0])
            w.write(video[1])
            raise KeyboardInterrupt
    np.testing.assert_array_equal(np.load(tmp_path / "stopped.npy"), video[:2])  # a valid .npy of two frames
    w = FrameWriter(tmp_path / "damaged.npy", 3)
    w.write(video[0])
    w.close(partial=True)
    np.testing.assert_array_equal(np.load(tmp_path / "damaged.npy", mmap_mode="r"), video[:1])
    with pytest.raises(LFStreamError, match="gif"):
        FrameWriter(tmp_path / "x.gif", 3)
    # a .npz: the archive write_lf writes, byte for byte, holding a frame at a time; Ctrl-C
    # keeps the frames so far, an error nothing (nor its raw frames)
    with FrameWriter(tmp_path / "whole.npz") as w:
        for frame in video:
            w.write(frame)
    write_lf(tmp_path / "ref.npz", video)
    assert (tmp_path / "whole.npz").read_bytes() == (tmp_path / "ref.npz").read_bytes()
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(tmp_path / "stopped.npz") as w:
            w.write(video[0])
            raise KeyboardInterrupt
    np.testing.assert_array_equal(load_lf(tmp_path / "stopped.npz").lf, video[:1])
    with pytest.raises(RuntimeError):
        with FrameWriter(tmp_path / "err.npz") as w:
            w.write(video[0])
            raise RuntimeError("boom")
    (tmp_path / "whole.npz").unlink()
    (tmp_path / "ref.npz").unlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged.npy", "stopped.mp4", "stopped.npy", "stopped.npz"]
    with pytest.raises(LFFileError, match="already exists"):
        FrameWriter(tmp_path / "stopped.mp4")


def test_an_array_file_whose_header_promises_more_than_it_holds_is_refused(tmp_path):
    """A truncated .npy, or a forged header (a shape of petabytes): one LFFormatError naming
    the file and the declared size, before numpy tries to allocate it; the same for the
    light field inside an .npz."""
    import zipfile

    from lfstream.errors import LFFormatError
    from lfstream.io import read_lf

    whole = tmp_path / "whole.npy"
    np.save(whole, np.zeros((3, 3, 8, 8, 3), np.uint8))
    data = whole.read_bytes()
    (tmp_path / "cut.npy").write_bytes(data[:-10])
    header = np.lib.format.header_data_from_array_1_0(np.zeros((1,), np.uint8))
    header["shape"] = (100000, 100000, 100000, 7, 7, 3)
    forged = tmp_path / "forged.npy"
    with open(forged, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, header)
        fh.write(b"\0" * 64)
    with zipfile.ZipFile(tmp_path / "forged.npz", "w") as z:
        z.writestr("lf.npy", forged.read_bytes())
    for name in ("cut.npy", "forged.npy", "forged.npz"):
        with pytest.raises(LFFormatError, match="header declares"):
            read_lf(tmp_path / name)
    assert read_lf(whole).shape == (3, 3, 8, 8, 3)


def _view_video_folder(folder, video, skip=(), sizes=None, frames=None):
    """A folder of one lossless video per view of ``video`` (T, U, V, H, W, 3)."""
    folder.mkdir()
    for u in range(video.shape[1]):
        for v in range(video.shape[2]):
            if (u, v) in skip:
                continue
            clip = video[: (frames or {}).get((u, v), len(video)), u, v]
            if sizes and (u, v) in sizes:
                clip = np.ascontiguousarray(clip[:, : sizes[(u, v)][0], : sizes[(u, v)][1]])
            write_video(folder / f"{u}_{v}.mkv", list(clip))
    return folder


def test_a_folder_of_view_videos_is_read_frame_by_frame(tmp_path, rng, monkeypatch):
    """A camera array's video (one file per view) reads lazily as an LF video: frame by frame
    the same light fields as read whole, crop and flips applied, each view's decoder on
    VIEW_DECODER_THREADS threads; missing views with their mask (allow_missing) or refused; views of different
    sizes or frame counts refused from their containers before any frame is decoded."""
    import lfstream.io.video as video_mod
    from lfstream.errors import LFMissingViewsError
    from lfstream.io import ReadOptions, open_video_lf, reads_lazily
    from lfstream.io.readers import VIEW_DECODER_THREADS

    video = random_lf(rng, (4, 3, 3, 8, 12, 3))
    folder = _view_video_folder(tmp_path / "views", video)
    assert reads_lazily(folder) and not reads_lazily(tmp_path)
    threads = []
    real = video_mod.iter_video_frames

    def spy(path, max_frames=None, threads_=None, **kwargs):
        threads.append(kwargs.get("threads", threads_))
        return real(path, max_frames, **kwargs)

    monkeypatch.setattr("lfstream.io.readers.iter_video_frames", spy)
    assert open_video_lf(folder).count is None  # Matroska keeps no count; counted where asked
    lazy = open_video_lf(folder, count_frames=True)
    assert (lazy.views, lazy.size, lazy.count, lazy.present) == ((3, 3), (8, 12), 4, None)
    np.testing.assert_array_equal(np.stack(list(lazy.frames)), video)
    assert threads == [VIEW_DECODER_THREADS] * 9  # the first open decoded nothing
    np.testing.assert_array_equal(read_lf(folder), video)
    flipped = open_video_lf(folder, ReadOptions(flip_u=True, max_frames=2), count_frames=True)
    assert flipped.count == 2
    np.testing.assert_array_equal(np.stack(list(flipped.frames)), video[:2, ::-1])
    cropped = open_video_lf(folder, ReadOptions(crop=1))
    np.testing.assert_array_equal(np.stack(list(cropped.frames)), video[:, 1:2, 1:2])
    holes = _view_video_folder(tmp_path / "holes", video, skip={(0, 2)})
    with pytest.raises(LFMissingViewsError):
        open_video_lf(holes)
    masked = open_video_lf(holes, ReadOptions(allow_missing=True))
    assert masked.present is not None and not masked.present[0, 2] and masked.present.sum() == 8
    got = np.stack(list(masked.frames))
    assert not got[:, 0, 2].any()
    np.testing.assert_array_equal(np.delete(got.reshape(4, 9, 8, 12, 3), 2, axis=1),
                                  np.delete(video.reshape(4, 9, 8, 12, 3), 2, axis=1))
    np.testing.assert_array_equal(read_lf(holes, return_mask=True)[1], masked.present)
    sized = _view_video_folder(tmp_path / "sized", video, sizes={(1, 1): (8, 10)})
    with pytest.raises(LFShapeError, match="1_1"):
        open_video_lf(sized)
    short = _view_video_folder(tmp_path / "short", video, frames={(2, 0): 3})
    with pytest.raises((LFShapeError, LFFormatError), match="2_0"):
        list(open_video_lf(short, count_frames=True).frames)


def test_a_folder_of_frame_folders_is_read_frame_by_frame(tmp_path, rng, monkeypatch):
    """A video written as one sub-folder of view images per frame (write_lf, lfstream decode
    -o FOLDER) reads lazily: one frame folder at a time, the count from the sub-folders; the
    same light fields as read whole; a frame unlike the first (size, or views missing) is
    refused naming its folder; a folder whose sub-folders are not frames reads as before."""
    import shutil
    from pathlib import Path

    import lfstream.io.readers as readers
    from lfstream.io import ReadOptions, open_video_lf, reads_lazily

    video = random_lf(rng, (4, 2, 3, 6, 8, 3))
    folder = tmp_path / "frames"
    write_lf(folder, video)
    assert reads_lazily(folder)
    reads = []
    real = readers.load_lf

    def spy(path, *a, **k):
        reads.append(Path(path).name)
        return real(path, *a, **k)

    monkeypatch.setattr(readers, "load_lf", spy)
    lazy = open_video_lf(folder, ReadOptions(flip_v=True))
    assert (lazy.count, lazy.views, lazy.size, reads) == (4, (2, 3), (6, 8), ["frame_000000"])
    got = []
    for k, frame in enumerate(lazy.frames):
        assert len(reads) == max(1, k + 1)  # one frame folder read at a time
        got.append(frame)
    np.testing.assert_array_equal(np.stack(got), video[:, :, ::-1])
    monkeypatch.setattr(readers, "load_lf", real)
    np.testing.assert_array_equal(read_lf(folder), video)
    (folder / "frame_000002" / "1_2.png").unlink()
    with pytest.raises(LFMissingViewsError, match="frame_000002"):
        list(open_video_lf(folder).frames)
    with pytest.raises(LFShapeError, match="frame_000002"):  # with its mask: unlike the first frame's
        list(open_video_lf(folder, ReadOptions(allow_missing=True)).frames)
    shutil.copytree(folder, tmp_path / "nested" / "clip")  # a folder holding a video folder: read whole
    assert not reads_lazily(tmp_path / "nested")


def test_a_folder_of_single_frame_npy_files_is_an_lf_video(tmp_path, rng):
    """One .npy a frame reads lazily like frame folders (the same frames as read whole); a
    folder whose .npy files hold clips is read whole as before."""
    from lfstream.io import open_video_lf, reads_lazily

    video = random_lf(rng, (3, 2, 2, 6, 8, 3))
    (tmp_path / "frames").mkdir()
    for t, frame in enumerate(video):
        np.save(tmp_path / "frames" / f"f{t:03d}.npy", frame)
    assert reads_lazily(tmp_path / "frames")
    lazy = open_video_lf(tmp_path / "frames")
    assert lazy.count == 3
    np.testing.assert_array_equal(np.stack(list(lazy.frames)), video)
    np.testing.assert_array_equal(read_lf(tmp_path / "frames"), video)
    (tmp_path / "clips").mkdir()
    np.save(tmp_path / "clips" / "a.npy", video[:2])
    np.save(tmp_path / "clips" / "b.npy", video[2:])
    assert not reads_lazily(tmp_path / "clips")
    np.testing.assert_array_equal(read_lf(tmp_path / "clips"), video)


def _written(tmp_path, video, kind):
    """``video`` written as ``kind``: a file extension, or a folder of view videos, of frame
    folders, of single-frame ``.npy`` files, or of clips read whole (``clips``)."""
    if kind.startswith("."):
        write_lf(tmp_path / f"v{kind}", video)
        return tmp_path / f"v{kind}"
    if kind == "view-videos":
        return _view_video_folder(tmp_path / "views", video)
    folder = tmp_path / kind
    folder.mkdir()
    for k, frame in enumerate(video):
        if kind == "frame-folders":
            write_lf(folder / f"frame_{k:06d}", frame)
        elif kind == "npy-frames":
            np.save(folder / f"frame_{k:06d}.npy", frame)
    if kind == "clips":  # frames 0-2 and 3-5 as two clips: concatenated, then the range
        np.save(folder / "a.npy", video[:3])
        np.save(folder / "b.npy", video[3:])
    return folder


@pytest.mark.parametrize("kind", [".avi", ".mp4", ".mkv", ".npy", ".npz", "view-videos", "frame-folders", "npy-frames",
                                  "clips"])
def test_a_frame_range_reads_the_frames_a_slice_of_the_whole_gives(tmp_path, rng, kind):
    """``first_frame`` (``--first-frame``) with ``max_frames``: load_lf and the lazy reader
    give exactly ``video[first:first + max]`` of every kind of LF video (the count says
    so where the container knows it: not Matroska's); a first frame past the end is one
    LFValueError naming the file, before a frame is decoded where the count is known."""
    from lfstream.errors import LFValueError
    from lfstream.io import ReadOptions, open_lf_frames

    video = random_lf(rng, (6, 3, 3, 8, 12, 3))
    path = _written(tmp_path, video, kind)
    np.testing.assert_array_equal(load_lf(path).lf, video)
    for first, most in ((0, None), (2, None), (2, 3), (5, None), (4, 9)):
        want = video[first:None if most is None else first + most]
        opts = ReadOptions(first_frame=first, max_frames=most)
        np.testing.assert_array_equal(load_lf(path, opts).lf, want)
        frames = open_lf_frames(path, opts)
        assert frames.count in (None, len(want))
        np.testing.assert_array_equal(np.stack(list(frames.frames)), want)
    with pytest.raises(LFValueError, match="first_frame 6") as info:
        load_lf(path, ReadOptions(first_frame=6))
    assert path.name in str(info.value)
    np.testing.assert_array_equal(read_lf(path, first_frame=3, max_frames=2), video[3:5])


def test_frames_skipped_in_an_intra_only_video_are_not_decoded():
    """An intra-only codec's packets before the first frame are read and dropped without
    decoding (an empty packet, a repeated frame in AVI, counts as none); an inter codec's
    are decoded (they predict the later ones), and only the frames from the first on come
    out."""
    from types import SimpleNamespace

    from lfstream.io.video import _decoded_from

    decoded = []

    def packet(k, size=1):  # an empty packet decodes to no frame (as FFmpeg's)
        return SimpleNamespace(size=size, decode=lambda: decoded.append(k) or ([f"frame {k}"] if size else []))

    packets = [packet(0), packet(1), packet("empty", 0), packet(2), packet(3), packet("flush", 0)]

    def container(intra):
        return SimpleNamespace(demux=lambda stream: iter(packets),
                               decode=lambda stream: (p for q in packets for p in q.decode()))

    stream = SimpleNamespace(codec_context=SimpleNamespace(codec=SimpleNamespace(intra_only=True)))
    assert list(_decoded_from(container(True), stream, 2)) == ["frame 2", "frame 3"]
    assert decoded == ["empty", 2, 3, "flush"]
    decoded.clear()
    stream.codec_context.codec.intra_only = False
    assert list(_decoded_from(container(False), stream, 2)) == ["frame 2", "frame 3"]
    assert decoded == [0, 1, "empty", 2, 3, "flush"]


def test_a_frame_range_of_a_single_light_field_is_refused(tmp_path, rng):
    from lfstream.errors import LFValueError
    from lfstream.io import ReadOptions

    write_lf(tmp_path / "still.npy", random_lf(rng, (3, 3, 8, 8, 3)))
    assert load_lf(tmp_path / "still.npy", ReadOptions(max_frames=1)).lf.shape == (3, 3, 8, 8, 3)
    with pytest.raises(LFValueError, match="still.npy: first_frame 1: a single light field"):
        load_lf(tmp_path / "still.npy", ReadOptions(first_frame=1))
    for bad in (-1, 1.5, True, "2"):
        with pytest.raises(LFValueError, match="first_frame"):
            ReadOptions(first_frame=bad)
