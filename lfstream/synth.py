"""Synthetic light-field scenes and videos with ground-truth disparity.

A camera array looks at a layered scene: a (possibly slanted) textured background plane
and several textured shapes in front of it, each at its own disparity, composited with
occlusion. Layers move over time (object motion plus a camera pan with parallax), the
exposure can drift, and the sensor can add noise and Lytro-like vignetting.

Rendering is exact for planes: a fronto-parallel layer at disparity ``d`` appears in view
``(u, v)`` translated by ``(-d*(u-u0), -d*(v-v0))`` (lfstream's HCI sign); a slanted plane,
whose disparity is affine in the centre view's coordinates, maps by an exactly inverted
affine warp. The ground truth is the disparity of the front-most opaque layer per pixel of
every view, in pixels per view step.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from lfstream.errors import LFValueError
from lfstream.lightfield import MAX_VIEW_SIDE, MAX_VIEWS_PER_AXIS


@dataclass(frozen=True)
class SynthConfig:
    """What to render. Every random choice derives from ``seed``.

    Attributes:
        frames: number of frames T.
        views: views per axis (U = V).
        size: (H, W) of each view.
        layers: shapes in front of the background.
        disparity_range: (far, near) disparities in pixels per view step; the background
            takes values near ``far``, shapes spread up to ``near``.
        slanted_background: give the background a disparity gradient.
        motion: largest shape speed in pixels per frame (0 for a static scene).
        camera_pan: lateral camera motion in pixels per frame (parallax: nearer layers move more).
        exposure_drift: relative exposure change over the clip (0.1 = +-10 %).
        noise: sensor noise standard deviation in 8-bit levels (0: none); signal-dependent
            shot noise plus read noise.
        vignetting: strength in [0, 1] of a corner-view and radial falloff like a Lytro capture.
        seed: random seed.
        travel_frames: the number of frames the scene is laid out for (its canvas, the
            exposure cycle); ``None``: ``frames``. A clip of ``frames <= travel_frames`` is then
            the first frames of any longer one with the same settings.
    """

    frames: int = 1
    views: int = 7
    size: tuple[int, int] = (128, 128)
    layers: int = 4
    disparity_range: tuple[float, float] = (-1.0, 1.5)
    slanted_background: bool = True
    motion: float = 1.5
    camera_pan: float = 0.5
    exposure_drift: float = 0.0
    noise: float = 0.0
    vignetting: float = 0.0
    travel_frames: int | None = None
    seed: int = 0

    def validate(self) -> None:
        h, w = self.size
        if not 1 <= self.frames <= 100000:
            raise LFValueError(f"frames: must be in 1..100000, got {self.frames}")
        if self.travel_frames is not None and not 1 <= self.travel_frames <= 100000:
            raise LFValueError(f"travel_frames: must be in 1..100000, got {self.travel_frames}")
        if not 1 <= self.views <= MAX_VIEWS_PER_AXIS:
            raise LFValueError(f"views: must be in 1..{MAX_VIEWS_PER_AXIS}, got {self.views}")
        if not (8 <= h <= MAX_VIEW_SIDE and 8 <= w <= MAX_VIEW_SIDE):
            raise LFValueError(f"size: each side must be in 8..{MAX_VIEW_SIDE}, got {h}x{w}")
        lo, hi = self.disparity_range
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise LFValueError(f"disparity_range: need finite far <= near, got {self.disparity_range}")
        if self.layers < 0 or self.noise < 0 or not 0 <= self.vignetting <= 1:
            raise LFValueError("layers and noise must be >= 0 and vignetting in [0, 1]")


@dataclass
class SynthClip:
    """A rendered clip: ``lf`` (T, U, V, H, W, 3) uint8 and ``disparity`` (T, U, V, H, W) float32."""

    lf: np.ndarray
    disparity: np.ndarray
    config: SynthConfig = field(default_factory=SynthConfig)


# ----------------------------------------------------------------------------------------
# Textures


@lru_cache(maxsize=1)
def _package_images() -> tuple[np.ndarray, ...]:
    """Natural images shipped inside installed packages (scikit-image's data), if present."""
    try:
        from skimage import data
    except ImportError:
        return ()
    imgs = []
    for name in ("astronaut", "coffee", "chelsea", "rocket", "immunohistochemistry"):
        try:
            img = getattr(data, name)()
        except Exception:  # a data file missing from a trimmed install: skip that image
            continue
        if img.ndim == 3 and img.shape[2] >= 3:
            imgs.append(np.ascontiguousarray(img[:, :, :3]).astype(np.float32) / 255.0)
    return tuple(imgs)


def _value_noise(rng: np.random.Generator, h: int, w: int, octaves: int = 5) -> np.ndarray:
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cells = 2 ** (o + 2)
        grid = rng.random((cells + 1, cells + 1)).astype(np.float32)
        out += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
        amp *= 0.55
    out /= total
    return (out - out.min()) / max(float(np.ptp(out)), 1e-6)


def _texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """An (h, w, 3) float32 texture in [0, 1]: a crop of a natural image or a procedural pattern."""
    kind = rng.integers(0, 4)
    imgs = _package_images()
    if kind == 0 and imgs:
        img = imgs[int(rng.integers(0, len(imgs)))]
        scale = max(h / img.shape[0], w / img.shape[1]) * rng.uniform(1.0, 1.6)
        big = cv2.resize(img, (int(np.ceil(img.shape[1] * scale)) + 1, int(np.ceil(img.shape[0] * scale)) + 1))
        y0 = int(rng.integers(0, big.shape[0] - h + 1))
        x0 = int(rng.integers(0, big.shape[1] - w + 1))
        return np.ascontiguousarray(big[y0 : y0 + h, x0 : x0 + w])
    base = rng.random(3).astype(np.float32)
    # the second colour is roughly the complement of the first, so every pattern has contrast
    tint = np.clip(1.0 - base + rng.uniform(-0.2, 0.2, 3), 0, 1).astype(np.float32)
    n = _value_noise(rng, h, w)
    if kind == 1:  # stripes with noise, strong orientation for disparity cues
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        theta = rng.uniform(0, np.pi)
        period = rng.uniform(4, 16)
        pat = 0.5 + 0.5 * np.sin(2 * np.pi * (xx * np.cos(theta) + yy * np.sin(theta)) / period)
        t = 0.6 * pat + 0.4 * n
    elif kind == 2:  # checkers
        cell = int(rng.integers(4, 14))
        yy, xx = np.mgrid[0:h, 0:w]
        t = 0.7 * (((yy // cell) + (xx // cell)) % 2).astype(np.float32) + 0.3 * n
    else:
        t = n
    return np.clip(base[None, None] * (1 - t[..., None]) + tint[None, None] * t[..., None], 0, 1).astype(np.float32)


def _shape_mask(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """An anti-aliased (h, w) float32 mask of a random ellipse, rectangle or polygon."""
    mask = np.zeros((h * 4, w * 4), np.uint8)  # 4x supersampling for soft edges
    cy, cx = rng.uniform(0.2, 0.8) * h * 4, rng.uniform(0.2, 0.8) * w * 4
    ry, rx = rng.uniform(0.1, 0.3) * h * 4, rng.uniform(0.1, 0.3) * w * 4
    kind = rng.integers(0, 3)
    if kind == 0:
        cv2.ellipse(mask, (int(cx), int(cy)), (int(rx), int(ry)), float(rng.uniform(0, 180)), 0, 360, 255, -1)
    elif kind == 1:
        cv2.rectangle(mask, (int(cx - rx), int(cy - ry)), (int(cx + rx), int(cy + ry)), 255, -1)
    else:
        n = int(rng.integers(3, 8))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        rad = rng.uniform(0.5, 1.0, n)
        pts = np.stack([cx + rx * rad * np.cos(ang), cy + ry * rad * np.sin(ang)], 1).astype(np.int32)
        cv2.fillPoly(mask, [pts], 255)
    return cv2.resize(mask, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


# ----------------------------------------------------------------------------------------
# Rendering


@dataclass
class _Layer:
    texture: np.ndarray  # (Hb, Wb, 3) on the enlarged canvas
    mask: np.ndarray | None  # (Hb, Wb) or None for the opaque background
    disparity: float  # at the canvas centre
    gradient: tuple[float, float]  # d(disparity)/dy, d/dx in centre-view pixels
    velocity: tuple[float, float]  # pixels per frame (y, x)

    @property
    def bbox(self) -> tuple[int, int, int, int]:
        """(y0, y1, x0, x1) of the mask's support on the canvas, or the whole canvas."""
        if not hasattr(self, "_bbox"):
            if self.mask is None:
                self._bbox = (0, self.texture.shape[0], 0, self.texture.shape[1])
            else:
                ys, xs = np.nonzero(self.mask > 0)
                self._bbox = (int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1) if ys.size else (0, 0, 0, 0)
        return self._bbox

    @property
    def rgba(self) -> np.ndarray:
        if not hasattr(self, "_rgba"):
            alpha = np.ones(self.texture.shape[:2], np.float32) if self.mask is None else self.mask
            self._rgba = np.ascontiguousarray(np.dstack([self.texture, alpha]))
        return self._rgba


def _view_warp(layer: _Layer, du: int, dv: int, offset: tuple[float, float], cy: float, cx: float,
               margin: int) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Affine map from view pixels to canvas pixels, and the layer's disparity at view pixels.

    Centre-view coordinates c = (y, x) relative to the image centre; disparity
    d(c) = d0 + gy*y + gx*x; a view pixel is p = c - d(c) * (du, dv). Solving for c:
    c = A^-1 (p + d0 * (du, dv)) with A = I - (du, dv)^T (gy, gx), a closed-form 2x2 inverse.
    Returns the 2x3 matrix for ``cv2.warpAffine`` (x first) and (d_const, d_y, d_x) with
    d(p) = d_const + d_y * y_p + d_x * x_p in absolute view pixel coordinates.
    """
    gy, gx = layer.gradient
    d0 = layer.disparity
    a00, a01, a10, a11 = 1.0 - du * gy, -du * gx, -dv * gy, 1.0 - dv * gx
    det = a00 * a11 - a01 * a10
    i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
    ty = i00 * d0 * du + i01 * d0 * dv
    tx = i10 * d0 * du + i11 * d0 * dv
    # canvas = A^-1 (q - centre) + t + centre + margin - offset for view pixel q
    cyc = ty + cy + margin - offset[0] - (i00 * cy + i01 * cx)
    cxc = tx + cx + margin - offset[1] - (i10 * cy + i11 * cx)
    m = np.array([[i11, i10, cxc], [i01, i00, cyc]], np.float64)
    dy, dx = gy * i00 + gx * i10, gy * i01 + gx * i11
    dconst = d0 + gy * ty + gx * tx - (dy * cy + dx * cx)
    return m, (dconst, dy, dx)


def iter_clip(config: SynthConfig = SynthConfig()) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Renders a clip frame by frame (memory of one frame, for long streams); yields
    ``(lf (U, V, H, W, 3) uint8, disparity (U, V, H, W) float32)``, the same frames as
    :func:`render_clip`, each its own arrays."""
    for lf, disp in _frames(config):
        yield lf.copy(), disp.copy()


def _frames(config: SynthConfig) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """:func:`iter_clip`'s frames in buffers the next frame overwrites (callers copy what
    they keep: one copy a frame, into memory they own)."""
    config.validate()
    rng = np.random.default_rng(config.seed)
    t_n, n = config.frames, config.views
    t_layout = max(t_n, config.travel_frames or t_n)  # what the canvas and the exposure cycle span
    h, w = config.size
    far, near = config.disparity_range
    u0 = n // 2
    max_travel = (config.motion + abs(config.camera_pan) * (1 + max(abs(far), abs(near)))) * (t_layout - 1)
    margin = int(np.ceil(max(abs(far), abs(near)) * u0 + max_travel + 4))
    hb, wb = h + 2 * margin, w + 2 * margin
    cy, cx = (h - 1) / 2.0, (w - 1) / 2.0

    layers: list[_Layer] = []
    # The slanted background stays inside [far, near] over every pixel any view sees: its
    # disparity varies by at most `span` over the image plus the parallax margin.
    span = 0.15 * (near - far) if config.slanted_background else 0.0
    bg_d = far + span + 0.15 * (near - far) * rng.random()
    reach_y, reach_x = h / 2 + abs(near) * u0 + 1, w / 2 + abs(near) * u0 + 1
    grad = (rng.uniform(-0.5, 0.5) * span / reach_y, rng.uniform(-0.5, 0.5) * span / reach_x)
    layers.append(_Layer(_texture(rng, hb, wb), None, bg_d, grad, (0.0, 0.0)))
    depths = np.sort(rng.uniform(bg_d + 0.2 * (near - bg_d), near, config.layers))  # back to front
    for d in depths:
        vel = rng.uniform(-1, 1, 2) * config.motion
        layers.append(_Layer(_texture(rng, hb, wb), _shape_mask(rng, hb, wb), float(d), (0.0, 0.0), (vel[0], vel[1])))

    lf = np.empty((1, n, n, h, w, 3), np.uint8)
    disp = np.empty((1, n, n, h, w), np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    vig = _vignetting_gains(n, h, w, config.vignetting)
    views = np.empty((n, n, h, w, 3), np.float32)
    for t in range(t_n):
        for u in range(n):
            for v in range(n):
                img = views[u, v]
                dmap = disp[0, u, v]
                for layer in layers:
                    pan = config.camera_pan * t * (1.0 + layer.disparity)  # parallax: near moves more
                    off = (layer.velocity[0] * t, layer.velocity[1] * t + pan)
                    m, (dc, dy, dx) = _view_warp(layer, u - u0, v - u0, off, cy, cx, margin)
                    # m maps view pixels to canvas pixels, hence WARP_INVERSE_MAP; texture and
                    # mask travel together in one 4-channel warp.
                    if layer.mask is None:
                        cv2.warpAffine(layer.texture, m, (w, h), dst=img, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                       borderMode=cv2.BORDER_REFLECT)
                        dmap[:] = dc if dy == 0 and dx == 0 else dc + dy * yy + dx * xx
                        continue
                    # Shapes are fronto-parallel (a pure translation): warp only the view
                    # rectangle their support lands in.
                    by0, by1, bx0, bx1 = layer.bbox
                    ry0, ry1 = max(0, int(np.floor(by0 - m[1, 2])) - 1), min(h, int(np.ceil(by1 - m[1, 2])) + 1)
                    rx0, rx1 = max(0, int(np.floor(bx0 - m[0, 2])) - 1), min(w, int(np.ceil(bx1 - m[0, 2])) + 1)
                    if ry1 <= ry0 or rx1 <= rx0:
                        continue
                    mr = m.copy()
                    mr[:, 2] += m[:, :2] @ np.array([rx0, ry0], np.float64)
                    warped = cv2.warpAffine(layer.rgba, mr, (rx1 - rx0, ry1 - ry0),
                                            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderValue=0.0)
                    a = np.ascontiguousarray(warped[..., 3])
                    roi = img[ry0:ry1, rx0:rx1]
                    roi += a[..., None] * (warped[..., :3] - roi)  # "over" compositing
                    np.copyto(dmap[ry0:ry1, rx0:rx1], np.float32(dc), where=a > 0.5)
        gain = 1.0 + config.exposure_drift * np.sin(2 * np.pi * t / max(t_layout, 2))
        if gain != 1.0:
            views *= gain
        if vig is not None:
            views *= vig[..., None]
        if config.noise > 0:
            # shot noise (variance grows with the signal) plus read noise: `noise` 8-bit levels
            # of standard deviation at mid-grey, half of it in the dark
            std = np.clip(views, 0.0, 1.0)
            std *= 1.5
            std += 0.25
            np.sqrt(std, out=std)
            std *= np.float32(config.noise / 255.0)
            std *= rng.standard_normal(views.shape, dtype=np.float32)
            views += std
        np.clip(views, 0.0, 1.0, out=views)
        # one rounding, saturating pass to uint8 (OpenCV), on a 2-D view of the frame
        lf[0] = cv2.convertScaleAbs(views.reshape(n * n * h, w * 3), alpha=255.0).reshape(n, n, h, w, 3)
        yield lf[0], disp[0]


def render_clip(config: SynthConfig = SynthConfig()) -> SynthClip:
    """Renders a clip; deterministic for a given config (including its seed).

    Returns:
        :class:`SynthClip` with ``lf`` (T, U, V, H, W, 3) uint8 and ``disparity``
        (T, U, V, H, W) float32 in pixels per view step.
    """
    config.validate()
    n, (h, w) = config.views, config.size
    # written frame by frame into arrays of the whole clip (a list of copies, stacked, held
    # the clip twice and copied it once more: 2.9 of 7.8 s for 20 frames of 7x7x375x540)
    lf = np.empty((config.frames, n, n, h, w, 3), np.uint8)
    disparity = np.empty((config.frames, n, n, h, w), np.float32)
    for t, (frame, disp) in enumerate(_frames(config)):
        lf[t], disparity[t] = frame, disp
    return SynthClip(lf=lf, disparity=disparity, config=config)


@lru_cache(maxsize=8)
def _vignetting_gains(n: int, h: int, w: int, strength: float) -> np.ndarray | None:
    """(n, n, h, w) gains: darker towards each view's edge and much darker in corner views."""
    if strength <= 0:
        return None
    from lfstream.optics import radial_falloff

    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r = np.hypot((yy - (h - 1) / 2) / (h / 2), (xx - (w - 1) / 2) / (w / 2)) / np.sqrt(2)  # 0 centre, 1 corner
    c = n // 2
    du, dv = np.meshgrid(np.arange(n) - c, np.arange(n) - c, indexing="ij")
    rv = (np.hypot(du, dv) / max(np.hypot(c, c), 1)).astype(np.float32)  # 0 centre view, 1 corner view
    # views further from the centre lose more light (the main lens's mechanical vignetting)
    falloff = radial_falloff(r[None, None] * (0.5 + rv[:, :, None, None]), 1.0, 2.0 * strength).astype(np.float32)
    return falloff * (1 - 0.6 * strength * rv**4)[:, :, None, None]


def synth_clip(frames: int = 1, views: int = 7, size: tuple[int, int] = (128, 128), seed: int = 0, **options) -> SynthClip:
    """Shorthand for ``render_clip(SynthConfig(frames=..., views=..., size=..., seed=..., **options))``."""
    return render_clip(SynthConfig(frames=frames, views=views, size=tuple(size), seed=seed, **options))


def fronto_parallel_plane(views: int, size: tuple[int, int], disparity: float, seed: int = 0) -> SynthClip:
    """One textured plane at constant disparity filling every view (a test pattern)."""
    return render_clip(SynthConfig(frames=1, views=views, size=size, layers=0, disparity_range=(disparity, disparity),
                                   slanted_background=False, motion=0.0, camera_pan=0.0, seed=seed))


__all__ = ["SynthConfig", "SynthClip", "render_clip", "iter_clip", "synth_clip", "fronto_parallel_plane"]
