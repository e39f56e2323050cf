"""Context-adaptive binary range coding of small 8-bit level maps (the key maps of the depth
hint and of the gain maps).

The map is coded in raster order as the residual of the median edge detector's prediction
(LOCO-I / JPEG-LS: ``min(a, b)``, ``max(a, b)`` or ``a + b - c`` from the left, upper and
upper-left neighbours), binarised as zero flag, sign, a unary prefix of the magnitude and an
Exp-Golomb escape, each binary decision coded with an adaptive probability chosen by the
local activity ``|a - c| + |b - c|`` (5 classes: flat areas, where the residual is almost
always zero, get their own statistics). The range coder is LZMA's (11-bit probabilities,
adaptation shift 5, carry propagation through a cached byte), all integer arithmetic, so
encoder and decoder agree bit for bit on every machine.

The decoder is bounded: a fixed number of decisions per value, reads past the end of the
body count as errors, and every decoded level is checked against the level count; a corrupt
body is reported (status codes), never a crash or a hang.
"""

from __future__ import annotations

import numba
import numpy as np

_JIT = dict(cache=True, nogil=True)

PROB_BITS = 11
_PROB_ONE = 1 << PROB_BITS
_MOVE = 5
_TOP = 1 << 24
_MASK32 = 0xFFFFFFFF
#: activity classes (contexts)
N_CONTEXTS = 5
#: magnitudes 1 .. UNARY coded by adaptive unary decisions, larger ones by an escape
UNARY = 12
_N_PROBS = 2 + UNARY
#: the escape's Exp-Golomb prefix never needs more ones than this (levels < 256)
_MAX_ESCAPE_BITS = 9
#: decode status codes
OK, BAD_LEVEL, OVERRUN, BAD_ESCAPE, TOO_MANY = 0, 1, 2, 3, 4
#: No value costs less than the zero flag at its most probable (p = 2017/2048: 0.022 bits),
#: so a body of n bytes holds at most ~364 n values: a payload declaring more is damaged or
#: hostile, refused before anything is allocated for it
MAX_VALUES_PER_BYTE = 400


def max_coded_size(n_values: int) -> int:
    """An upper bound on the coded size of ``n_values`` levels, in bytes (the encoder's buffer)."""
    # at most 2 + UNARY adaptive decisions (<= 11 bits each) and 2 * 9 + 1 bypass bits a value
    return 16 + n_values * ((2 + UNARY) * PROB_BITS + 2 * _MAX_ESCAPE_BITS + 1) // 8


@numba.njit(inline="always", **_JIT)
def _predict(levels, y, x):  # pragma: no cover - compiled
    """(context, prediction) of value (y, x) from its causal neighbours."""
    if y == 0:
        a = levels[0, x - 1] if x > 0 else 0
        b = a
        c = a
    elif x == 0:
        a = levels[y - 1, 0]
        b = a
        c = a
    else:
        a = levels[y, x - 1]
        b = levels[y - 1, x]
        c = levels[y - 1, x - 1]
    g = abs(a - c) + abs(b - c)
    ctx = 0
    while g > 0 and ctx < N_CONTEXTS - 1:
        g >>= 1
        ctx += 1
    hi = max(a, b)
    lo = min(a, b)
    if c >= hi:
        return ctx, lo
    if c <= lo:
        return ctx, hi
    return ctx, a + b - c


@numba.njit(inline="always", **_JIT)
def _shift_low(low, cache, pending, pos, out):  # pragma: no cover - compiled
    if low < 0xFF000000 or low > _MASK32:
        carry = low >> 32
        temp = cache
        while True:
            out[pos] = (temp + carry) & 0xFF
            pos += 1
            temp = 0xFF
            pending -= 1
            if pending == 0:
                break
        cache = (low >> 24) & 0xFF
    pending += 1
    low = (low & 0x00FFFFFF) << 8
    return low, cache, pending, pos


@numba.njit(inline="always", **_JIT)
def _encode_bit(probs, ctx, k, bit, low, rng, cache, pending, pos, out):  # pragma: no cover - compiled
    p = probs[ctx, k]
    bound = (rng >> PROB_BITS) * p
    if bit == 0:
        rng = bound
        probs[ctx, k] = p + ((_PROB_ONE - p) >> _MOVE)
    else:
        low += bound
        rng -= bound
        probs[ctx, k] = p - (p >> _MOVE)
    while rng < _TOP:
        rng = (rng << 8) & _MASK32
        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
    return low, rng, cache, pending, pos


@numba.njit(inline="always", **_JIT)
def _encode_direct(bit, low, rng, cache, pending, pos, out):  # pragma: no cover - compiled
    rng >>= 1
    if bit:
        low += rng
    while rng < _TOP:
        rng = (rng << 8) & _MASK32
        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
    return low, rng, cache, pending, pos


@numba.njit(**_JIT)
def encode_levels(levels, out):  # pragma: no cover - compiled
    """Codes ``levels`` ((h, w) int32, values 0..255) into ``out`` (uint8, at least
    :func:`max_coded_size` long); returns the number of bytes written."""
    h, w = levels.shape
    probs = np.full((N_CONTEXTS, _N_PROBS), _PROB_ONE // 2, np.int64)
    low, rng, cache, pending, pos = 0, _MASK32, 0, 1, 0
    for y in range(h):
        for x in range(w):
            ctx, pred = _predict(levels, y, x)
            r = levels[y, x] - pred
            low, rng, cache, pending, pos = _encode_bit(probs, ctx, 0, 1 if r != 0 else 0, low, rng, cache, pending,
                                                        pos, out)
            if r == 0:
                continue
            low, rng, cache, pending, pos = _encode_bit(probs, ctx, 1, 1 if r < 0 else 0, low, rng, cache, pending,
                                                        pos, out)
            m = abs(r) - 1
            for j in range(UNARY):
                more = 1 if m > j else 0
                low, rng, cache, pending, pos = _encode_bit(probs, ctx, 2 + j, more, low, rng, cache, pending, pos,
                                                            out)
                if more == 0:
                    break
            if m >= UNARY:  # Exp-Golomb (order 0) of m - UNARY in direct bits
                e = m - UNARY + 1
                n = 0
                while (e >> (n + 1)) > 0:
                    n += 1
                for _ in range(n):
                    low, rng, cache, pending, pos = _encode_direct(1, low, rng, cache, pending, pos, out)
                low, rng, cache, pending, pos = _encode_direct(0, low, rng, cache, pending, pos, out)
                for i in range(n - 1, -1, -1):
                    low, rng, cache, pending, pos = _encode_direct((e >> i) & 1, low, rng, cache, pending, pos, out)
    for _ in range(5):
        low, cache, pending, pos = _shift_low(low, cache, pending, pos, out)
    return pos


@numba.njit(inline="always", **_JIT)
def _next_byte(body, at):  # pragma: no cover - compiled
    return (body[at] if at < body.shape[0] else 0), at + 1


@numba.njit(**_JIT)
def _normalise(rng, code, body, at):  # pragma: no cover - compiled
    """The decoder's counterpart of the encoder's byte shifts (past the body's end: zeros,
    counted in ``at``)."""
    while rng < _TOP:
        byte, at = _next_byte(body, at)
        rng = (rng << 8) & _MASK32
        code = ((code << 8) | byte) & _MASK32
    return rng, code, at


@numba.njit(**_JIT)
def _decode_direct(rng, code, body, at):  # pragma: no cover - compiled
    """One bit of :func:`_encode_direct` (probability one half)."""
    rng >>= 1
    if code >= rng:
        code -= rng
        bit = 1
    else:
        bit = 0
    rng, code, at = _normalise(rng, code, body, at)
    return bit, rng, code, at


@numba.njit(**_JIT)
def decode_levels(body, n_levels, levels):  # pragma: no cover - compiled
    """Inverse of :func:`encode_levels` (``body``: its bytes after the first, which is
    always 0); fills ``levels`` ((h, w) int32) and returns a status: ``OK``, ``BAD_LEVEL``
    (a value outside ``0 .. n_levels - 1``), ``OVERRUN`` (the body ended early) or
    ``BAD_ESCAPE`` (an impossible magnitude)."""
    h, w = levels.shape
    probs = np.full((N_CONTEXTS, _N_PROBS), _PROB_ONE // 2, np.int64)
    rng = _MASK32
    code = 0
    at = 0
    for _ in range(4):
        byte, at = _next_byte(body, at)
        code = (code << 8) | byte
    for y in range(h):
        for x in range(w):
            ctx, pred = _predict(levels, y, x)
            r = 0
            k = 0
            n_bits = 0
            while True:  # the value's decisions in order: zero flag, sign, unary, escape
                if k < _N_PROBS:
                    p = probs[ctx, k]
                    bound = (rng >> PROB_BITS) * p
                    if code < bound:
                        rng = bound
                        probs[ctx, k] = p + ((_PROB_ONE - p) >> _MOVE)
                        bit = 0
                    else:
                        code -= bound
                        rng -= bound
                        probs[ctx, k] = p - (p >> _MOVE)
                        bit = 1
                    rng, code, at = _normalise(rng, code, body, at)
                else:
                    bit, rng, code, at = _decode_direct(rng, code, body, at)
                if k == 0:
                    if bit == 0:
                        break
                    k = 1
                elif k == 1:
                    r = -1 if bit else 1  # the sign; magnitude 1 so far
                    k = 2
                elif k < _N_PROBS:
                    if bit == 0:
                        break
                    r += 1 if r > 0 else -1
                    k += 1
                else:  # escape: n ones, a zero, then n bits
                    if bit == 1:
                        n_bits += 1
                        if n_bits > _MAX_ESCAPE_BITS:
                            return BAD_ESCAPE
                        continue
                    e = 1
                    for _ in range(n_bits):
                        bit, rng, code, at = _decode_direct(rng, code, body, at)
                        e = (e << 1) | bit
                    extra = e - 1
                    r += extra if r > 0 else -extra
                    break
            value = pred + r
            if value < 0 or value >= n_levels:
                return BAD_LEVEL
            levels[y, x] = value
    # a whole body is read exactly: every byte the encoder flushed, nothing after it
    return OK if at <= body.shape[0] else OVERRUN


def code_levels(levels: np.ndarray) -> bytes:
    """``levels`` (2-D, values 0..255) coded by :func:`encode_levels`, without the coder's
    first byte (always 0)."""
    levels = np.ascontiguousarray(levels, np.int32)
    out = np.empty(max_coded_size(levels.size), np.uint8)
    return out[1:encode_levels(levels, out)].tobytes()


def decode_coded_levels(body: bytes, shape: tuple[int, int], n_levels: int) -> tuple[np.ndarray, int]:
    """Inverse of :func:`code_levels`: the ``shape`` int32 levels, below ``n_levels``, and
    the decoder's status (:data:`OK`, else the map is not to be used; :data:`TOO_MANY`: more
    values than the body can hold, nothing allocated)."""
    if shape[0] * shape[1] > MAX_VALUES_PER_BYTE * (len(body) + 1) + 1024:
        return np.zeros((0, 0), np.int32), TOO_MANY
    levels = np.empty(shape, np.int32)
    return levels, int(decode_levels(np.frombuffer(body, np.uint8), n_levels, levels))
