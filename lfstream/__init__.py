"""lfstream: light-field video compression, reconstruction and refocusing.

Conventions (see :mod:`lfstream.lightfield`): a frame is ``(U, V, H, W, 3)``, a video
``(T, U, V, H, W, 3)``; the centre view is ``(U // 2, V // 2)``; uint8 at the boundaries,
float32 in ``[0, 1]`` inside; disparity follows the HCI benchmark's sign.

The packages follow the data flow: :mod:`lfstream.io` (read and write light fields) ->
:mod:`lfstream.codec` (encode, the ``.lfs`` bitstream, decode) -> :mod:`lfstream.refocus`
(focal stacks) -> :mod:`lfstream.stream` (the pipeline and its transports), with
:mod:`lfstream.models` (the networks) beside the decoder and refocusing, and
:mod:`lfstream.cli` on top. ``import lfstream`` imports neither torch nor numba.
"""

from lfstream import errors

# the exception hierarchy is public API; __all__ takes the names from errors.__all__
from lfstream.errors import (  # noqa: F401 - public, listed through errors.__all__
    BitstreamError,
    LFFileError,
    LFFormatError,
    LFMissingViewsError,
    LFShapeError,
    LFStreamError,
    LFValueError,
    WeightsError,
)
from lfstream.io import ReadOptions, load_lf, read_lf, read_pfm, write_lf, write_pfm
from lfstream.version import __version__


def __getattr__(name: str):
    # The codec is imported only when asked for, so `import lfstream` stays light.
    if name in ("encode", "decode"):
        from lfstream import codec

        return getattr(codec, name)
    if name == "batch":
        from lfstream.cluster import batch

        return batch
    raise AttributeError(f"module 'lfstream' has no attribute {name!r}")


__all__ = [
    "__version__",
    *errors.__all__,
    "ReadOptions",
    "read_lf",
    "load_lf",
    "write_lf",
    "read_pfm",
    "write_pfm",
    "encode",
    "decode",
    "batch",
]
