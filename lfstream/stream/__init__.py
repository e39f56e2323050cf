"""Streaming: Producer -> Encoder -> Transport -> Decoder -> Refocus -> Sink.

- :mod:`~lfstream.stream.config`: :class:`StreamConfig` and its choices and ranges.
- :mod:`~lfstream.stream.sources`: the built-in synthetic clip, LF files and videos.
- :mod:`~lfstream.stream.stages`: one class per stage, each owning its statistics.
- :mod:`~lfstream.stream.transport`: in-process, ``.lfs`` file and TCP channels.
- :mod:`~lfstream.stream.refocuser`, :mod:`~lfstream.stream.sinks`: focal stacks and files.
- :mod:`~lfstream.stream.report`: typed statistics and the run's summary.
- :mod:`~lfstream.stream.pipeline`: :class:`Pipeline` wires them with threads and queues.
"""

from lfstream.stream.config import REFOCUS_MODES, SAVE_KINDS, TRANSPORTS, StreamConfig
from lfstream.stream.pipeline import Pipeline, PipelineError
from lfstream.stream.refocuser import Refocuser
from lfstream.stream.report import write_summary
from lfstream.stream.sinks import Sink
from lfstream.stream.sources import Source, file_source, render_builtin_clip, synthetic_source

__all__ = ["StreamConfig", "Pipeline", "PipelineError", "Refocuser", "Sink", "Source", "synthetic_source",
           "render_builtin_clip", "file_source", "write_summary", "REFOCUS_MODES", "TRANSPORTS", "SAVE_KINDS"]
