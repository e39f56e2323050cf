"""The encoder deadline: a call that never returns is abandoned and retried, then reported."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import lfstream.codec.residual as residual
from lfstream.codec.deadline import call_with_deadline, encoder_deadline
from lfstream.errors import EncoderStalledError, LFStreamError


@pytest.fixture
def release():
    """An event the hung calls wait on; set at teardown so no test thread outlives its test."""
    event = threading.Event()
    yield event
    event.set()


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
