"""Click to focus: a self-contained HTML page for the focal stacks in an output folder.

:func:`write_viewer` turns what ``lfstream stream`` or ``lfstream refocus`` wrote — the
planes (``plane_XX.mp4`` or ``plane_XX.png``), ``planes.json`` and ``disparity.json`` — into
``index.html`` beside them: inline JavaScript and CSS, no network and no server, so it
opens from ``file://``. Each frame's planes are one JPEG sprite (``viewer/frame_NNNNNN.jpg``,
planes stacked vertically): switching planes is instant and the page's size stays
proportional to the outputs. The page keeps its state in ``window.lfview = {frame, plane,
planes, frames}`` and shows the picture in the element ``#view``; clicking a pixel focuses
the plane whose slope is nearest the scene's disparity there (from the decoder's map,
embedded at low resolution), with a short sweep; arrow keys step planes and frames.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np

from lfstream.errors import LFFileError, LFValueError
from lfstream.io import iter_video_frames, read_image
from lfstream.io._fs import atomic_write_bytes, atomic_write_text

#: The side of the disparity map the page keeps (per frame), in pixels at most.
DISPARITY_SIDE = 96


def disparity_record(seq: int, disparity: np.ndarray, side: int = DISPARITY_SIDE) -> dict:
    """One frame's disparity for ``disparity.json``: block means at most ``side`` pixels on
    its longer side, quantised to 8 bits over its range.

    Shape:
        - disparity: ``(H, W)`` px per view step
    """
    d = np.asarray(disparity, np.float32)
    h, w = d.shape
    f = max(1, int(np.ceil(max(h, w) / side)))
    small = cv2.resize(d, (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA)
    lo, hi = float(small.min()), float(small.max())
    q = np.round((small - lo) / (hi - lo) * 255.0).astype(np.uint8) if hi > lo else np.zeros(small.shape, np.uint8)
    return {"frame": int(seq), "lo": lo, "hi": hi, "rows": int(q.shape[0]), "cols": int(q.shape[1]),
            "q": q.ravel().tolist()}


def write_disparity_json(out: Path, records: list[dict]) -> Path:
    path = Path(out) / "disparity.json"
    atomic_write_text(path, json.dumps({"frames": records}))
    return path


def _plane_images(out: Path, n_planes: int) -> list[list[np.ndarray]]:
    """Frames x planes of images, from plane videos, one folder of planes, or per-frame folders."""
    videos = [out / f"plane_{k:02d}.mp4" for k in range(n_planes)]
    if all(v.exists() for v in videos):
        per_plane = [list(iter_video_frames(v)) for v in videos]
        n = min(len(p) for p in per_plane)
        return [[per_plane[k][t] for k in range(n_planes)] for t in range(n)]
    pngs = [out / f"plane_{k:02d}.png" for k in range(n_planes)]
    if all(p.exists() for p in pngs):
        return [[read_image(p)[:, :, :3] for p in pngs]]
    frames = sorted(p for p in (out / "frames").glob("frame_*")) if (out / "frames").is_dir() else \
        sorted(p for p in out.glob("frame_*") if p.is_dir())
    if frames and all((f / f"plane_{k:02d}.png").exists() for f in frames for k in range(n_planes)):
        return [[read_image(f / f"plane_{k:02d}.png")[:, :, :3] for k in range(n_planes)] for f in frames]
    raise LFFileError(f"{out}: no focal planes found (plane_XX.mp4, plane_XX.png or frame_*/plane_XX.png)")


def write_viewer(out: str | os.PathLike, fps: float | None = None, quality: int = 88) -> Path:
    """Writes ``index.html`` (and its sprites) for the focal stacks in ``out``; returns its path.

    Raises:
        LFFileError: ``out`` holds no focal planes or no ``planes.json``.
    """
    out = Path(out)
    try:
        meta = json.loads((out / "planes.json").read_text())
    except (OSError, ValueError) as exc:
        raise LFFileError(f"{out}: no readable planes.json (write one with lfstream stream or refocus)") from exc
    planes = meta.get("planes") or []
    if not planes:
        raise LFValueError(f"{out}/planes.json: lists no planes")
    images = _plane_images(out, len(planes))
    h, w = images[0][0].shape[:2]
    disparity = []
    if (out / "disparity.json").exists():
        try:
            disparity = json.loads((out / "disparity.json").read_text()).get("frames", [])
        except ValueError:
            disparity = []
    sprite_dir = out / "viewer"
    sprite_dir.mkdir(exist_ok=True)
    sprites = []
    for t, stack in enumerate(images):
        name = f"viewer/frame_{t:06d}.jpg"
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(np.concatenate(stack, axis=0), cv2.COLOR_RGB2BGR),
                               [int(cv2.IMWRITE_JPEG_QUALITY), quality])
        if not ok:  # pragma: no cover - OpenCV fails only on invalid input
            raise LFFileError(f"{out / name}: cannot encode")
        atomic_write_bytes(out / name, buf.tobytes())
        sprites.append(name)
    aif = out / "all_in_focus.png"
    data = {"planes": planes, "frames": len(images), "width": w, "height": h, "fps": fps or 8.0,
            "sprites": sprites, "disparity": disparity, "all_in_focus": aif.name if aif.exists() else None}
    page = _PAGE.replace("/*DATA*/", json.dumps(data, separators=(",", ":")))
    path = out / "index.html"
    atomic_write_text(path, page)
    return path


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>lfstream focal stack</title>
<style>
body{font:14px system-ui,sans-serif;margin:16px;background:#111;color:#eee}
#view{position:relative;max-width:100%;background-repeat:no-repeat;cursor:crosshair;border:1px solid #444}
.row{margin:8px 0;display:flex;gap:10px;align-items:center;flex-wrap:wrap}
input[type=range]{width:360px}
#label{font-family:monospace}
button{background:#333;color:#eee;border:1px solid #666;padding:3px 10px}
</style></head><body>
<h3>lfstream: click a point to focus on it</h3>
<div id="view"></div>
<div class="row"><label for="focus">focus</label><input id="focus" type="range" min="0" step="1">
<span id="label"></span></div>
<div class="row" id="framerow"><button id="play">play</button><label for="frame">frame</label>
<input id="frame" type="range" min="0" step="1"><span id="framelabel"></span>
<button id="aif">all in focus</button></div>
<p>Keys: up/down step the focus, left/right step the frames. Planes: slope is the disparity in focus
(pixels per view step), alpha the refocus parameter.</p>
<script>
"use strict";
const D = /*DATA*/;
const K = D.planes.length, view = document.getElementById("view");
const focus = document.getElementById("focus"), frameInput = document.getElementById("frame");
const label = document.getElementById("label"), frameLabel = document.getElementById("framelabel");
window.lfview = {frame: 0, plane: Math.floor(K / 2), planes: D.planes, frames: D.frames, showingAllInFocus: false};
focus.max = K - 1; frameInput.max = Math.max(0, D.frames - 1);
if (D.frames < 2) { document.getElementById("play").style.display = "none"; frameInput.disabled = true; }
if (!D.all_in_focus) { document.getElementById("aif").style.display = "none"; }
function fit() {
  const w = Math.min(Math.max(D.width, 540), window.innerWidth - 40);  // small pictures scaled up
  view.style.width = w + "px"; view.style.height = Math.round(w * D.height / D.width) + "px";
  view.style.backgroundSize = "100% " + (K * 100) + "%";
}
function describe(p) {
  let s = "plane " + p.index + "  slope " + (p.slope >= 0 ? "+" : "") + p.slope.toFixed(3) +
          "  alpha " + (p.alpha === null ? "-" : p.alpha.toFixed(3));
  if (p.distance_m !== undefined) s += "  distance " + (p.distance_m === null ? "inf" : p.distance_m.toFixed(2) + " m");
  return s;
}
function show() {
  const s = window.lfview;
  if (s.showingAllInFocus) {
    view.style.backgroundImage = "url(" + D.all_in_focus + ")";
    view.style.backgroundSize = "100% 100%"; view.style.backgroundPosition = "0 0";
  } else {
    view.style.backgroundImage = "url(" + D.sprites[s.frame] + ")";
    view.style.backgroundSize = "100% " + (K * 100) + "%";
    view.style.backgroundPosition = "0 " + (K > 1 ? (100 * s.plane / (K - 1)) : 0) + "%";
  }
  focus.value = s.plane; frameInput.value = s.frame;
  label.textContent = describe(D.planes[s.plane]);
  frameLabel.textContent = (s.frame + 1) + " / " + D.frames;
}
function setPlane(k) { window.lfview.plane = Math.max(0, Math.min(K - 1, k)); window.lfview.showingAllInFocus = false; show(); }
function setFrame(t) { window.lfview.frame = Math.max(0, Math.min(D.frames - 1, t)); show(); }
let sweep = null;
function sweepTo(target) {
  if (sweep) clearInterval(sweep);
  sweep = setInterval(function () {
    const k = window.lfview.plane;
    if (k === target) { clearInterval(sweep); sweep = null; return; }
    setPlane(k + (target > k ? 1 : -1));
  }, 40);
}
function disparityAt(x, y) {
  const recs = D.disparity;
  if (!recs.length) return null;
  let r = recs[0];
  for (const c of recs) { if (c.frame <= window.lfview.frame) r = c; }
  const col = Math.min(r.cols - 1, Math.floor(x * r.cols / D.width));
  const row = Math.min(r.rows - 1, Math.floor(y * r.rows / D.height));
  return r.lo + r.q[row * r.cols + col] / 255 * (r.hi - r.lo);
}
view.addEventListener("click", function (e) {
  const b = view.getBoundingClientRect();
  const x = (e.clientX - b.left) / b.width * D.width, y = (e.clientY - b.top) / b.height * D.height;
  const d = disparityAt(x, y);
  if (d === null) return;
  let best = 0;
  D.planes.forEach(function (p, k) { if (Math.abs(p.slope - d) < Math.abs(D.planes[best].slope - d)) best = k; });
  window.lfview.lastClick = {x: x, y: y, disparity: d, target: best};
  window.lfview.showingAllInFocus = false;
  sweepTo(best);
});
focus.addEventListener("input", function () { setPlane(parseInt(focus.value, 10)); });
frameInput.addEventListener("input", function () { setFrame(parseInt(frameInput.value, 10)); });
let player = null;
document.getElementById("play").addEventListener("click", function () {
  if (player) { clearInterval(player); player = null; this.textContent = "play"; return; }
  this.textContent = "pause";
  player = setInterval(function () { setFrame((window.lfview.frame + 1) % D.frames); }, 1000 / D.fps);
});
document.getElementById("aif").addEventListener("click", function () {
  window.lfview.showingAllInFocus = !window.lfview.showingAllInFocus; show();
});
document.addEventListener("keydown", function (e) {
  if (e.key === "ArrowUp") { setPlane(window.lfview.plane + 1); e.preventDefault(); }
  else if (e.key === "ArrowDown") { setPlane(window.lfview.plane - 1); e.preventDefault(); }
  else if (e.key === "ArrowRight") { setFrame(window.lfview.frame + 1); e.preventDefault(); }
  else if (e.key === "ArrowLeft") { setFrame(window.lfview.frame - 1); e.preventDefault(); }
});
window.addEventListener("resize", fit);
fit(); show();
</script></body></html>
"""


__all__ = ["DISPARITY_SIDE", "disparity_record", "write_disparity_json", "write_viewer"]
