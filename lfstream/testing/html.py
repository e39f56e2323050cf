"""The comparison report a person looks at: one self-contained HTML page (no network, no
files beside it) with the per-frame metric curve, a frame x view heat map of PSNR, and the
worst view of the worst frame side by side with its difference."""

from __future__ import annotations

import base64
import html
import os
from pathlib import Path

import numpy as np

from lfstream.metrics import PSNR_CAP_DB
from lfstream.testing.compare import ComparisonReport

#: Heat-map colour range in dB: views at or below the low end are darkest.
HEAT_RANGE_DB = (20.0, 50.0)
#: Widest heat map drawn, in frames (longer videos are binned, each column the worst of its frames).
HEAT_MAX_COLUMNS = 1200


def _png(image: np.ndarray) -> str:
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image[..., ::-1]) if image.ndim == 3 else image)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise RuntimeError("PNG encoding failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def _heat_map(report: ComparisonReport) -> np.ndarray:
    """``(views, columns, 3)`` uint8: each column a frame (or a bin of frames, their worst),
    each row a view in row-major order, coloured by PSNR (identical views white)."""
    import cv2

    u, v = report.views
    psnr = np.array([r.metrics.psnr.reshape(u * v) for r in report.frames], np.float64)  # (T, U*V)
    psnr = np.where(np.isnan(psnr), np.nan, np.minimum(psnr, PSNR_CAP_DB))
    t = len(psnr)
    if t > HEAT_MAX_COLUMNS:
        edges = np.linspace(0, t, HEAT_MAX_COLUMNS + 1).astype(int)
        psnr = np.stack([np.nanmin(psnr[a:b], axis=0) for a, b in zip(edges[:-1], edges[1:])])
    lo, hi = HEAT_RANGE_DB
    scaled = np.clip((np.nan_to_num(psnr, nan=lo) - lo) / (hi - lo), 0, 1)
    levels = (scaled.T * 255).astype(np.uint8)  # (views, columns)
    rgb = cv2.applyColorMap(levels, cv2.COLORMAP_VIRIDIS)[..., ::-1].copy()
    rgb[psnr.T >= PSNR_CAP_DB] = 255
    rgb[np.isnan(psnr.T)] = 128
    # scale up so each cell is visible
    sy = max(1, 240 // (u * v))
    sx = max(1, 900 // max(1, len(psnr)))
    return np.repeat(np.repeat(rgb, sy, axis=0), sx, axis=1)


def _curve_svg(report: ComparisonReport, width: int = 900, height: int = 220) -> str:
    frames = [r.frame for r in report.frames]
    series = {"MPSNR": [min(r.metrics.mpsnr, PSNR_CAP_DB) for r in report.frames],
              "worst view": [min(float(np.nanmin(r.metrics.psnr)), PSNR_CAP_DB) for r in report.frames]}
    values = [y for s in series.values() for y in s]
    lo, hi = min(values), max(values)
    if hi - lo < 1e-6:
        lo, hi = lo - 1, hi + 1
    f0, f1 = frames[0], max(frames[-1], frames[0] + 1)
    m = 40

    def xy(f: int, y: float) -> str:
        return (f"{m + (f - f0) / (f1 - f0) * (width - 2 * m):.1f},"
                f"{height - m - (y - lo) / (hi - lo) * (height - 2 * m):.1f}")

    colours = {"MPSNR": "#1f77b4", "worst view": "#d62728"}
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
             f'aria-label="PSNR per frame">',
             f'<rect x="{m}" y="{m}" width="{width - 2 * m}" height="{height - 2 * m}" fill="none" stroke="#888"/>',
             f'<text x="4" y="{m}" font-size="11">{hi:.1f} dB</text>',
             f'<text x="4" y="{height - m}" font-size="11">{lo:.1f} dB</text>',
             f'<text x="{m}" y="{height - 10}" font-size="11">frame {f0}</text>',
             f'<text x="{width - m - 60}" y="{height - 10}" font-size="11">frame {frames[-1]}</text>']
    for k, (name, ys) in enumerate(series.items()):
        pts = " ".join(xy(f, y) for f, y in zip(frames, ys))
        parts.append(f'<polyline fill="none" stroke="{colours[name]}" stroke-width="1.5" points="{pts}"/>')
        parts.append(f'<text x="{width - m - 120}" y="{m + 14 + 14 * k}" font-size="11" '
                     f'fill="{colours[name]}">{html.escape(name)}</text>')
    for r in report.frames:
        if not r.passed:
            parts.append(f'<circle cx="{xy(r.frame, min(r.metrics.mpsnr, PSNR_CAP_DB)).split(",")[0]}" '
                         f'cy="{m - 6}" r="3" fill="#d62728"><title>frame {r.frame} failed</title></circle>')
    parts.append("</svg>")
    return "".join(parts)


def write_html(report: ComparisonReport, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Writes ``report`` as one self-contained page (atomically; an existing file is
    replaced only with ``overwrite``)."""
    from lfstream.io._fs import atomic_write_text, check_new_file

    path = check_new_file(path, overwrite)
    verdict = "passed" if report.passed else f"failed: frames {', '.join(map(str, report.failed_frames[:50]))}"
    rows = []
    for r in report.frames:
        if r.passed and len(report.frames) > 60:
            continue  # long videos: the failing frames only
        j = r.to_json()
        rows.append(f"<tr class='{'ok' if r.passed else 'bad'}'><td>{j['frame']}</td><td>{j['mpsnr']:.2f}</td>"
                    f"<td>{j['mssim']:.4f}</td><td>({j['worst_view'][0]}, {j['worst_view'][1]})</td>"
                    f"<td>{j['worst_view_psnr']:.2f}</td><td>{j['max_abs']:g}</td>"
                    f"<td>{html.escape('; '.join(r.failures)) or 'ok'}</td></tr>")
    crops = ""
    if report.worst is not None:
        frame, (u, v), a, b = report.worst
        diff = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1)
        gain = 255.0 / max(1, int(diff.max()))
        diff_img = np.clip(diff * gain, 0, 255).astype(np.uint8)
        crops = (f"<h2>Worst view: frame {frame}, view ({u}, {v})</h2><div class='crops'>"
                 f"<figure><img src='{_png(a)}' alt='reference'><figcaption>reference</figcaption></figure>"
                 f"<figure><img src='{_png(b)}' alt='test'><figcaption>test</figcaption></figure>"
                 f"<figure><img src='{_png(diff_img)}' alt='difference'><figcaption>|difference| "
                 f"(max {int(diff.max())} levels, scaled ×{gain:.1f})</figcaption></figure></div>")
    u, v = report.views
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>lfstream compare: {html.escape(verdict)}</title>
<style>
body {{ font: 14px system-ui, sans-serif; margin: 24px; color: #222; }}
table {{ border-collapse: collapse; }} td, th {{ padding: 2px 8px; text-align: right; }}
tr.bad {{ background: #fde0dc; }} .crops {{ display: flex; gap: 12px; flex-wrap: wrap; }}
figure {{ margin: 0; }} .crops img {{ width: 300px; image-rendering: pixelated; }}
#heatmap {{ width: 900px; height: 240px; border: 1px solid #888; image-rendering: pixelated; }}
.verdict {{ font-weight: 600; color: {'#1a7f37' if report.passed else '#cf222e'}; }}
</style></head><body>
<h1>lfstream compare</h1>
<p>reference <code>{html.escape(report.reference)}</code>, test <code>{html.escape(report.test)}</code>:
{len(report.frames)} frames of {u}×{v} views of {report.size[0]}×{report.size[1]}.
<span class="verdict" id="verdict">{html.escape(verdict)}</span></p>
<h2>PSNR per frame</h2>{_curve_svg(report) if report.frames else ''}
<h2>PSNR by frame (columns) and view (rows, row-major)</h2>
<p>{HEAT_RANGE_DB[0]:g} dB and below darkest, {HEAT_RANGE_DB[1]:g} dB and above brightest; identical views white.</p>
<img id="heatmap" src="{_png(_heat_map(report)) if report.frames else ''}" alt="PSNR heat map">
{crops}
<h2>Frames{' (failing only)' if len(report.frames) > 60 else ''}</h2>
<table><tr><th>frame</th><th>MPSNR</th><th>MSSIM</th><th>worst view</th><th>its PSNR</th><th>max |diff|</th>
<th>verdict</th></tr>
{''.join(rows)}
</table></body></html>
"""
    atomic_write_text(path, page)
    return path
