"""lfstream's worker threads and thread budgets: the kept pool that overlaps two parts of one
frame's work (:func:`in_background`), the lane for the work only a frame's end needs
(:func:`beside`), and a library's own thread count lowered inside a block
(:func:`single_thread`, :func:`single_numba_thread`)."""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")

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

    with single_thread(numba.get_num_threads, numba.set_num_threads):
        yield


@contextlib.contextmanager
def single_thread(get: Callable[[], int], set_: Callable[[int], object]) -> Iterator[None]:
    """A library's thread count (read by ``get``, written by ``set_``) set to 1 inside the
    block and restored afterwards, even when the block raises."""
    previous = get()
    set_(1)
    try:
        yield
    finally:
        set_(previous)
