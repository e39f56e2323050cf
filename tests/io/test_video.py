"""The video writer's conversion and low-delay mode (lfstream.io.video)."""

import av
import cv2
import numpy as np
import pytest

from lfstream.errors import LFValueError
from lfstream.io.video import VideoWriter, iter_video_frames, rgb_to_video_i420


def _smooth_rgb(rng, h, w):
    return cv2.GaussianBlur(rng.integers(0, 256, (h, w, 3), dtype=np.uint8), (9, 9), 3)


def _swscale_i420(img):
    return av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="rgb24").reformat(format="yuv420p").to_ndarray()


def _psnr(a, b):
    return 10 * np.log10(255.0**2 / np.mean((a.astype(np.float64) - b) ** 2))


@pytest.mark.parametrize("h, w", [(64, 90), (34, 48)])  # half heights even and odd
def test_video_i420_matches_swscale(rng, h, w):
    img = _smooth_rgb(rng, h, w)
    ours, ref = rgb_to_video_i420(img).astype(int), _swscale_i420(img).astype(int)
    assert ours.shape == ref.shape == (h * 3 // 2, w)
    # luma within one level; chroma (2x2 means, as swscale's) within two, 0.5 on average
    assert np.abs(ours[:h] - ref[:h]).max() <= 1
    assert np.abs(ours[h:] - ref[h:]).max() <= 2 and np.abs(ours[h:] - ref[h:]).mean() < 0.5
    # and the player's inverse (swscale's) brings it back as close as swscale's own round trip
    back = av.VideoFrame.from_ndarray(rgb_to_video_i420(img), format="yuv420p").to_ndarray(format="rgb24")
    own = av.VideoFrame.from_ndarray(_swscale_i420(img), format="yuv420p").to_ndarray(format="rgb24")
    assert _psnr(img, back) >= _psnr(img, own) - 0.1


def test_video_i420_pads_by_edge_replication(rng):
    img = _smooth_rgb(rng, 63, 91)
    planes = rgb_to_video_i420(img, (64, 92))
    padded = cv2.copyMakeBorder(img, 0, 1, 0, 1, cv2.BORDER_REPLICATE)
    np.testing.assert_array_equal(planes, rgb_to_video_i420(padded))
    for size in [(63, 92), (62, 92), (64, 91)]:
        with pytest.raises(LFValueError, match="even size"):
            rgb_to_video_i420(img, size)


@pytest.mark.parametrize("low_delay, fast_search", [(False, False), (True, False), (True, True)])
def test_low_delay_writer_keeps_up_and_round_trips(tmp_path, rng, low_delay, fast_search):
    base = _smooth_rgb(rng, 75, 100)
    frames = [np.roll(base, 2 * k, axis=1) for k in range(8)]
    path = tmp_path / f"clip_{low_delay}_{fast_search}.mp4"
    w = VideoWriter(path, lossless=False, crf=17, preset="veryfast", threads=1, low_delay=low_delay,
                    fast_search=fast_search)
    for f in frames:
        w.write(f)
    in_flight = len(frames) - w.packets
    w.close()
    # x264's default lookahead holds every one of 8 frames back until close; low delay
    # emits all but one or two as they come
    assert in_flight <= 2 if low_delay else in_flight >= 6
    assert w.packets == len(frames)
    # x264 writes its settings into the stream (a user-data SEI): the options reached it
    settings = path.read_bytes()
    assert (b" rc_lookahead=1 " in settings and b" bframes=1 " in settings) == low_delay
    assert (b" me=dia " in settings and b" subme=1 " in settings) == fast_search
    back = list(iter_video_frames(path))
    assert len(back) == len(frames)
    assert min(_psnr(a, b) for a, b in zip(frames, back)) > 35.0  # crf 17 of a noisy texture: ~37-38 dB


def _exp_golomb(bits: str, pos: int) -> tuple[int, int]:
    """An unsigned Exp-Golomb code at ``pos`` of a bit string: (value, next position)."""
    zeros = 0
    while bits[pos + zeros] == "0":
        zeros += 1
    end = pos + 2 * zeros + 1
    return int(bits[pos + zeros:end], 2) - 1, end


def _entropy_coding_flags(path) -> list[int]:
    """``entropy_coding_mode_flag`` of every picture parameter set in an MP4's avcC record
    (0: CAVLC, 1: CABAC; ITU-T H.264 7.3.2.2: pps_id ue(v), sps_id ue(v), then the flag)."""
    with av.open(str(path)) as container:
        avcc = bytes(container.streams.video[0].codec_context.extradata)
    pos = 6
    for _ in range(avcc[5] & 0x1F):  # the SPS records
        pos += 2 + int.from_bytes(avcc[pos:pos + 2], "big")
    flags = []
    for _ in range(avcc[pos]):
        n = int.from_bytes(avcc[pos + 1:pos + 3], "big")
        nal = avcc[pos + 3:pos + 3 + n]
        assert nal[0] & 0x1F == 8  # a picture parameter set
        bits = "".join(f"{b:08b}" for b in nal[1:8])
        _, p = _exp_golomb(bits, 0)
        _, p = _exp_golomb(bits, p)
        flags.append(int(bits[p]))
        pos += 2 + n
    return flags


def test_lossless_mp4_is_exact_and_coded_for_quick_reading(tmp_path, rng):
    """The lossless MP4 mosaic is RGB bit for bit and CAVLC-coded (x264's fastdecode): CABAC
    made reading a 7x7x375x540 mosaic cost 438 ms of CPU a frame against 149."""
    frames = [_smooth_rgb(rng, 48, 64) for _ in range(3)]
    path = tmp_path / "lossless.mp4"
    with VideoWriter(path, lossless=True) as w:
        for f in frames:
            w.write(f)
    for got, want in zip(iter_video_frames(path), frames):
        np.testing.assert_array_equal(got, want)
    assert _entropy_coding_flags(path) == [0]
    with VideoWriter(tmp_path / "cabac.mp4", lossless=False, crf=17, preset="veryfast") as w:  # the check can fail
        w.write(frames[0])
    assert _entropy_coding_flags(tmp_path / "cabac.mp4") == [1]


@pytest.mark.parametrize("ext, codec", [(".avi", "utvideo"), (".nut", "utvideo"), (".mkv", "ffv1"), (".mp4", "h264"),
                                        (".webm", "vp9")])
def test_lossless_containers_code_their_codec_bit_exactly(tmp_path, rng, ext, codec):
    """Each lossless container holds the codec LOSSLESS_CODECS names (Ut Video in .avi and
    .nut, the quick one to read; FFV1 in .mkv; x264 RGB in .mp4; VP9 in .webm, which holds
    no x264: writing it raised PyAV's ValueError), its frames RGB bit for bit at an odd size,
    with the view grid in its metadata (read back as a light field)."""
    from lfstream.io import read_lf, write_lf

    lf = np.stack([_smooth_rgb(rng, 21, 35) for _ in range(2 * 3)]).reshape(1, 2, 3, 21, 35, 3)
    lf = np.concatenate([lf, lf[..., ::-1, :]])  # two frames
    path = tmp_path / f"clip{ext}"
    write_lf(path, lf)
    with av.open(str(path)) as container:
        assert container.streams.video[0].codec_context.name == codec
    np.testing.assert_array_equal(read_lf(path), lf)


def test_lossy_webm_plays_back_close_and_a_gif_is_no_light_field(tmp_path, rng):
    """A lossy .webm is VP9 yuv420p (an odd size padded and cropped back), close to its
    frames; a light field is not written as a .gif (a 256-colour image, not read back as one):
    refused in one line by write_lf and FrameWriter instead of made a folder of that name."""
    from lfstream.errors import LFValueError
    from lfstream.io import FrameWriter, write_lf

    frames = [_smooth_rgb(rng, 47, 61) for _ in range(3)]
    path = tmp_path / "lossy.webm"
    with VideoWriter(path, lossless=False, crf=20) as w:
        for f in frames:
            w.write(f)
    with av.open(str(path)) as container:
        assert container.streams.video[0].codec_context.name == "vp9"
    back = list(iter_video_frames(path))
    assert [b.shape for b in back] == [f.shape for f in frames]
    assert min(_psnr(a, b) for a, b in zip(frames, back)) > 35.0
    lf = np.zeros((2, 2, 8, 8, 3), np.uint8)
    for write in (lambda p: write_lf(p, lf), lambda p: FrameWriter(p)):
        with pytest.raises(LFValueError, match="gif"):
            write(tmp_path / "lf.gif")
    assert not (tmp_path / "lf.gif").exists()


_WRITE_SCRIPT = """
import sys
import numpy as np
from lfstream.io import VideoWriter
from lfstream.synth import synth_clip
# moving layers with sensor noise: content on which the lossy writer's bytes used to vary
frames = [np.ascontiguousarray(f[1, 1]) for f in synth_clip(12, 3, (150, 200), seed=4, noise=2.0).lf]
for name, lossless in (("lossy.mp4", False), ("lossless.mp4", True), ("ffv1.mkv", True), ("utvideo.avi", True),
                       ("lossy.webm", False)):
    with VideoWriter(sys.argv[1] + "/" + name, lossless=lossless) as w:
        for f in frames:
            w.write(f)
"""


def test_the_same_frames_give_the_same_file_whatever_the_heap_holds(tmp_path):
    """Two processes write the same frames with the allocator filling memory with different
    bytes (MALLOC_PERTURB_): every file is the same byte for byte. Before: x264's B-frames
    behind its full lookahead read uninitialised memory (lossy .mp4), and Matroska wrote
    random UIDs (.mkv)."""
    import os
    import subprocess
    import sys

    outs = []
    for perturb in ("165", "33"):
        out = tmp_path / perturb
        out.mkdir()
        env = {**os.environ, "MALLOC_PERTURB_": perturb}
        subprocess.run([sys.executable, "-c", _WRITE_SCRIPT, str(out)], check=True, env=env, timeout=120)
        outs.append(out)
    for name in ("lossy.mp4", "lossless.mp4", "ffv1.mkv", "utvideo.avi", "lossy.webm"):
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name


def test_a_later_first_frame_of_an_inter_coded_video_starts_at_its_key_frame(tmp_path, monkeypatch):
    """An H.264 video with a key frame every 5 frames and B-frames (display order differs
    from decode order): from every first frame the frames are exactly the whole decode's;
    from frame 7 on the reader seeks to the key frame at frame 5 and decodes 2 frames it
    drops, not 7 (counted); before the second key frame it decodes from the start."""
    import lfstream.io.video as video_mod

    path = tmp_path / "gop.mp4"
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        stream.options = {"g": "5", "bf": "3", "crf": "30"}
        for i in range(17):
            img = np.full((48, 64, 3), 12 * i, np.uint8)
            img[:, 3 * i:3 * i + 3] = 255
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    whole = list(iter_video_frames(path))
    assert len(whole) == 17
    for first in range(17):
        part = list(iter_video_frames(path, first_frame=first))
        assert len(part) == 17 - first and all(np.array_equal(a, b) for a, b in zip(part, whole[first:])), first
    key, target = video_mod._key_frame_before(path, 7)
    assert key < target and video_mod._key_frame_before(path, 3) is None
    decoded = []
    real_open = video_mod._open_container

    class Counting:  # the container, counting the frames its decoder gives
        def __init__(self, container):
            self.container = container

        def __enter__(self):
            self.container.__enter__()
            return self

        def __exit__(self, *exc):
            return self.container.__exit__(*exc)

        def __getattr__(self, name):
            return getattr(self.container, name)

        def decode(self, stream):
            for frame in self.container.decode(stream):
                decoded.append(frame.pts)
                yield frame

    monkeypatch.setattr(video_mod, "_open_container", lambda p: Counting(real_open(p)))
    assert len(list(iter_video_frames(path, first_frame=7, max_frames=2))) == 2
    assert 2 < len(decoded) <= 4  # frames 5 and 6 at most dropped, 7 and 8 kept (not frames 0-6)
    decoded.clear()
    assert len(list(iter_video_frames(path, first_frame=3, max_frames=2))) == 2
    assert len(decoded) == 5
