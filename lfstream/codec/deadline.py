"""A deadline for third-party encoders, so that a library that deadlocks cannot hang lfstream.

Why: SVT-AV1 (4.1.0, inside PyAV) was seen once to block forever while flushing a residual
sequence (``avcodec_receive_packet`` -> ``svt_av1_enc_get_packet``, every encoder thread
waiting on a semaphore, no CPU used); a re-run of the same input finished normally, as the
encoder trackers report for such intermittent hangs. PyAV releases the GIL around
``avcodec_send_frame``/``avcodec_receive_packet``, so a call made on a worker thread can be
waited for with a timeout: :func:`call_with_deadline` runs the whole encode there, and when
it has not returned in time abandons that thread (blocked in C, it uses no CPU; it is a
daemon, so it does not keep the process alive) and runs the encode again from the start on
a fresh encoder. Encoders are deterministic, so a retry gives the bytes the first attempt
would have given. After the last attempt it raises :class:`EncoderStalledError`.

Deadlines are generous on purpose (:func:`encoder_deadline`: a minute plus 2 µs per coded
pixel, many times what SVT-AV1 needs): a deadlock is
forever, and a slow machine must never see a false alarm.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TypeVar

from lfstream.errors import EncoderStalledError

T = TypeVar("T")

#: Seconds every encode is allowed before the per-pixel allowance.
BASE_DEADLINE_S = 60.0
#: Seconds allowed per coded pixel: several times what SVT-AV1 preset 8 and x265 medium need
#: on a 2-core CPU, so only a hung encoder reaches it.
DEADLINE_S_PER_PIXEL = 2e-6
#: Attempts before giving up (the first plus one retry on a fresh encoder).
ATTEMPTS = 2

_log = logging.getLogger("lfstream")


def encoder_deadline(pixels: int) -> float:
    """Seconds to wait for an encode of ``pixels`` coded pixels (all frames together)."""
    return BASE_DEADLINE_S + DEADLINE_S_PER_PIXEL * max(int(pixels), 0)


def _run_into(fn: Callable[[], object], outcome: dict[str, object]) -> None:
    try:
        outcome["value"] = fn()
    except BaseException as exc:  # handed to the waiting caller, who re-raises it
        outcome["error"] = exc


def call_with_deadline(fn: Callable[[], T], timeout_s: float, what: str, attempts: int = ATTEMPTS) -> T:
    """Runs ``fn()`` on a daemon thread and returns its result, re-running it from the start
    when it has not returned within ``timeout_s``.

    ``fn`` must be self-contained (create its own encoder, read only its inputs), so that an
    abandoned attempt cannot disturb the next one. Exceptions ``fn`` raises propagate
    unchanged; KeyboardInterrupt reaches the caller while it waits.

    Raises:
        EncoderStalledError: no attempt returned in time (names ``what`` and the deadline).
    """
    if timeout_s <= 0 or attempts < 1:
        raise ValueError(f"call_with_deadline: timeout_s > 0 and attempts >= 1, got {timeout_s}, {attempts}")
    for attempt in range(1, attempts + 1):
        outcome: dict[str, object] = {}

        # each attempt writes only into its own dict (bound as an argument, not the loop
        # variable): an abandoned attempt that returns late cannot overwrite a later one
        worker = threading.Thread(target=_run_into, args=(fn, outcome), name=f"lfstream-{what}-{attempt}",
                                  daemon=True)
        worker.start()
        worker.join(timeout_s)
        if not worker.is_alive():
            if "error" in outcome:
                raise outcome["error"]  # type: ignore[misc]
            return outcome["value"]  # type: ignore[return-value]
        _log.warning("%s: no result after %.0f s (attempt %d of %d); abandoning that encoder",
                     what, timeout_s, attempt, attempts)
    raise EncoderStalledError(f"{what}: the encoder did not finish within {timeout_s:.0f} s "
                              f"({attempts} attempts; a third-party encoder deadlock)")


__all__ = ["BASE_DEADLINE_S", "DEADLINE_S_PER_PIXEL", "ATTEMPTS", "EncoderStalledError", "encoder_deadline",
           "call_with_deadline"]
