"""lfstream's worker threads: the kept pool, the lane beside the critical path, thread budgets."""

from __future__ import annotations

import threading

import pytest

import lfstream.codec.workers as workers
from lfstream.codec.workers import beside, completed, in_background, single_numba_thread, single_thread


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

    monkeypatch.setattr(workers, "_cores", lambda: 2)
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
    # spinning its idle worker: workers.beside)
    assert all(n == numba.config.NUMBA_NUM_THREADS for _, _, n in order)
    # called on the lane itself: run before returning (a lane job waiting on the lane would hang)
    nested = beside(lambda: beside(lambda: threading.current_thread().name).done())
    assert nested.result(5.0) is True
    with pytest.raises(KeyError, match="lane"):
        beside(lambda: {}["lane"]).result(5.0)
    monkeypatch.setattr(workers, "_cores", lambda: 8)
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




def test_single_thread_sets_one_and_restores_even_when_the_block_raises():
    count = [3]
    try:
        with single_thread(lambda: count[0], lambda n: count.__setitem__(0, n)):
            assert count[0] == 1
            raise RuntimeError("inside")
    except RuntimeError:
        pass
    assert count[0] == 3
