"""The light-field array convention and the operations on it.

Convention (stated once, used everywhere):

* A frame is an array of shape ``(U, V, H, W, C)``; a video is ``(T, U, V, H, W, C)``.
  ``u`` indexes the *row* and ``v`` the *column* of the view grid, ``C`` is 3 (RGB).
* The centre view is ``(U // 2, V // 2)``.
* uint8 at the boundaries (files, bitstreams, the public decode result); float32 in
  ``[0, 1]`` inside the numerical stages.
* Disparity (HCI convention): a scene point at pixel ``(y, x)`` of the centre view with
  disparity ``d`` appears at ``(y - d*(u - u0), x - d*(v - v0))`` in view ``(u, v)``;
  ``d > 0`` means nearer than the focal plane. Units are pixels per view step.
* View axes: a capture whose grid is not aligned with the image axes (a camera array with
  its rows flipped, its row and column baselines unequal, or the rig rotated against the
  sensor) moves a point by ``d * A @ (u - u0, v - v0)`` instead, where ``A`` is a 2x2
  matrix mapping a view step to a displacement ``(dy, dx)`` per unit disparity; the
  convention above is ``A = I``. The codec estimates ``A`` per stream and sends it with the
  depth hint (:mod:`lfstream.codec.hint`); :func:`view_offsets` is the one place that
  turns it into per-view offsets.

Every function here accepts a numpy array or a torch tensor and returns the same kind,
because they are pure re-indexing or averaging operations.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from lfstream.errors import LFShapeError, LFValueError

if TYPE_CHECKING:
    import torch

    ArrayT = TypeVar("ArrayT", np.ndarray, torch.Tensor)
else:
    ArrayT = TypeVar("ArrayT")

#: Largest number of views per axis or pixels per side accepted anywhere, so that a
#: corrupt header or a wrong argument fails early instead of allocating terabytes.
MAX_VIEWS_PER_AXIS = 64
MAX_VIEW_SIDE = 16384


def is_tensor(x: object) -> bool:
    """Whether ``x`` is a torch tensor, without importing torch.

    torch is imported only by the code that runs networks; an object can be a tensor only
    once torch has been imported (fast start-up). A torch still being imported by another
    thread has no ``Tensor`` yet, and then nothing is one."""
    tensor = getattr(sys.modules.get("torch"), "Tensor", None)
    return tensor is not None and isinstance(x, tensor)


def _permute(x: ArrayT, axes: tuple[int, ...]) -> ArrayT:
    if is_tensor(x):
        return x.permute(*axes)
    return np.transpose(x, axes)


def _is_array(x: object) -> bool:
    return isinstance(x, np.ndarray) or is_tensor(x)


def check_lf(lf: object, name: str = "lf", allow_video: bool = True) -> tuple[int, ...]:
    """Validates that ``lf`` follows the convention and returns its shape.

    Args:
        lf: candidate light field (numpy array or torch tensor).
        name: how the error message refers to the argument.
        allow_video: accept a 6-D ``(T, U, V, H, W, C)`` array too.

    Returns:
        The shape as a tuple.

    Raises:
        LFShapeError: wrong type, rank, empty axis or channel count.
    """
    if not _is_array(lf):
        raise LFShapeError(f"{name}: expected a numpy array or torch tensor, got {type(lf).__name__}")
    shape = tuple(int(s) for s in lf.shape)  # type: ignore[union-attr]
    ranks = (5, 6) if allow_video else (5,)
    if len(shape) not in ranks:
        want = "(U, V, H, W, C) or (T, U, V, H, W, C)" if allow_video else "(U, V, H, W, C)"
        raise LFShapeError(f"{name}: expected shape {want}, got {shape}")
    if any(s == 0 for s in shape):
        raise LFShapeError(f"{name}: empty axis in shape {shape}")
    if shape[-1] not in (1, 3, 4):
        raise LFShapeError(f"{name}: last axis must be colour channels (1, 3 or 4), got {shape[-1]} in {shape}")
    return shape


def view_offsets(views: tuple[int, int], axes: np.ndarray | None = None) -> np.ndarray:
    """The displacement of every view per unit of centre-view disparity: view ``(u, v)``
    samples the centre view at ``(y, x) + d * offsets[u, v]``.

    Args:
        views: ``(U, V)``.
        axes: ``(2, 2)`` view axes ``A`` (rows ``dy, dx``; columns a step in ``u``, in
            ``v``); ``None``: the convention, ``A = I``, so ``offsets[u, v] = (u - u0, v - v0)``.

    Shape:
        - output: ``(U, V, 2)`` float32
    """
    u, v = views
    steps = np.stack(np.meshgrid(np.arange(u) - u // 2, np.arange(v) - v // 2, indexing="ij"), axis=-1)
    steps = steps.astype(np.float64)
    if axes is not None:
        a = np.asarray(axes, np.float64)
        if a.shape != (2, 2) or not np.all(np.isfinite(a)):
            raise LFValueError(f"axes: expected a finite (2, 2) matrix, got shape {a.shape}")
        steps = steps @ a.T
    return steps.astype(np.float32)


def canonical_views(lf: np.ndarray, axes: np.ndarray | None,
                    present: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """The light field's views reordered so that its grid follows the convention (``A = I``,
    :func:`view_offsets`) as far as an order of views can: swapped where a step along ``u``
    moves points along ``x`` (a grid stored ``(V, U)`` or turned a quarter), then reversed
    along each axis whose steps move points the opposite way (rows or columns of views
    flipped). What is left of ``A`` after that (unequal baselines, a slight turn) stays.
    Refocusing the result with the convention's shifts focuses at the disparity ``d`` the
    codec's hint measures on ``lf`` with ``axes``; its centre view is ``lf``'s.

    A reversed axis of even length loses its last view after reversing (the farthest on the
    side with one view more): the centre view then stays at index ``n // 2``. The result is
    a view of ``lf`` (no copy).

    Args:
        lf: ``(U, V, H, W, C)`` or ``(T, U, V, H, W, C)``.
        axes: the ``(2, 2)`` view axes (``None``: the convention, ``lf`` returned as it is).
        present: ``(U, V)`` mask of views present, reordered the same way.

    Shape:
        - output: ``(U', V', H, W, C)`` (``T`` first for a video), ``U'``, ``V'`` as described
    """
    if axes is None:
        return lf, present
    a = np.asarray(axes, np.float64)
    if a.shape != (2, 2) or not np.all(np.isfinite(a)):
        raise LFValueError(f"axes: expected a finite (2, 2) matrix, got shape {a.shape}")
    lead = lf.ndim - 5
    # which image axis each view axis mostly moves along (row 0: y, row 1: x)
    u_along, v_along = int(np.argmax(np.abs(a[:, 0]))), int(np.argmax(np.abs(a[:, 1])))
    if u_along == 1 and v_along == 0:  # swapped: the grid's rows step along x
        order = list(range(lead)) + [lead + 1, lead] + list(range(lead + 2, lf.ndim))
        lf = lf.transpose(order)
        present = None if present is None else np.asarray(present).T
        a = a[:, ::-1]
    elif u_along == v_along:  # both axes along one image axis: no order of views fixes that
        return lf, present
    for axis in (0, 1):
        if a[axis, axis] >= 0:
            continue
        n = lf.shape[lead + axis]
        reverse = slice(None, None, -1) if n % 2 else slice(n - 1, 0, -1)
        lf = lf[(slice(None),) * (lead + axis) + (reverse,)]
        if present is not None:
            present = np.asarray(present)[(slice(None),) * axis + (reverse,)]
    return lf, present


def axes_as_list(axes: np.ndarray | None, digits: int = 4) -> list[list[float]] | None:
    """View axes as the JSON outputs report them (``view_axes``): rounded nested lists,
    ``None`` for none."""
    return None if axes is None else [[round(float(x), digits) for x in row] for row in np.asarray(axes)]


def lf_dims(lf: ArrayT) -> tuple[int, int, int, int, int]:
    """Returns ``(U, V, H, W, C)`` of a frame or video."""
    shape = check_lf(lf)
    u, v, h, w, c = shape[-5:]
    return u, v, h, w, c


def centre_index(u: int, v: int) -> tuple[int, int]:
    """The centre view's grid index, ``(U // 2, V // 2)``."""
    return u // 2, v // 2


def centre_view(lf: ArrayT) -> ArrayT:
    """The centre view of a frame or video.

    Shape:
        - lf: ``(*, U, V, H, W, C)``
        - output: ``(*, H, W, C)``
    """
    u, v, *_ = lf_dims(lf)
    u0, v0 = centre_index(u, v)
    return lf[..., u0, v0, :, :, :]


def check_crop(views: tuple[int, int], k: int) -> None:
    """Raises :class:`LFValueError` unless ``k`` is a central crop :func:`crop_views` can
    take of a ``views`` grid (a reader checks it before the frames arrive)."""
    u, v = views
    if not isinstance(k, (int, np.integer)) or k < 1 or k > min(u, v):
        raise LFValueError(f"views: crop size must be an integer in 1..{min(u, v)}, got {k!r}")


def check_first_frame(first_frame: object, count: int | None = None, source: object = None) -> None:
    """Raises :class:`LFValueError` unless ``first_frame`` is a video frame index (an
    integer, 0 or more) a reader or decoder can start at: below ``count``, the frames of
    the video ``source`` where it is known."""
    if not isinstance(first_frame, (int, np.integer)) or isinstance(first_frame, bool) or first_frame < 0:
        raise LFValueError(f"first_frame: a frame index (0 or more), got {first_frame!r}")
    if count is not None and first_frame >= count:
        where = f"{source}: " if source is not None else ""
        raise LFValueError(f"{where}first_frame {first_frame}: it holds {count} frame(s), 0..{count - 1}")


def frames_in_range(count: int, first_frame: int, max_frames: int | None, source: object = None) -> int:
    """How many of a video's ``count`` frames the range from ``first_frame`` of at most
    ``max_frames`` holds (``first_frame`` checked against ``count``: :func:`check_first_frame`)."""
    check_first_frame(first_frame, count, source)
    left = count - first_frame
    return left if max_frames is None else min(left, max_frames)


def crop_views(lf: ArrayT, k: int) -> ArrayT:
    """Keeps the central ``k x k`` views, so the centre view stays the centre view.

    Shape:
        - lf: ``(*, U, V, H, W, C)`` with ``U, V >= k``
        - output: ``(*, k, k, H, W, C)``
    """
    u, v, *_ = lf_dims(lf)
    check_crop((u, v), k)
    su, sv = u // 2 - k // 2, v // 2 - k // 2
    return lf[..., su : su + k, sv : sv + k, :, :, :]


def downsample_angular(lf: ArrayT, factor: int = 2) -> ArrayT:
    """Angular down-sampling by averaging each ``factor x factor`` block of adjacent views.

    This is how the seed (§2.3.1) simulates a plenoptic camera with fewer, larger pixels
    under each microlens. Views that do not fill a whole block at the far edge are dropped.
    The result is float32 (numpy) or the input's float dtype (torch).

    Shape:
        - lf: ``(*, U, V, H, W, C)``
        - output: ``(*, U // factor, V // factor, H, W, C)``
    """
    u, v, h, w, c = lf_dims(lf)
    if not isinstance(factor, (int, np.integer)) or factor < 1 or factor > min(u, v):
        raise LFValueError(f"factor: must be an integer in 1..{min(u, v)}, got {factor!r}")
    nu, nv = u // factor, v // factor
    lead = tuple(lf.shape[:-5])
    x = lf[..., : nu * factor, : nv * factor, :, :, :]
    x = x.reshape(*lead, nu, factor, nv, factor, h, w, c)
    nl = len(lead)
    if is_tensor(x):
        xf = x if x.is_floating_point() else x.float()
        if not x.is_floating_point():
            xf = xf / 255.0
        return xf.mean(dim=(nl + 1, nl + 3))
    xf = x.astype(np.float32)
    if x.dtype == np.uint8:
        xf /= 255.0
    return xf.mean(axis=(nl + 1, nl + 3))


def to_sensor(lf: ArrayT) -> ArrayT:
    """SAI grid to plenoptic sensor (lenslet) image, seed Eq. 2.4.

    ``Lp[s*U + u, t*V + v] = L[u, v, s, t]``: microlens ``(s, t)`` covers a ``U x V`` block
    of sensor pixels and pixel ``(u, v)`` under it belongs to view ``(u, v)`` (0-based form
    of ``L(s,t,u,v) = Lp(u + (s-1)N, v + (t-1)N)``).

    Shape:
        - lf: ``(*, U, V, H, W, C)``
        - output: ``(*, H*U, W*V, C)``
    """
    return _tile(lf, (2, 0, 3, 1, 4))


def from_sensor(img: ArrayT, views: int | tuple[int, int]) -> ArrayT:
    """Plenoptic sensor image to SAI grid; the inverse of :func:`to_sensor`.

    Shape:
        - img: ``(*, H*U, W*V, C)``
        - output: ``(*, U, V, H, W, C)``
    """
    return _untile(img, views, lenslet=True)


def to_mosaic(lf: ArrayT) -> ArrayT:
    """SAI grid to a mosaic with the views tiled side by side, row ``u`` of views on top.

    Shape:
        - lf: ``(*, U, V, H, W, C)``
        - output: ``(*, U*H, V*W, C)``
    """
    return _tile(lf, (0, 2, 1, 3, 4))


def _tile(lf: ArrayT, order: tuple[int, ...]) -> ArrayT:
    """``lf`` (*, U, V, H, W, C) permuted by ``order`` (of its last five axes) and the pairs
    of axes then folded into the rows and columns of one image (*, U*H, V*W, C)."""
    u, v, h, w, c = lf_dims(lf)
    lead = tuple(lf.shape[:-5])
    n = len(lead)
    axes = tuple(range(n)) + tuple(n + k for k in order)
    return _permute(lf, axes).reshape(*lead, u * h, v * w, c)


def _untile(img: ArrayT, views: int | tuple[int, int], lenslet: bool) -> ArrayT:
    """The inverse of :func:`_tile`: a sensor image (``lenslet``: the views interleaved
    under each microlens) or a mosaic (views side by side) to (*, U, V, H, W, C)."""
    what, grid = ("sensor image", "angular size") if lenslet else ("mosaic", "view grid")
    u, v = (views, views) if isinstance(views, (int, np.integer)) else views
    if img.ndim < 3:
        raise LFShapeError(f"{what}: expected (..., H, W, C), got shape {tuple(img.shape)}")
    ih, iw, c = (int(s) for s in img.shape[-3:])
    if u < 1 or v < 1 or ih % u or iw % v:
        raise LFShapeError(f"{what}: size {ih}x{iw} is not a multiple of the {grid} {u}x{v}")
    lead = tuple(img.shape[:-3])
    n = len(lead)
    if lenslet:
        x = img.reshape(*lead, ih // u, u, iw // v, v, c)
        order = (1, 3, 0, 2, 4)
    else:
        x = img.reshape(*lead, u, ih // u, v, iw // v, c)
        order = (0, 2, 1, 3, 4)
    return _permute(x, tuple(range(n)) + tuple(n + k for k in order))


def from_mosaic(img: ArrayT, views: int | tuple[int, int]) -> ArrayT:
    """Mosaic to SAI grid; the inverse of :func:`to_mosaic`.

    Shape:
        - img: ``(*, U*H, V*W, C)``
        - output: ``(*, U, V, H, W, C)``
    """
    return _untile(img, views, lenslet=False)


def aperture_weights(
    views: tuple[int, int], radius: float | None = None, shape: str = "circle"
) -> np.ndarray:
    """Weights over the view grid that model a synthetic aperture.

    Args:
        views: ``(U, V)``.
        radius: aperture radius in view steps, measured from the centre view; ``None``
            means the full grid (every view weight 1). Radius 0 is a pinhole (seed Eq. 2.2).
        shape: ``"circle"`` (hard disc), ``"square"`` (box) or ``"gaussian"``
            (``exp(-r^2 / (2 radius^2))``, radius acting as sigma).

    Returns:
        float32 array ``(U, V)`` summing to a positive value.
    """
    u, v = views
    uu, vv = np.meshgrid(np.arange(u) - u // 2, np.arange(v) - v // 2, indexing="ij")
    if radius is None:
        return np.ones((u, v), np.float32)
    if not np.isfinite(radius) or radius < 0:
        raise LFValueError(f"aperture radius must be finite and >= 0, got {radius!r}")
    if shape == "circle":
        w = (uu**2 + vv**2 <= radius**2 + 1e-9).astype(np.float32)
    elif shape == "square":
        w = ((np.abs(uu) <= radius + 1e-9) & (np.abs(vv) <= radius + 1e-9)).astype(np.float32)
    elif shape == "gaussian":
        if radius == 0:
            w = ((uu == 0) & (vv == 0)).astype(np.float32)
        else:
            w = np.exp(-(uu**2 + vv**2) / (2.0 * radius**2)).astype(np.float32)
    else:
        raise LFValueError(f"aperture shape must be circle, square or gaussian, got {shape!r}")
    return w


def dof_image(lf: ArrayT, weights: np.ndarray | torch.Tensor | None = None) -> ArrayT:
    """Depth-of-field image: the weighted mean of the views through an aperture (seed Eq. 2.1).

    With ``weights=None`` every view counts equally (the full aperture); a one-hot weight at
    the centre view gives the pinhole image (Eq. 2.2). The result is float (float32 for
    uint8 input, scaled to ``[0, 1]``).

    Shape:
        - lf: ``(*, U, V, H, W, C)``
        - weights: ``(U, V)``
        - output: ``(*, H, W, C)``
    """
    u, v, *_ = lf_dims(lf)
    is_torch = is_tensor(lf)
    x = as_float(lf)
    if weights is None:
        if is_torch:
            return x.mean(dim=(-5, -4))
        return x.mean(axis=(-5, -4))
    wt = np.asarray(weights.detach().cpu() if is_tensor(weights) else weights, np.float32)
    if tuple(wt.shape) != (u, v):
        raise LFShapeError(f"weights: expected shape ({u}, {v}), got {tuple(wt.shape)}")
    total = float(wt.sum())
    if not np.isfinite(total) or total <= 0 or bool((wt < 0).any()):
        raise LFValueError("weights: must be non-negative and sum to a positive finite value")
    wt = wt / total
    if is_torch:
        import torch

        return torch.einsum("...uvhwc,uv->...hwc", x, torch.as_tensor(wt, device=x.device, dtype=x.dtype))
    return np.einsum("...uvhwc,uv->...hwc", x, wt.astype(x.dtype), optimize=True)


def as_float(x: ArrayT) -> ArrayT:
    """uint8 -> float32 in ``[0, 1]``; float inputs are returned as float32 (torch keeps its
    float dtype), other integer types are rejected (:func:`check_samples`)."""
    check_samples(x)
    if is_tensor(x):
        return x.float() / 255.0 if x.dtype == sys.modules["torch"].uint8 else x
    if x.dtype == np.uint8:
        return x.astype(np.float32) / np.float32(255.0)
    return x.astype(np.float32, copy=False)


def to_network_input(x: np.ndarray | torch.Tensor, device: str | torch.device = "cpu") -> torch.Tensor:
    """Images or light fields with channels last (lfstream's boundary layout) to the
    channels-before-(H, W) float32 tensor the networks take: uint8 is scaled to ``[0, 1]``.

    Shape:
        - x: ``(..., H, W, C)``; output: ``(..., C, H, W)``
    """
    import torch

    t = x if isinstance(x, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(x))
    t = t.to(device).movedim(-1, -3)
    return t.float().div_(255.0) if t.dtype == torch.uint8 else t.float()


def to_uint8(x: ArrayT) -> ArrayT:
    """Float in ``[0, 1]`` -> uint8 with rounding and clipping; NaN maps to 0. Other integer
    types are rejected (:func:`check_samples`)."""
    check_samples(x)
    if is_tensor(x):
        torch = sys.modules["torch"]
        if x.dtype == torch.uint8:
            return x
        return torch.nan_to_num(x.float() * 255.0 + 0.5, nan=0.0).clamp_(0, 255).to(torch.uint8)
    if x.dtype == np.uint8:
        return x
    y = np.nan_to_num(np.asarray(x, np.float32) * np.float32(255.0) + np.float32(0.5), nan=0.0)
    return np.clip(y, 0, 255).astype(np.uint8)


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a`` (no copy), for the numba kernels' input arrays.

    numba compiles an array's read-only flag into a kernel's signature, so the same kernel
    called with a writable array and with a read-only one (a memory-mapped file, a
    ``broadcast_to`` result) loads, or on a fresh install compiles, two machine-code
    versions: a stream's warm-up on writable arrays then left five kernels to load in the
    timed run. Inputs passed through this take one signature whatever their origin.
    """
    view = a.view()
    view.flags.writeable = False
    return view


def check_finite(x: ArrayT, name: str = "lf") -> None:
    """Raises :class:`LFValueError` if a float array holds NaN or Inf.

    lfstream rejects non-finite input instead of sanitising it: a NaN in a light field is
    a bug upstream, and silently replacing it would hide that bug.
    """
    if is_tensor(x):
        if x.is_floating_point() and not bool(sys.modules["torch"].isfinite(x).all()):
            raise LFValueError(f"{name}: contains NaN or Inf values")
    elif np.issubdtype(np.asarray(x).dtype, np.floating) and not np.isfinite(x).all():
        raise LFValueError(f"{name}: contains NaN or Inf values")


#: How far outside ``[0, 1]`` a float light field may reach before the codec refuses it:
#: less is resampling overshoot and is clipped; more is data in other units (8-bit values
#: stored as float would otherwise code as a white frame).
FLOAT_RANGE_SLACK = 1.0


def check_samples(x: ArrayT, name: str = "lf") -> None:
    """Raises :class:`LFValueError` naming ``name`` unless the samples are uint8 (8-bit
    levels) or float (``[0, 1]``), numpy or torch: another integer type's scale is a guess
    (8-bit levels in an int64 array were read as floats and saturated to white)."""
    if is_tensor(x):
        ok = x.is_floating_point() or x.dtype == sys.modules["torch"].uint8
        dtype = str(x.dtype).replace("torch.", "")
    else:
        a = np.asarray(x)
        ok, dtype = a.dtype == np.uint8 or np.issubdtype(a.dtype, np.floating), a.dtype.name
    if not ok:
        raise LFValueError(f"{name}: {dtype} samples; expected uint8, or float in [0, 1] (8-bit levels in "
                           "another integer type: .astype(np.uint8))")


def check_unit_range(x: np.ndarray, name: str = "lf") -> None:
    """Raises :class:`LFValueError` if a float array's values reach further outside ``[0, 1]``
    than :data:`FLOAT_RANGE_SLACK`, or the samples are neither uint8 nor float (another
    integer type's scale is a guess: 8-bit levels in an int64 array, say, read as floats
    saturated to white)."""
    a = np.asarray(x)
    check_samples(a, name)
    if a.dtype == np.uint8 or a.size == 0:
        return
    lo, hi = float(a.min()), float(a.max())
    if lo < -FLOAT_RANGE_SLACK or hi > 1.0 + FLOAT_RANGE_SLACK:
        raise LFValueError(f"{name}: float values span {lo:g} .. {hi:g}; expected uint8, or float in [0, 1] "
                           "(8-bit values stored as float: divide by 255)")


__all__ = [
    "view_offsets",
    "canonical_views",
    "axes_as_list",
    "check_samples",
    "check_unit_range",
    "FLOAT_RANGE_SLACK",
    "to_network_input",
    "MAX_VIEWS_PER_AXIS",
    "MAX_VIEW_SIDE",
    "check_lf",
    "lf_dims",
    "centre_index",
    "centre_view",
    "check_crop",
    "check_first_frame",
    "frames_in_range",
    "crop_views",
    "downsample_angular",
    "to_sensor",
    "from_sensor",
    "to_mosaic",
    "from_mosaic",
    "aperture_weights",
    "dof_image",
    "as_float",
    "to_uint8",
    "read_only",
    "check_finite",
]
