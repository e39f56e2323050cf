"""``assert_lf_close``: a light-field assertion for users' own tests, in the manner of
``numpy.testing.assert_allclose``."""

from __future__ import annotations

import numpy as np

from lfstream.testing.compare import Thresholds, compare


def assert_lf_close(actual, desired, *, min_psnr: float | None = None, min_ssim: float | None = None,
                    max_abs: float | None = None, scope: str = "view", present=None) -> None:
    """Raises an ``AssertionError`` unless every frame of ``actual`` is close to ``desired``.

    With no threshold the two must be identical. The message names each failing frame, its
    worst view and the metrics that missed, so a failing test says where to look. Works from
    pytest with no plugin.

    Args:
        actual: the light field or LF video under test (an array or a path lfstream reads).
        desired: the expected one, of the same shape.
        min_psnr: least PSNR in dB (per view, or the frame's MPSNR with ``scope="frame"``).
        min_ssim: least SSIM (likewise).
        max_abs: largest absolute difference of any sample, in 8-bit levels.
        scope: ``"view"`` (every view must pass) or ``"frame"`` (the frame's means must).
        present: ``(U, V)`` mask of the views to compare (``None``: all).

    Raises:
        AssertionError: a frame misses a threshold, or the shapes differ.

    Shape:
        - actual, desired: ``(U, V, H, W, C)`` or ``(T, U, V, H, W, C)``; present: ``(U, V)``
    """
    from lfstream.errors import LFShapeError
    from lfstream.testing.compare import frame_metrics, judge

    thresholds = Thresholds(min_psnr=min_psnr, min_ssim=min_ssim, max_abs=max_abs, scope=scope)
    try:
        if present is None:
            results = list(compare(desired, actual, thresholds))
        else:
            a, d = np.asarray(actual), np.asarray(desired)
            if a.shape != d.shape:
                raise LFShapeError(f"shapes differ: actual {a.shape}, desired {d.shape}")
            a, d = (a, d) if a.ndim == 6 else (a[None], d[None])
            results = [judge(k, frame_metrics(d[k], a[k], present), thresholds) for k in range(len(a))]
    except LFShapeError as exc:
        raise AssertionError(f"light fields not comparable: {exc}") from None
    failed = [r for r in results if not r.passed]
    if not failed:
        return
    lines = [f"{len(failed)} of {len(results)} frames not close "
             f"({_describe(thresholds)}):"]
    for r in failed[:20]:
        u, v = r.metrics.worst_view
        lines.append(f"  frame {r.frame}: {'; '.join(r.failures)} — MPSNR {r.metrics.mpsnr:.2f} dB, "
                     f"MSSIM {r.metrics.mssim:.4f}, worst view ({u}, {v}) at {r.metrics.psnr[u, v]:.2f} dB, "
                     f"max |diff| {r.metrics.max_abs:g}")
    if len(failed) > 20:
        lines.append(f"  ... and {len(failed) - 20} more frames")
    raise AssertionError("\n".join(lines))


def _describe(t: Thresholds) -> str:
    if t.exact:
        return "identical required"
    parts = [f"{name} {value:g}" for name, value in (("min_psnr", t.min_psnr), ("min_ssim", t.min_ssim),
                                                     ("max_abs", t.max_abs)) if value is not None]
    return ", ".join(parts) + f", per {t.scope}"
