"""The warp's and the refocus's inner loops compile to vector code on this CPU.

The decoder's speed rests on a few loops that LLVM vectorises only while their bodies stay
free of branches, gathers and signed index checks (:mod:`lfstream.codec.warp.kernels`); a
change that breaks that still gives the same bytes, so only the generated code shows it.
Each loop is compiled afresh (the disk cache keeps no assembly) with its module's options
and its machine code searched for packed instructions on 256- or 512-bit registers.
"""

from __future__ import annotations

import re

import numba
import numpy as np
import pytest

from lfstream.codec._numba import _ROW_BORROWED


def _simd_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


pytestmark = pytest.mark.skipif("avx2" not in _simd_flags(), reason="the vector width checked is AVX2's or wider")

#: a packed instruction on a ymm or zmm register: ``vpmuludq %ymm1, %ymm2, %ymm3``, ``vfmadd231ps ... %zmm0``
_WIDE = re.compile(r"^\s+v\w+\s+[^\n]*%[yz]mm", re.M)


def _asm(py_func, args, **options) -> str:
    fresh = numba.njit(**{**options, "cache": False})(py_func)
    fresh(*args)
    return next(iter(fresh.inspect_asm().values()))


def _wide_ops(asm: str, mnemonic: str) -> int:
    return sum(1 for line in _WIDE.findall(asm) if line.split()[0].startswith(mnemonic))


def test_the_bilinear_blend_of_packed_lanes_is_vector_code():
    from lfstream.codec.warp import kernels as k

    w = 97
    packed = np.zeros((w + 2) * 8, np.uint64)
    idx, fx, fy = np.zeros(w, np.int32), np.full(w, 300, np.int32), np.full(w, 700, np.int32)
    asm = _asm(k._row_accs.py_func, (packed, np.uint32(w + 2), idx, fx, fy, k._TAPS_ALL, np.zeros((4, w), np.uint64),
                                     np.zeros(w, np.uint64)), **_ROW_BORROWED)
    # the lanes' products: 64-bit multiplies made of 32-bit ones on AVX2, native on AVX-512
    assert _wide_ops(asm, "vpmul") >= 4


def test_the_sample_positions_are_vector_code():
    from lfstream.codec.warp import kernels as k

    h, w = 5, 97
    dmap = np.linspace(-2, 2, h * w, dtype=np.float32).reshape(h, w)
    args = (dmap, np.arange(w, dtype=np.float32), 2, np.float32(1.5), np.float32(-0.5), h, np.zeros(w, np.int32),
            np.zeros(w, np.int32), np.zeros(w, np.int32))
    asm = _asm(k._row_taps.py_func, args, **_ROW_BORROWED)
    assert _wide_ops(asm, "vfmadd") + _wide_ops(asm, "vmul") >= 2  # the positions, eight a register
    assert _wide_ops(asm, "vcvtt") >= 1  # their conversion to fixed point


def test_the_focal_stack_row_sums_are_vector_code():
    from lfstream.refocus import _kernels as r

    n = 301
    acc = np.zeros(n, np.float32)
    src = np.arange(n, dtype=np.uint8)
    asm = _asm(r._axpy2.py_func, (acc, src, src, np.float32(0.25), np.float32(0.75)), fastmath=True)
    assert _wide_ops(asm, "vfmadd") + _wide_ops(asm, "vmul") >= 2
