"""The encoder's JPEG-Hance strength map: how much of the network's correction each tile of
the centre view should get, measured on the decoded light field.

JPEG-Hance (:mod:`lfstream.models.jpeg_hance`) restores the decoded, post-filtered centre
view; the decoder warps the restored view into every view. Where the hint's residual
misalignment dominates, a sharper centre view warps further from the true views, so the
full correction can lose (the two-block fast network shipped until 2026-11-28 on the
held-out seahorse: -0.07 dB on the decoded LF at q50) while half of it gained (+0.19). The encoder has the original views: it
decodes its own packet, runs the network, and keeps, per tile, the strength level whose
warp has the smallest squared error over every view (measured from the warps of the plain
and the restored centre: :func:`measure_hance_map`). The map travels in the
JPEG (:func:`lfstream.codec.centre.jpeg.with_hance_map`, 16 x 16 tiles: 96 bytes a frame) and the
decoder blends the correction by it, bilinearly (:func:`lfstream.codec.centre.jpeg.hance_strength`).
Measured with the fast preset's encode at q50, on the three scenes the network was not
trained on, the decoded LF with the map against the post-filter alone: seahorse +0.260 dB,
cotton +0.295, lytro_translucent +0.114 with the shipped network (four blocks at 0.617 of
their correction, the map's top level; without the map +0.215 / +0.294 / +0.105); with the
two-block network before it +0.211 / +0.317 / +0.112 (its full correction -0.072 / +0.310 /
+0.075 dB; 8 x 8 tiles +0.198 / +0.311 / +0.102). MSSIM higher on each. Costs the
encoder the hint and gains of every frame (its reference decoder follows the stream), and a
decode, the network and two warps on the frames it measures (the first and every hint key
frame), several times the default encode. An option (``Encoder(hance_map=True)``, ``lfstream encode --hance-map``,
``lfstream stream --hance-map``), not the default. A stream with maps names the network in
its header, and a decoder's ``hance="auto"`` runs it there on any device.
"""

from __future__ import annotations

import numpy as np

from lfstream.codec.centre.jpeg import HANCE_LEVELS, MAX_HANCE_TILES
from lfstream.errors import LFValueError

#: The JPEG-Hance preset the encoder measures its maps for; a decoder running another preset
#: restores at full strength. A stream with maps names it in its header (``meta["hance_map"]``),
#: and a decoder's ``hance="auto"`` runs that preset's network on it: the encoder measured
#: where it helps.
HANCE_MAP_PRESET = "fast"
#: Tiles a side of the map the encoder measures (fewer where the view has fewer pixels): 16,
#: 96 bytes a frame; on lytro_translucent 8 x 8 tiles gained +0.102 dB, 16 x 16 +0.112.
HANCE_MAP_TILES = 16


def tile_edges(n: int, tiles: int) -> np.ndarray:
    """The ``tiles + 1`` edges splitting ``n`` pixels into ``tiles`` near-equal tiles."""
    return np.round(np.linspace(0, n, tiles + 1)).astype(np.int64)


def measure_hance_map(views: np.ndarray, centre: np.ndarray, restored: np.ndarray, disparity: np.ndarray,
                      axes: np.ndarray | None = None, gains: np.ndarray | None = None,
                      present: np.ndarray | None = None, tiles: int = HANCE_MAP_TILES,
                      occlusion: bool = True, warped: np.ndarray | None = None) -> np.ndarray:
    """Per tile of the centre view, the strength level (0..:data:`HANCE_LEVELS`) whose warp
    comes closest to the original ``views``: squared errors summed over the views present and
    the tile's pixels; ties go to the lower level.

    The decoder warps the centre blended at the level
    (:func:`lfstream.codec.centre.jpeg.blend_restored`, then :func:`lfstream.codec.warp.cpu.warp_views`),
    and the warp is linear in the image it warps (the splat's order and the holes follow the
    disparity alone), so the warp at strength ``s`` is ``P + s * (R - P)``, with ``P`` and
    ``R`` the warps of ``centre`` and ``restored``, up to the rounding of each to 8 bits. The
    error is then a quadratic in ``s`` per tile, measured from two warps in one pass
    (:func:`lfstream.codec.centre.hance_kernels.strength_error_terms`) rather than a blend, a warp and an
    error pass per level: a fraction of the work, the same decoded light fields within
    0.001 dB (the rounding moves a level only where two are within it).

    Args:
        views: the original frame, uint8.
        centre: the decoded, post-filtered centre view (the network's input), uint8.
        restored: the network's output for it, uint8.
        disparity: the decoder's centre-view disparity; axes, gains: the decoder's.
        present: ``(U, V)`` views that exist; ``None``: all.
        tiles: tiles a side (at most :data:`lfstream.codec.centre.jpeg.MAX_HANCE_TILES`).
        warped: ``centre``'s warp as above where the caller has it (the encoder's reference
            decode: the decoder's light field), one warp saved.

    Shape:
        - views: ``(U, V, H, W, 3)``; centre, restored: ``(H, W, 3)``; disparity: ``(H, W)``
        - output: ``(min(tiles, H), min(tiles, W))`` uint8
    """
    from lfstream.codec.centre.hance_kernels import strength_error_terms
    from lfstream.codec.warp.cpu import warp_views

    if not 1 <= tiles <= MAX_HANCE_TILES:
        raise LFValueError(f"tiles: 1..{MAX_HANCE_TILES}, got {tiles!r}")
    u, v, h, w, _ = views.shape
    if centre.shape != (h, w, 3) or restored.shape != centre.shape:
        raise LFValueError(f"centre and restored: ({h}, {w}, 3) like the views, got {centre.shape} and {restored.shape}")
    if warped is not None and warped.shape != views.shape:
        raise LFValueError(f"warped: {views.shape} like the views, got {warped.shape}")
    mask = np.ones((u, v), bool) if present is None else np.asarray(present, bool)
    rows, cols = tile_edges(h, min(tiles, h)), tile_edges(w, min(tiles, w))
    plain = warp_views(centre, disparity, (u, v), occlusion=occlusion, gains=gains, axes=axes) \
        if warped is None else np.ascontiguousarray(warped)
    full = warp_views(restored, disparity, (u, v), occlusion=occlusion, gains=gains, axes=axes)
    cross, square = np.empty((h, w), np.int64), np.empty((h, w), np.int64)
    strength_error_terms(plain, full, np.ascontiguousarray(views), mask, cross, square)

    def per_tile(a: np.ndarray) -> np.ndarray:
        return np.add.reduceat(np.add.reduceat(a, rows[:-1], axis=0), cols[:-1], axis=1)

    # the error at level k is the level-0 error plus (2 k n cross + k^2 square) / n^2,
    # n = HANCE_LEVELS: compared as the integers 2 k n cross + k^2 square (exact)
    k = np.arange(HANCE_LEVELS + 1, dtype=np.int64)[:, None, None]
    change = 2 * k * HANCE_LEVELS * per_tile(cross)[None] + k * k * per_tile(square)[None]
    return change.argmin(axis=0).astype(np.uint8)


__all__ = ["HANCE_MAP_PRESET", "HANCE_MAP_TILES", "tile_edges", "measure_hance_map"]
