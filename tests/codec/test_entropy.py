"""The level-map range coder (lfstream.codec._entropy): exact, bounded, and refusing damage."""

import numpy as np
import pytest

from lfstream.codec._entropy import (
    BAD_LEVEL,
    OK,
    OVERRUN,
    UNARY,
    code_levels,
    decode_coded_levels,
    max_coded_size,
)


@pytest.mark.parametrize("kind", ["smooth", "random", "jumps", "constant", "one"])
def test_round_trip_is_exact(rng, kind):
    h, w = (1, 1) if kind == "one" else (23, 37)
    if kind == "smooth":
        levels = np.clip(np.cumsum(rng.integers(-2, 3, (h, w)), axis=1) + 60, 0, 120)
    elif kind == "random":
        levels = rng.integers(0, 256, (h, w))
    elif kind == "jumps":  # magnitudes far past the unary prefix: the escape codes them
        levels = np.where(rng.random((h, w)) < 0.5, 0, 255)
    else:
        levels = np.full((h, w), 7)
    body = code_levels(levels)
    assert len(body) + 1 <= max_coded_size(levels.size)
    back, status = decode_coded_levels(body, (h, w), int(levels.max()) + 1)
    assert status == OK and np.array_equal(back, levels)
    if kind == "jumps":
        assert np.abs(np.diff(levels, axis=1)).max() > UNARY


def test_smooth_maps_cost_a_fraction_of_a_byte_a_value(rng):
    """The point of the contexts: a piecewise-smooth map (what the hint sends) costs far less
    than a byte a value, and a constant one almost nothing."""
    smooth = np.clip(np.cumsum(rng.integers(-1, 2, (64, 96)), axis=1) // 3 + 40, 0, 80)
    assert len(code_levels(smooth)) < 0.25 * smooth.size  # measured 0.16 bytes a value
    assert len(code_levels(np.full((64, 96), 3))) < 32  # measured 24 (probabilities saturate at 11 bits)


def test_damage_is_reported_not_crashed(rng):
    levels = np.clip(np.cumsum(rng.integers(-3, 4, (30, 40)), axis=1) + 50, 0, 99)
    body = code_levels(levels)
    for cut in range(len(body)):  # every truncation: the decoder notices the missing bytes
        assert decode_coded_levels(body[:cut], levels.shape, 100)[1] != OK
    assert decode_coded_levels(body[:-1], levels.shape, 100)[1] == OVERRUN
    # fewer levels than the map uses: refused, not written out of range
    assert decode_coded_levels(body, levels.shape, int(levels.max()))[1] == BAD_LEVEL
    for _ in range(300):  # bit flips: a status, or a map whose values are all in range
        bad = bytearray(body)
        bad[int(rng.integers(0, len(bad)))] ^= 1 << int(rng.integers(0, 8))
        back, status = decode_coded_levels(bytes(bad), levels.shape, 100)
        if status == OK:
            assert back.min() >= 0 and back.max() < 100


def test_a_body_too_small_for_its_declared_size_is_refused_before_allocating():
    """The cheapest value costs 0.022 bits: a constant map is the limit (measured 24 bytes for
    6144 values), and a payload declaring far more values than its bytes can hold is refused
    without allocating them (a hostile 8192 x 8192 hint in a few bytes)."""
    from lfstream.codec._entropy import MAX_VALUES_PER_BYTE, TOO_MANY

    flat = np.zeros((512, 512), np.int32)
    body = code_levels(flat)
    assert flat.size <= MAX_VALUES_PER_BYTE * (len(body) + 1)  # the densest real map still decodes
    back, status = decode_coded_levels(body, flat.shape, 1)
    assert status == OK and np.array_equal(back, flat)
    back, status = decode_coded_levels(body[:8], (8192, 8192), 1)
    assert status == TOO_MANY and back.size == 0
