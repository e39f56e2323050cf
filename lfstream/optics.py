"""Plenoptic-camera optics (seed chapter 2): refocus parameters, SPC <-> camera array,
depth of field, vignetting.

Refocus parameters, all equivalent:

* ``alpha`` (Ng 2005, seed Eq. 2.3): the synthetic film plane at ``F' = alpha * F``. View
  ``(u, v)`` is shifted by ``(1 - 1/alpha) * (u - u0, v - v0)`` pixels before averaging.
  ``alpha = 1`` keeps the captured focus, ``alpha < 1`` focuses farther, ``alpha > 1`` nearer.
* ``slope`` (HCI, plenpy): the shift in pixels per view step, ``slope = 1 - 1/alpha``.
  Refocusing at ``slope = d`` brings points of disparity ``d`` into focus (lfstream's
  disparity convention, :mod:`lfstream.lightfield`). ``alpha = 1 / (1 - slope)``, so slopes
  ``>= 1`` have no positive alpha; lfstream accepts them as slopes.
* Hahne's shift ``a``: the same pixel shift between adjacent views used by the seed's
  Table 2.1 (there called "alpha"); ``a = slope``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass

import numpy as np

from lfstream.errors import LFShapeError, LFValueError

#: The seed's sixteen refocus parameters, alpha = 0.125, 0.25, ..., 2.0.
SEED_ALPHAS: tuple[float, ...] = tuple(0.125 * k for k in range(1, 17))


def check_alpha(alpha: float) -> float:
    """Returns ``alpha`` as float; rejects non-finite or non-positive values."""
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise LFValueError(f"alpha: expected a number, got {alpha!r}") from None
    if not math.isfinite(a) or a <= 0:
        raise LFValueError(f"alpha: must be finite and > 0 (1 - 1/alpha diverges at 0), got {alpha!r}")
    return a


def slope_from_alpha(alpha: float) -> float:
    """``slope = 1 - 1/alpha`` (pixels of shift per view step)."""
    return 1.0 - 1.0 / check_alpha(alpha)


def alpha_from_slope(slope: float) -> float:
    """``alpha = 1 / (1 - slope)``; raises for slopes ``>= 1`` (no finite positive alpha)."""
    s = float(slope)
    if not math.isfinite(s):
        raise LFValueError(f"slope: must be finite, got {slope!r}")
    if s >= 1.0:
        raise LFValueError(f"slope {s} >= 1 has no finite positive alpha; refocus by slope instead")
    return 1.0 / (1.0 - s)


def slopes_from_alphas(alphas: Iterable[float]) -> np.ndarray:
    """Vectorised :func:`slope_from_alpha`; returns float64 ``(K,)``."""
    return np.array([slope_from_alpha(a) for a in alphas], dtype=np.float64)


def radial_falloff(d, r: float, a: float):
    """Two-parameter radial falloff ``F(d; r, a) = 1 / (1 + (d / r)^(2a))``.

    ``d`` is the distance from the centre, ``r`` the radius where the transmission has
    fallen to one half and ``a`` the steepness: small ``a`` is a gentle fall from the
    centre (main-lens vignetting), large ``a`` approaches a hard disc of radius ``r`` (the
    round image of the aperture under a microlens). Values lie in ``(0, 1]``, 1 at the centre.
    """
    if not (np.isfinite(r) and r > 0 and np.isfinite(a) and a >= 0):
        raise LFValueError(f"radial_falloff: need r > 0 and a >= 0, got r={r!r}, a={a!r}")
    d = np.abs(np.asarray(d, dtype=np.float64))
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + (d / r) ** (2.0 * a))


# ----------------------------------------------------------------------------------------
# Standard plenoptic camera <-> camera array (seed §2.2)


@dataclass(frozen=True)
class PlenopticCamera:
    """A standard plenoptic camera (SPC): main lens, microlens array (MLA), sensor.

    Attributes:
        focal_length_mm: main-lens focal length F.
        f_number: main-lens f-number; aperture A = F / f_number.
        microlenses: M microlenses per axis.
        pixels_per_lens: N pixels per axis under each microlens.
        microlens_pitch_mm: default ``A / M`` (the MLA spans the aperture's image, as in
            the seed's worked example: 50 mm / 500 = 0.1 mm).
        pixel_pitch_mm: default ``microlens_pitch / N``.
        focus_distance_m: object distance the main lens is focused on (``inf``: the MLA
            sits at the focal plane, image distance ``b = F``).
        principal_plane_gap_mm: distance between the main lens's principal planes (0 for a
            thin lens); only shifts distances measured from the MLA.

    The microlens focal length follows f-number matching: ``f_s = f_number * pitch``.
    """

    focal_length_mm: float
    f_number: float
    microlenses: int
    pixels_per_lens: int
    microlens_pitch_mm: float | None = None
    pixel_pitch_mm: float | None = None
    focus_distance_m: float = math.inf
    principal_plane_gap_mm: float = 0.0

    def __post_init__(self) -> None:
        for name in ("focal_length_mm", "f_number"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val > 0):
                raise LFValueError(f"{name}: must be finite and > 0, got {val!r}")
        for name in ("microlenses", "pixels_per_lens"):
            val = getattr(self, name)
            if not isinstance(val, (int, np.integer)) or val < 1:
                raise LFValueError(f"{name}: must be a positive integer, got {val!r}")
        for name in ("microlens_pitch_mm", "pixel_pitch_mm"):
            val = getattr(self, name)
            if val is not None and not (math.isfinite(val) and val > 0):
                raise LFValueError(f"{name}: must be finite and > 0, got {val!r}")
        if not self.focus_distance_m * 1000.0 > self.focal_length_mm:
            raise LFValueError(f"focus_distance_m: must exceed the focal length, got {self.focus_distance_m!r}")

    @property
    def aperture_mm(self) -> float:
        return self.focal_length_mm / self.f_number

    @property
    def lens_pitch_mm(self) -> float:
        return self.microlens_pitch_mm if self.microlens_pitch_mm is not None else self.aperture_mm / self.microlenses

    @property
    def pitch_mm(self) -> float:
        """Pixel pitch."""
        return self.pixel_pitch_mm if self.pixel_pitch_mm is not None else self.lens_pitch_mm / self.pixels_per_lens

    @property
    def microlens_focal_length_mm(self) -> float:
        return self.f_number * self.lens_pitch_mm

    @property
    def image_distance_mm(self) -> float:
        """Main lens to MLA, from the thin-lens equation for the focus distance."""
        f = self.focal_length_mm
        if math.isinf(self.focus_distance_m):
            return f
        o = self.focus_distance_m * 1000.0
        return 1.0 / (1.0 / f - 1.0 / o)


@dataclass(frozen=True)
class CameraArray:
    """The camera array equivalent to an SPC (seed Eq. 2.5-2.7).

    ``positions_mm[i][j]`` is camera (i, j)'s (y, x) centre on the main-lens plane; the array
    is centred on the optical axis (Hahne's correction of Dansereau's model). View (u, v)
    of the light field is camera (u, v)'s image: ``L(s, t, u, v) = I_C(u,v)(s, t)``.
    """

    cameras: tuple[int, int]
    camera_aperture_mm: float
    camera_focal_length_mm: float
    camera_fov_deg: float
    camera_resolution: tuple[int, int]
    positions_mm: tuple[tuple[tuple[float, float], ...], ...]

    @property
    def baseline_mm(self) -> float:
        """Distance between neighbouring cameras (their apertures abut)."""
        return self.camera_aperture_mm

    def as_dict(self) -> dict:
        d = asdict(self)
        d["cameras"] = list(self.cameras)
        d["camera_resolution"] = list(self.camera_resolution)
        d["positions_mm"] = [[list(p) for p in row] for row in self.positions_mm]
        return d


def camera_array(spc: PlenopticCamera) -> CameraArray:
    """The N x N camera array equivalent to a plenoptic camera.

    Each camera's aperture is ``A / N`` per axis and its focal length ``F / N`` (same
    f-number as the main lens); its field of view is ``2 arctan(A / 2F)`` (seed Eq. 2.5) and
    its resolution M x M. The seed's Eq. 2.6 writes ``A / (N x N)``, but its own worked example
    (F = 100 mm, f/2, N = 25: cameras of 2 mm aperture and 4 mm focal length) needs ``A / N``
    per axis; this follows the example.
    """
    n, m = spc.pixels_per_lens, spc.microlenses
    a = spc.aperture_mm / n
    c = (n - 1) / 2.0
    positions = tuple(tuple(((i - c) * a, (j - c) * a) for j in range(n)) for i in range(n))
    fov = math.degrees(2.0 * math.atan(spc.aperture_mm / (2.0 * spc.focal_length_mm)))
    return CameraArray((n, n), a, spc.focal_length_mm / n, fov, (m, m), positions)


def plenoptic_camera(array: CameraArray) -> PlenopticCamera:
    """The inverse of :func:`camera_array`: the SPC an abutting N x N camera array models."""
    n_u, n_v = array.cameras
    if n_u != n_v or array.camera_resolution[0] != array.camera_resolution[1]:
        raise LFShapeError(f"camera array: needs a square grid and resolution, got {array.cameras}, {array.camera_resolution}")
    f = array.camera_focal_length_mm * n_u
    a = array.camera_aperture_mm * n_u
    return PlenopticCamera(focal_length_mm=f, f_number=f / a, microlenses=array.camera_resolution[0], pixels_per_lens=n_u)


# ----------------------------------------------------------------------------------------
# Refocus distance and depth of field (Hahne's ray model, thin lens)


@dataclass(frozen=True)
class RefocusPlane:
    """Where a refocus shift puts the focus. Distances in metres from the MLA (the sensor
    side, as Hahne measures), ``inf`` where the plane or a border lies at or beyond infinity."""

    slope: float
    alpha: float | None
    focus_m: float
    dof_near_m: float
    dof_far_m: float


def _ray_intersection(p0: float, m0: float, p1: float, m1: float) -> float:
    """Distance t in front of the MLA where rays x = p + m t cross (inf for parallel rays)."""
    if m0 == m1:
        return math.inf
    return (p1 - p0) / (m0 - m1)


def refocus_plane(spc: PlenopticCamera, slope: float) -> RefocusPlane:
    """Focus distance and depth-of-field borders of the plane refocused with ``slope``.

    Model (Hahne et al. 2016, which the seed validated): the refocused pixel combines the
    outermost views of a microlens row, whose chief rays leave pixel centres, pass through
    microlens centres ``slope * (N - 1)`` lenses apart and cross behind the main lens; the
    thin-lens equation maps the crossing to object space. Pixels sit relative to their
    micro-image centre, which the main lens's exit pupil (at distance ``b``) projects
    outwards from each microlens by ``f_s / b``. The depth-of-field borders come from the
    rays through the opposite pixel and microlens borders.

    Args:
        spc: the camera.
        slope: shift in pixels per view step (Hahne's ``a``); 0 keeps the main lens's focus.
    """
    if not math.isfinite(slope):
        raise LFValueError(f"slope: must be finite, got {slope!r}")
    n = spc.pixels_per_lens
    pm, pp, fs = spc.lens_pitch_mm, spc.pitch_mm, spc.microlens_focal_length_mm
    b, f = spc.image_distance_mm, spc.focal_length_mm
    c = (n - 1) / 2.0
    # microlens positions of the two outer views, centred on the axis as far as possible
    j0 = -round(slope * (n - 1) / 2.0, 9)
    js = (j0, slope * (n - 1) + j0)
    rays_centre, rays_upper, rays_lower = [], [], []
    for k, i in enumerate((c, -c)):
        s = js[k] * pm
        centre = s + s * fs / b  # micro-image centre on the sensor
        u = centre + i * pp
        rays_centre.append((s, (s - u) / fs))
        # border rays: through the pixel's upper/lower edge and the lens's upper/lower edge
        rays_upper.append((s + pm / 2, (s - (u + pp / 2)) / fs))
        rays_lower.append((s - pm / 2, (s - (u - pp / 2)) / fs))

    def object_distance(t: float) -> float:
        b_new = b - t  # image-side crossing, measured from the main lens
        if not math.isfinite(t) or b_new <= f:
            return math.inf
        return (1.0 / (1.0 / f - 1.0 / b_new) + b + spc.principal_plane_gap_mm) / 1000.0

    focus = object_distance(_ray_intersection(*rays_centre[0], *rays_centre[1]))
    near = object_distance(_ray_intersection(*rays_lower[0], *rays_upper[1]))
    far = object_distance(_ray_intersection(*rays_upper[0], *rays_lower[1]))
    near, far = min(near, far), max(near, far)
    alpha = 1.0 / (1.0 - slope) if slope < 1 else None
    return RefocusPlane(slope=float(slope), alpha=alpha, focus_m=focus, dof_near_m=near, dof_far_m=far)


def slope_for_distance(spc: PlenopticCamera, distance_m: float) -> float:
    """The slope whose refocus plane lies at ``distance_m`` (inverse of :func:`refocus_plane`)."""
    if not (math.isfinite(distance_m) and distance_m * 1000.0 > spc.focal_length_mm + spc.image_distance_mm):
        raise LFValueError(f"distance_m: must be finite and beyond the camera, got {distance_m!r}")
    lo, hi = -5.0 * spc.pixels_per_lens, 5.0 * spc.pixels_per_lens
    # focus distance decreases monotonically as the slope grows (for slopes above the
    # main lens's own focus); bisection on the model keeps one source of truth
    lo = 0.0 if math.isinf(spc.focus_distance_m) else lo
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        d = refocus_plane(spc, mid).focus_m
        if d > distance_m:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# ----------------------------------------------------------------------------------------
# Vignetting as masks on the 4-D light field (seed §2.4)


def main_lens_vignetting(views: tuple[int, int], size: tuple[int, int], r: float, a: float) -> np.ndarray:
    """Main-lens vignetting: a radial falloff over the whole sensor, mapped to 4-D.

    The falloff ``F(d; r, a)`` is evaluated at each sensor pixel's distance ``d`` from the
    sensor centre, in units of the sensor's half-diagonal, and the sensor image is turned
    into the ``(U, V, H, W)`` mask by seed Eq. 2.4. Every view keeps light: the falloff is
    smooth across the sensor, so each view is darkened at its borders, not removed.
    """
    from lfstream.lightfield import from_sensor

    u, v = views
    h, w = size
    sh, sw = h * u, w * v
    yy, xx = np.mgrid[0:sh, 0:sw].astype(np.float64)
    d = np.hypot(yy - (sh - 1) / 2, xx - (sw - 1) / 2) / np.hypot(sh / 2, sw / 2)
    sensor = radial_falloff(d, r, a).astype(np.float32)
    return np.ascontiguousarray(from_sensor(sensor[:, :, None], (u, v))[..., 0])


def mla_vignetting(views: tuple[int, int], size: tuple[int, int], r: float, a: float) -> np.ndarray:
    """Microlens vignetting: the same falloff inside every micro-image.

    ``d`` is a pixel's distance from its micro-image centre in pixels; a micro-image is the
    round image of the main-lens aperture, so the corner pixels of each U x V block — the
    corner views — fall off fastest. With ``a`` large the falloff is a hard disc of radius
    ``r`` pixels and the corner views are removed (seed §2.4.2).

    Shape:
        - output: ``(U, V, H, W)`` float32
    """
    u, v = views
    h, w = size
    du = np.arange(u) - (u - 1) / 2
    dv = np.arange(v) - (v - 1) / 2
    d = np.hypot(du[:, None], dv[None, :])
    per_view = radial_falloff(d, r, a).astype(np.float32)
    return np.ascontiguousarray(np.broadcast_to(per_view[:, :, None, None], (u, v, h, w)))


def apply_vignetting(lf, mask):
    """Hadamard product of a light field with a ``(U, V, H, W)`` mask, on the 4-D array as is.

    Shape:
        - lf: ``(*, U, V, H, W, C)``; mask: ``(U, V, H, W)``
        - output: like ``lf``, float (uint8 input becomes float32 in [0, 1])
    """
    from lfstream.lightfield import as_float, check_lf

    shape = check_lf(lf)
    if tuple(mask.shape) != tuple(shape[-5:-1]):
        raise LFShapeError(f"mask: expected shape {tuple(shape[-5:-1])}, got {tuple(mask.shape)}")
    x = as_float(lf)
    import torch

    if isinstance(x, torch.Tensor):
        m = torch.as_tensor(np.asarray(mask, np.float32), device=x.device, dtype=x.dtype)
        return x * m[..., None]
    return x * np.asarray(mask, np.float32)[..., None]


__all__ = [
    "main_lens_vignetting",
    "mla_vignetting",
    "apply_vignetting",
    "PlenopticCamera",
    "CameraArray",
    "RefocusPlane",
    "camera_array",
    "plenoptic_camera",
    "refocus_plane",
    "slope_for_distance",
    "radial_falloff", "SEED_ALPHAS", "check_alpha", "slope_from_alpha", "alpha_from_slope", "slopes_from_alphas"]
