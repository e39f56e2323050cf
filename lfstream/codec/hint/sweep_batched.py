"""The encoder's plane sweep (:func:`lfstream.codec.hint.sweep._sweep`) as tensor operations on
any torch device: every candidate plane and every view in one pass, no per-plane or per-row
Python loop. The CPU reference stays the fused numba kernels
(:func:`lfstream.codec.hint.kernels.sweep_cost`, :func:`~lfstream.codec.hint.kernels.winner_subpixel`)
and OpenCV's box filter; this is the same arithmetic written for a GPU, checked against them
on the CPU (tests/codec/hint/test_sweep_batched.py).

The same steps and numbers as the kernels: each view translated by the candidate's shift
times its offset (bilinear, border replicated: a candidate moves the whole view by one
sub-pixel vector, so the taps are two rows and two columns per view and candidate), the mean
absolute difference to the centre, a ``(2r + 1)^2`` box mean with the border replicated, the
cheapest candidate per pixel (the first of equal ones) refined by a parabola through its
neighbours. The sums run in another order than the kernels' (and the kernels' compiler fuses
multiply-adds), so costs agree to float32 rounding, and a pixel whose two best candidates tie
to that rounding may take the other one (the tests bound both).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from lfstream.errors import LFShapeError, LFValueError

#: candidate planes x views x pixels per pass (float32 intermediates: about 1 GiB at the peak)
DEFAULT_CHUNK_PIXELS = 1 << 26


def _taps(n: int, pos: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The two taps of sampling positions ``pos`` along an axis of length ``n`` (the
    kernel's floor, then the border replicated) and the weight of the second.

    Shape:
        - pos: ``(D, J, n)`` float32
        - output: ``(D, J, n)`` int64 twice and float32
    """
    base = torch.floor(pos)
    first = base.to(torch.int64)
    return first.clamp(0, n - 1), (first + 1).clamp(0, n - 1), pos - base


def sweep_cost_batched(images: torch.Tensor, offsets: torch.Tensor, shifts: torch.Tensor,
                       chunk_pixels: int = DEFAULT_CHUNK_PIXELS) -> torch.Tensor:
    """Plane-sweep matching cost of a centre image against shifted views, as
    :func:`lfstream.codec.hint.kernels.sweep_cost` computes it.

    ``cost[k, y, x] = mean_j |I_j(y - s_k * du_j, x - s_k * dv_j) - I_0(y, x)|``, view ``j``
    sampled bilinearly with the border replicated.

    Args:
        images: centre first, then the J views.
        offsets: view offsets ``(u - u0, v - v0)`` along the capture's axes.
        shifts: candidate disparities in pixels of ``images`` per view step.
        chunk_pixels: candidates are taken in groups of at most this many plane x view x
            pixel samples (memory, not results).

    Shape:
        - images: ``(1 + J, h, w)`` float32
        - offsets: ``(J, 2)`` float32
        - shifts: ``(D,)`` float32
        - output: ``(D, h, w)`` float32, on ``images``' device
    """
    if images.ndim != 3 or images.shape[0] < 2:
        raise LFShapeError(f"images: (1 + J, h, w) with J >= 1, got {tuple(images.shape)}")
    n_j, h, w = images.shape[0] - 1, images.shape[1], images.shape[2]
    if tuple(offsets.shape) != (n_j, 2) or shifts.ndim != 1 or shifts.shape[0] < 1:
        raise LFShapeError(f"offsets: ({n_j}, 2) and shifts: (D,), got {tuple(offsets.shape)} and {tuple(shifts.shape)}")
    dev = images.device
    images = images.float()
    offsets = offsets.to(dev, torch.float32)
    shifts = shifts.to(dev, torch.float32)
    centre, views = images[0], images[1:]
    step = max(1, int(chunk_pixels) // max(1, n_j * h * w))
    rows = torch.arange(h, device=dev, dtype=torch.float64).view(1, 1, h)
    columns = torch.arange(w, device=dev).view(1, 1, w)
    jj = torch.arange(n_j, device=dev).view(1, n_j, 1, 1)
    out = []
    for k0 in range(0, shifts.shape[0], step):
        s = shifts[k0:k0 + step].view(-1, 1)
        d = s.shape[0]
        # the kernel's positions: the row y - s * du rounded once (its compiler fuses the
        # multiply-add; the float64 product of float32 values is exact), the column shift
        # -s * dv the same for every column, so its fraction is one number a view
        sy = (rows - (s.double() * offsets[:, 0].double()).unsqueeze(-1)).float()
        y0, y1, ay = _taps(h, sy)
        dx = (-s * offsets[:, 1]).unsqueeze(-1)
        dx_floor = torch.floor(dx)
        cols = columns + dx_floor.to(torch.int64)
        x0, x1 = cols.clamp(0, w - 1), (cols + 1).clamp(0, w - 1)
        # the two rows of every output row, each at its two columns: (d, J, h, w) gathers
        r0 = views[jj, y0.unsqueeze(-1), x0.unsqueeze(-2)]
        r0b = views[jj, y0.unsqueeze(-1), x1.unsqueeze(-2)]
        r1 = views[jj, y1.unsqueeze(-1), x0.unsqueeze(-2)]
        r1b = views[jj, y1.unsqueeze(-1), x1.unsqueeze(-2)]
        ax4 = (dx - dx_floor).view(d, n_j, 1, 1)
        ay4 = ay.unsqueeze(-1)
        top = r0 + ax4 * (r0b - r0)
        bot = r1 + ax4 * (r1b - r1)
        diff = (top + ay4 * (bot - top) - centre).abs_()
        out.append(diff.sum(dim=1) * np.float32(1.0 / n_j))
    return torch.cat(out)


def box_mean(cost: torch.Tensor, radius: int) -> torch.Tensor:
    """Each plane's ``(2r + 1)^2`` box mean with the border replicated (OpenCV's ``blur``
    with ``BORDER_REPLICATE``, as :func:`lfstream.codec.hint.sweep._sweep` aggregates).

    Shape:
        - cost: ``(D, h, w)``; output the same
    """
    if radius <= 0:
        return cost
    k = 2 * radius + 1
    padded = F.pad(cost.unsqueeze(1), (radius, radius, radius, radius), mode="replicate")
    return F.avg_pool2d(padded, k, stride=1).squeeze(1)


def winner_subpixel_batched(cost: torch.Tensor, shifts: torch.Tensor) -> torch.Tensor:
    """Per pixel the cheapest candidate (the first of equal ones), refined by a parabola
    through its neighbours, as :func:`lfstream.codec.hint.kernels.winner_subpixel`.

    Shape:
        - cost: ``(D, h, w)`` float32, D >= 3; shifts: ``(D,)`` evenly spaced
        - output: ``(h, w)`` float32
    """
    n_d = cost.shape[0]
    if n_d < 3:
        raise LFValueError(f"winner_subpixel_batched: at least 3 candidates, got {n_d}")
    shifts = shifts.to(cost.device, torch.float32)
    best = torch.argmin(cost, dim=0)
    c_best = cost.gather(0, best.unsqueeze(0)).squeeze(0)
    inner = (best > 0) & (best < n_d - 1)
    cm = cost.gather(0, (best - 1).clamp(0, n_d - 1).unsqueeze(0)).squeeze(0)
    cp = cost.gather(0, (best + 1).clamp(0, n_d - 1).unsqueeze(0)).squeeze(0)
    denom = cm - 2 * c_best + cp
    ok = inner & (denom > 1e-9)
    off = torch.where(ok, (0.5 * (cm - cp) / torch.where(ok, denom, torch.ones_like(denom))).clamp(-0.5, 0.5),
                      torch.zeros_like(denom))
    return shifts[best] + off * (shifts[1] - shifts[0])


def sweep_batched(images: np.ndarray, offsets: np.ndarray, candidates: np.ndarray, scale: int, radius: int,
                  device: str | torch.device) -> np.ndarray:
    """The whole sweep (cost, box mean, winner) on ``device``, what
    :func:`lfstream.codec.hint.sweep._sweep` does with the kernels: ``candidates`` are disparities
    in pixels of the full view per view step, ``images`` are at ``1 / scale``.

    Shape:
        - images: ``(1 + J, h, w)`` float32; offsets: ``(J, 2)``; candidates: ``(D,)``, D >= 3
        - output: ``(h, w)`` float32 NumPy array, in the candidates' unit
    """
    dev = torch.device(device)
    cands = np.ascontiguousarray(candidates, np.float32)
    with torch.no_grad():
        t_images = torch.from_numpy(np.ascontiguousarray(images, np.float32)).to(dev)
        cost = sweep_cost_batched(t_images, torch.from_numpy(np.ascontiguousarray(offsets, np.float32)),
                                  torch.from_numpy(cands / np.float32(scale)))
        return winner_subpixel_batched(box_mean(cost, int(radius)), torch.from_numpy(cands)).cpu().numpy()


__all__ = ["DEFAULT_CHUNK_PIXELS", "sweep_cost_batched", "box_mean", "winner_subpixel_batched", "sweep_batched"]
