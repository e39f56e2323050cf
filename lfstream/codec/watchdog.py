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

import contextlib
import logging
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
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


_background: ThreadPoolExecutor | None = None
_background_lock = threading.Lock()
_WORKER_PREFIX = "lfstream-worker"  # the workers' thread names (on_worker_thread)


def in_background(fn: Callable[[], T]) -> Future:
    """``fn()`` started now on lfstream's worker threads (two, created on first use and
    kept): two independent parts of one frame's work overlapped on a multi-core machine
    (OpenCV, zstd and numba kernels release the GIL). Kept threads, not a thread per call:
    a numba parallel kernel called from a new thread starts a new OpenMP team, which cost
    more than the overlap saved.

    Only for short work that cannot block (a third-party encoder goes through
    :func:`call_with_deadline`)."""
    global _background
    with _background_lock:
        if _background is None:
            _background = ThreadPoolExecutor(max_workers=2, thread_name_prefix=_WORKER_PREFIX)
    return _background.submit(fn)


_lane: ThreadPoolExecutor | None = None
_LANE_NAME = _WORKER_PREFIX + "-lane"
#: At most this many cores: :func:`beside` queues its jobs on one lane thread.
LANE_MAX_CORES = 2


def _cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        return os.cpu_count() or 1


def beside(fn: Callable[[], T]) -> Future:
    """``fn()`` started beside the calling thread's critical path: the parts of one frame's
    work that only its end needs (the encoder's centre view and post-filter choice, the view
    axes detection). On a machine of at most :data:`LANE_MAX_CORES` cores they queue on one
    lane thread, one after another, instead of taking two more threads beside the caller's
    parallel kernels (on two cores, two extra threads cost more wall and CPU time than the
    one lane, for the same bytes). Elsewhere
    :func:`in_background`. Called on the lane itself, ``fn`` runs before this returns.

    The jobs keep numba's thread count: a lane job on one thread (:func:`single_numba_thread`)
    beside the prediction checks on one thread each left the caller's OpenMP team the only
    one in the process, and libgomp then spins its idle worker as long as on an idle machine
    (it throttles the spin only where it runs more threads than cores): 31-34 ms of CPU an
    encode instead of 20, 16-17 ms of wall instead of 11-12."""
    global _lane
    if _cores() > LANE_MAX_CORES:
        return in_background(fn)
    if threading.current_thread().name.startswith(_LANE_NAME):
        return completed(fn())
    with _background_lock:
        if _lane is None:
            _lane = ThreadPoolExecutor(max_workers=1, thread_name_prefix=_LANE_NAME)
    return _lane.submit(fn)


def on_worker_thread() -> bool:
    """Whether the caller runs on one of :func:`in_background`'s worker threads, where it
    must not submit more work and wait for it (two busy workers waiting on each other's
    queue would never finish)."""
    return threading.current_thread().name.startswith(_WORKER_PREFIX)


def completed(value: T) -> Future:
    """A future that already holds ``value``: the result of work done on the calling thread
    where a caller takes either that or :func:`in_background`'s future."""
    done: Future = Future()
    done.set_result(value)
    return done


@contextlib.contextmanager
def single_numba_thread() -> Iterator[None]:
    """numba's parallel kernels called from this thread run on it alone inside the block (the
    count is per thread: other threads keep theirs; restored afterwards). For work run beside
    other work on a 2-core machine: two calls that would each spread over both cores then
    take one core each instead of taking turns on both (an OpenMP team waits for its slowest
    thread). Not on every thread of a piece of work at once: a team of two left alone in the
    process has libgomp spin its idle worker through the others' time (see :func:`beside`)."""
    import numba

    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


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


__all__ = ["in_background", "on_worker_thread", "BASE_DEADLINE_S", "DEADLINE_S_PER_PIXEL", "ATTEMPTS",
           "EncoderStalledError", "encoder_deadline", "call_with_deadline"]
