"""Frame-level regression testing for light fields and LF videos.

- :func:`assert_lf_close`: an assertion for users' own tests (pytest needs no plugin).
- :mod:`~lfstream.testing.compare`: :func:`compare` two inputs frame by frame against
  :class:`Thresholds` (``lfstream compare``).
- :mod:`~lfstream.testing.golden`: golden files of per-frame digests and metrics
  (``lfstream golden record`` / ``check``).
- :mod:`~lfstream.testing.html`: the self-contained HTML report (``lfstream compare --html``).
"""

from lfstream.testing.assertions import assert_lf_close
from lfstream.testing.compare import (
    SCOPES,
    ComparisonReport,
    FrameMetrics,
    FrameResult,
    Thresholds,
    compare,
    compare_report,
    frame_metrics,
)

__all__ = ["assert_lf_close", "compare", "compare_report", "frame_metrics", "Thresholds", "FrameMetrics",
           "FrameResult", "ComparisonReport", "SCOPES"]
