"""The lfstream codec (seed chapter 3): JPEG centre view + depth-based reconstruction.

Data flow, one module per step:

- :mod:`~lfstream.codec.encoder`: the frame -> a :class:`~lfstream.codec.bitstream.Packet`
  (the centre view by :mod:`~lfstream.codec.centre.jpeg` or, in the ``balanced``/``best`` presets,
  as an AV1 key frame by :mod:`~lfstream.codec.centre.av1`; the depth hint by
  :mod:`~lfstream.codec.hint`, per-view gains by :mod:`~lfstream.codec.gains`; on request
  the JPEG-Hance strength map by :mod:`~lfstream.codec.centre.hance`).
- :mod:`~lfstream.codec.bitstream`: the ``.lfs`` container (header, packets, limits, CRCs).
- :mod:`~lfstream.codec.decoder`: packet -> light field (JPEG-Hance where it helps,
  disparity from the hint, flat or Depth-Net, the occlusion-aware warp of
  :mod:`~lfstream.codec.warp.cpu`, the gains).
- :mod:`~lfstream.codec.stream_encoder`: one stream's encoder frame by frame (the first frame's
  choice, the encoder, the budget the later frames follow), behind every front end.
- :mod:`~lfstream.codec.api`: the entry points (encode, decode, iter_decode, decode_file).
- :mod:`~lfstream.codec.rate`: rate control (preset, quality, hint precision for a bpp).
- :mod:`~lfstream.codec.baseline`: the HEVC/AV1 pseudo-sequence the codec is judged against.

Importing this package does not import torch or compile kernels; the networks and the
numba warp load when first used.
"""

from lfstream.codec.api import decode, decode_file, encode, iter_decode
from lfstream.codec.bitstream import Limits, Packet, StreamHeader
from lfstream.codec.centre.jpeg import QUALITY_RANGE, decode_jpeg, encode_jpeg, jpeg_roundtrip
from lfstream.codec.decoder import (
    BATCH_RANGE,
    DEPTH_MODES,
    HANCE_MAX_QUALITY,
    HANCE_MODES,
    DecodedFrame,
    Decoder,
)
from lfstream.codec.encoder import ENCODER_NAME, Encoder, EncodeStats, frames_of
from lfstream.codec.hint import HintOptions
from lfstream.codec.stream_encoder import CodingOptions, StreamEncoder, encode_file

__all__ = [
    "BATCH_RANGE",
    "DEPTH_MODES",
    "HANCE_MODES",
    "HANCE_MAX_QUALITY",
    "QUALITY_RANGE",
    "ENCODER_NAME",
    "Limits",
    "Packet",
    "StreamHeader",
    "HintOptions",
    "Encoder",
    "EncodeStats",
    "Decoder",
    "DecodedFrame",
    "encode",
    "decode",
    "iter_decode",
    "decode_file",
    "encode_file",
    "StreamEncoder",
    "CodingOptions",
    "frames_of",
    "encode_jpeg",
    "decode_jpeg",
    "jpeg_roundtrip",
]
