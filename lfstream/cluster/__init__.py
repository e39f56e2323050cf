"""Beyond one machine: batch encoding and decoding of LF video collections, in this process
or on a Ray cluster (:func:`batch`, also ``lfstream.batch`` and ``lfstream batch``).

- :mod:`~lfstream.cluster.jobs`: frame groups and the deterministic functions that encode
  or decode one.
- :mod:`~lfstream.cluster.run`: :func:`batch`, the engines (local, Ray) and the report.

Ray is an optional extra (``pip install 'lfstream[ray]'``), imported only by
``engine="ray"``.
"""

from lfstream.cluster.jobs import DecodeOptions, EncodeOptions
from lfstream.cluster.run import ENGINES, MODES, BatchReport, FileResult, batch

__all__ = ["batch", "BatchReport", "FileResult", "EncodeOptions", "DecodeOptions", "ENGINES", "MODES"]
