"""Stream sources (lfstream.stream.sources)."""

import numpy as np
import pytest

from lfstream import load_lf, write_lf
from lfstream.io import ReadOptions
from lfstream.stream.sources import file_source
from tests.conftest import random_lf


@pytest.mark.parametrize("opts", [ReadOptions(flip_u=True), ReadOptions(flip_v=True, crop=3), ReadOptions(max_frames=2)])
def test_a_video_streams_frame_by_frame_with_the_reading_options(tmp_path, rng, opts):
    """The stream reads a mosaic video lazily with the same crop and flips as load_lf (the
    flips were once dropped on this path: ``lfstream stream clip.mp4 --flip-u`` streamed
    the views in the file's order)."""
    video = random_lf(rng, (3, 5, 5, 8, 10, 3))
    write_lf(tmp_path / "clip.mp4", video, fps=15)
    source = file_source(tmp_path / "clip.mp4", opts)
    want = load_lf(tmp_path / "clip.mp4", opts).lf
    assert source.total == len(want) and source.fps == pytest.approx(15)
    np.testing.assert_array_equal(np.stack(list(source.frames)), want)


def test_an_lfs_streams_frame_by_frame_as_it_decodes(tmp_path, monkeypatch):
    """An ``.lfs`` input is decoded one frame at a time as ``lfstream.decode`` decodes it
    (the hint's parallax), with the reading options applied; the whole stream is not decoded
    before the first frame is handed on."""
    import lfstream
    import lfstream.codec.api as decoder
    from lfstream.synth import synth_clip

    clip = synth_clip(3, 5, (32, 40), seed=6).lf
    data = lfstream.encode(clip, fps=15)
    (tmp_path / "clip.lfs").write_bytes(data)
    decoded = lfstream.decode(data)
    source = file_source(tmp_path / "clip.lfs", ReadOptions(flip_v=True, max_frames=2))
    assert source.total == 2 and source.fps == pytest.approx(15)
    calls = []
    real = decoder.iter_decode
    monkeypatch.setattr(decoder, "iter_decode", lambda *a, **k: calls.append(1) or real(*a, **k))
    first = next(source.frames)
    np.testing.assert_array_equal(first, decoded[0, :, ::-1])
    np.testing.assert_array_equal(next(source.frames), decoded[1, :, ::-1])
    assert next(source.frames, None) is None and calls == [1]
