"""The seed's Depth-Net path (lfstream.models.centre_depth): the network, and the decoder that
predicts each frame's disparity from its restored centre view alone."""

from __future__ import annotations

import io

import numpy as np
import pytest
import torch

import lfstream
from lfstream.codec.bitstream import iter_packets, read_header
from lfstream.codec.decoder import Decoder
from lfstream.models.centre_depth import CentreDepthConfig, CentreDepthNet, predict_centre_disparity
from lfstream.synth import synth_clip


@pytest.fixture(scope="module")
def stream() -> tuple[np.ndarray, bytes]:
    lf = synth_clip(1, 5, (48, 64), seed=8).lf[0]
    return lf, lfstream.encode(lf, quality=60, depth_hint=False, preset="fast")


def _decode(data: bytes, **kw) -> np.ndarray:
    fh = io.BytesIO(data)
    header = read_header(fh)
    return Decoder(header, hance="off", **kw).decode_packet(next(iter_packets(fh, header))).lf


@pytest.mark.parametrize("size", [(37, 53), (64, 64)])
def test_the_network_gives_one_bounded_map_at_any_size(size):
    torch.manual_seed(0)
    net = CentreDepthNet(CentreDepthConfig(max_disparity=2.0))
    for p in net.head.parameters():  # a trained head: anything but zero
        torch.nn.init.normal_(p, std=1.0)
    out = net(torch.rand(2, 3, *size))
    assert out.shape == (2, 1, *size) and torch.isfinite(out).all() and out.abs().max() <= 2.0
    assert torch.equal(CentreDepthNet()(torch.rand(1, 3, *size)), torch.zeros(1, 1, *size))  # untrained: flat


def test_an_untrained_seed_network_decodes_exactly_the_flat_light_field(stream):
    """On a stream without a hint, ``depth="net"`` runs the seed's path: the disparity from the
    centre view, then the warp the hint goes through. A network that predicts zero gives
    the flat decode byte for byte (every view the centre view)."""
    _, data = stream
    np.testing.assert_array_equal(_decode(data, depth="net", depth_net=CentreDepthNet()), _decode(data, depth="flat"))


def test_the_seed_path_warps_by_the_predicted_disparity(stream, monkeypatch):
    """A network that predicts the scene's disparity decodes the views as the hint's warp of
    the same disparity would: the same warp, fed by the network instead of the hint."""
    from lfstream.codec.warp import warp_views

    lf, data = stream

    class Constant(CentreDepthNet):
        def forward(self, centre):
            return torch.full((centre.shape[0], 1, *centre.shape[2:]), 0.75)

    got = _decode(data, depth="net", depth_net=Constant())
    flat = _decode(data, depth="flat")
    centre = flat[2, 2]
    np.testing.assert_array_equal(got, warp_views(centre, np.full(centre.shape[:2], 0.75, np.float32), (5, 5)))
    assert not np.array_equal(got, flat)


def test_predictions_are_finite_whatever_the_network_says():
    class Broken(CentreDepthNet):
        def forward(self, centre):
            return torch.full((centre.shape[0], 1, *centre.shape[2:]), float("nan"))

    d = predict_centre_disparity(np.zeros((2, 8, 8, 3), np.uint8), Broken())
    assert d.shape == (2, 8, 8) and np.all(d == 0)


def test_the_shipped_seed_network_decodes_a_stream_without_a_hint(stream, tmp_path, capsys):
    """The CLI and the API run the seed's path on a stream encoded with ``--no-depth-hint``."""
    from lfstream.cli import main

    lf, data = stream
    rec = lfstream.decode(data, depth="net", hance="on")
    assert rec.shape == (1, *lf.shape) and rec.dtype == np.uint8
    src = tmp_path / "seed.lfs"
    src.write_bytes(data)
    assert main(["decode", str(src), "-o", str(tmp_path / "out.npy"), "--depth", "net", "--json"]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), lfstream.decode(data, depth="net")[0])


def test_auto_decodes_a_hint_stream_as_the_bare_hint_and_a_hintless_one_flat():
    """``depth="auto"`` never runs a Depth-Net: a stream with a hint decodes exactly as
    ``depth="hint"`` (the refiner was measured below the hint on held-out scenes) and one
    without exactly as ``depth="flat"`` (the seed's network loses on held-out scenes,
    docs/networks.md)."""
    lf = synth_clip(1, 5, (48, 64), seed=9).lf[0]
    hinted = lfstream.encode(lf, quality=60, preset="fast")
    bare = lfstream.encode(lf, quality=60, depth_hint=False, preset="fast")
    np.testing.assert_array_equal(lfstream.decode(hinted, depth="auto"), lfstream.decode(hinted, depth="hint"))
    np.testing.assert_array_equal(lfstream.decode(bare, depth="auto"), lfstream.decode(bare, depth="flat"))
