"""The encoder watchdog: a call that never returns is abandoned and retried, then reported."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import lfstream.codec.residual as residual
import lfstream.codec.watchdog as watchdog
from lfstream.codec.watchdog import beside, call_with_deadline, completed, encoder_deadline, in_background, single_numba_thread
from lfstream.errors import EncoderStalledError, LFStreamError


@pytest.fixture
def release():
    """An event the hung calls wait on; set at teardown so no test thread outlives its test."""
    event = threading.Event()
    yield event
    event.set()


def test_in_background_runs_beside_the_caller_and_hands_back_its_outcome():
    started, go = threading.Event(), threading.Event()

    def job():
        started.set()
        assert go.wait(5.0)  # runs while the caller goes on: the caller releases it
        return threading.current_thread().name

    fut = in_background(job)
    assert started.wait(5.0)
    go.set()
    assert fut.result(5.0).startswith("lfstream-worker")

    def fail():
        raise KeyError("inner")

    with pytest.raises(KeyError, match="inner"):
        in_background(fail).result(5.0)


def test_beside_queues_on_one_lane_thread_on_two_cores_and_the_pool_elsewhere(monkeypatch):
    import numba

    monkeypatch.setattr(watchdog, "_cores", lambda: 2)
    order: list[tuple[str, int, int]] = []
    gate = threading.Event()

    def job(k: int):
        def run():
            if k == 0:
                assert gate.wait(5.0)
            order.append((threading.current_thread().name, k, numba.get_num_threads()))
            return k
        return run

    futures = [beside(job(k)) for k in range(3)]
    gate.set()
    assert [f.result(5.0) for f in futures] == [0, 1, 2]
    names = {name for name, _, _ in order}
    assert len(names) == 1 and names.pop().startswith("lfstream-worker-lane")
    assert [k for _, k, _ in order] == [0, 1, 2]  # one after another, in order
    # numba's own thread count (one thread each beside checks on one thread each left libgomp
    # spinning its idle worker: watchdog.beside)
    assert all(n == numba.config.NUMBA_NUM_THREADS for _, _, n in order)
    # called on the lane itself: run before returning (a lane job waiting on the lane would hang)
    nested = beside(lambda: beside(lambda: threading.current_thread().name).done())
    assert nested.result(5.0) is True
    with pytest.raises(KeyError, match="lane"):
        beside(lambda: {}["lane"]).result(5.0)
    monkeypatch.setattr(watchdog, "_cores", lambda: 8)
    assert beside(lambda: threading.current_thread().name).result(5.0).startswith("lfstream-worker")
    assert not beside(lambda: threading.current_thread().name).result(5.0).startswith("lfstream-worker-lane")


def test_single_numba_thread_restores_the_callers_count_and_completed_holds_its_value():
    import numba

    before = numba.get_num_threads()
    with pytest.raises(RuntimeError):
        with single_numba_thread():
            assert numba.get_num_threads() == 1
            raise RuntimeError("inside")
    assert numba.get_num_threads() == before
    done = completed(b"x")
    assert done.done() and done.result() == b"x"


def test_returns_value_and_propagates_errors():
    assert call_with_deadline(lambda: 41 + 1, 5.0, "sum") == 42

    def fail():
        raise KeyError("inner")

    with pytest.raises(KeyError, match="inner"):
        call_with_deadline(fail, 5.0, "failing")


def test_a_call_that_hangs_once_is_retried(release):
    calls = []

    def flaky():
        calls.append(1)
        if len(calls) == 1:
            release.wait()  # the first attempt deadlocks
        return "bytes"

    t0 = time.perf_counter()
    assert call_with_deadline(flaky, 0.2, "flaky") == "bytes"
    assert len(calls) == 2
    assert time.perf_counter() - t0 < 3.0  # waited about one deadline, not forever


def test_a_call_that_always_hangs_raises_one_clear_error(release):
    with pytest.raises(EncoderStalledError, match=r"AV1 test: the encoder did not finish within 0 s \(2 attempts"):
        call_with_deadline(release.wait, 0.1, "AV1 test")
    assert issubclass(EncoderStalledError, LFStreamError)  # the CLI's one line and exit status 2


def test_deadline_grows_with_pixels_and_is_generous():
    assert encoder_deadline(0) >= 60.0
    # a 7x7x375x540 residual sequence: SVT-AV1 preset 8 takes ~1 s; allow far more
    assert encoder_deadline(48 * 375 * 540) > 60.0 + 15.0
    with pytest.raises(ValueError):
        call_with_deadline(lambda: None, 0.0, "zero")


def test_residual_encode_survives_a_stalled_encoder(monkeypatch, release):
    """The residual's AV1 sequence: the first encoder's flush deadlocks; the retry on a fresh
    encoder gives the bytes an undisturbed encode gives."""
    rng = np.random.default_rng(3)
    lf = rng.integers(0, 256, (2, 2, 32, 48, 3), dtype=np.uint8)
    expected = residual.encode_residual(lf, None, 40, 12)

    real = residual.svtav1_encoder
    made = []

    class StallingFlush:
        def __init__(self, ctx):
            self.ctx = ctx

        def encode(self, frame):
            if frame is None:
                release.wait()
            return self.ctx.encode(frame)

    def encoder(*args, **kwargs):
        ctx = real(*args, **kwargs)
        made.append(ctx)
        return StallingFlush(ctx) if len(made) == 1 else ctx

    monkeypatch.setattr(residual, "svtav1_encoder", encoder)
    monkeypatch.setattr(residual, "encoder_deadline", lambda pixels: 1.0)
    assert residual.encode_residual(lf, None, 40, 12) == expected
    assert len(made) == 2
