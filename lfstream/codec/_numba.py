"""numba compile options the codec's kernels share: parallel kernels, row helpers with and
without reference counting, and OpenCV-exact arithmetic."""

from __future__ import annotations

from numba.core.cpu import CPUTargetOptions

_PARALLEL = dict(parallel=True, fastmath=True, cache=True, nogil=True)


# The parallel kernels run one row (or view) per prange iteration and do the row's work in
# plain njit functions (one place for the row's scalars, the same code at any thread count).
# Indices derived from uint8 data are computed in signed int32: a difference of unsigned
# values wraps and, without bounds checks, reads far outside a lookup table (a bug found
# here: joint_upsample gave different maps from run to run). tests/codec checks the
# kernels against plain-Python references and across thread counts.
_ROW = dict(fastmath=True, cache=True, nogil=True)


# Row helpers that allocate nothing run without numba's reference counting (``_nrt=False``):
# with it, every array argument of a call that LLVM does not inline is counted up on entry
# and down on each exit with atomic instructions, a dozen or more a row through the warp's
# helpers, a sixth of a decode's CPU under perf (NRT_incref and NRT_decref the two hottest
# instructions); their callers hold the arrays meanwhile.
# ``_nrt`` is an option numba's CPU target knows but does not document: where a numba
# without it would refuse the kernels, they count as before.
_BORROW = {"_nrt": False} if hasattr(CPUTargetOptions, "_nrt") else {}


_ROW_BORROWED = dict(_ROW, **_BORROW)


# OpenCV's arithmetic reproduced: no fastmath (a fused multiply-add or a reordered sum would
# round differently from OpenCV's separate float32 multiplies and adds)
_EXACT = dict(cache=True, nogil=True)


_EXACT_BORROWED = dict(_EXACT, **_BORROW)  # (see _ROW_BORROWED)


# The spans of views on the centre's row or column (8 of the 12 sweep views of a 7x7 grid):
# one interpolation instead of three, half the loads (the fine sweep 12 % faster). Their
# costs equal _sweep_span's to the bit: fast-math without reassociation (and not inlined
# into the caller, whose flags would apply), written in the order the compiler evaluates
# _sweep_span with a zero weight; any other order moved hint maps by 2e-7 and changed the
# stream bytes of three of the seven shared scenes. tests/codec/hint/test_hint.py compares.
_NO_REASSOC = dict(fastmath={"nnan", "ninf", "nsz", "arcp", "contract", "afn"}, cache=True, nogil=True)


_NO_REASSOC_BORROWED = dict(_NO_REASSOC, **_BORROW)  # (see _ROW_BORROWED)


# The view axes' fit (lfstream.codec.hint.axes._fit_axes) on a few thousand flow samples. Its
# numpy version made about sixty calls on small arrays, on the lane whose end the hint waits
# for; these kernels give the same axes to the bit (tests/codec/hint/test_hint.py). Samples are rows
# of ``flows``: ``(dy_0, dx_0, dy_1, dx_1, ...)``, one pair per view. fastmath lets the
# per-sample sums vectorise (2 ns an element without it); they round like numpy's to well
# under the float32 the axes are returned in.
_FIT = dict(fastmath=True, cache=True, nogil=True)
