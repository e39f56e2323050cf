"""The encoder's JPEG-Hance strength map: how much of the network's correction each tile of
the centre view should get, measured on the decoded light field.

JPEG-Hance (:mod:`lfstream.models.jpeg_hance`) restores the decoded, post-filtered centre
view; the decoder warps the restored view into every view. Where the hint's residual
misalignment dominates, a sharper centre view warps further from the true views, so the
full correction can lose (the fast network on the held-out seahorse: -0.07 dB on the
decoded LF at q50) while half of it gains (+0.19). The encoder has the original views: it
decodes its own packet, runs the network, warps the centre at each strength level and keeps,
per tile, the level with the smallest squared error over every view. The map travels in the
JPEG (:func:`lfstream.codec.jpeg.with_hance_map`, 16 x 16 tiles: 96 bytes a frame) and the
decoder blends the correction by it, bilinearly (:func:`lfstream.codec.jpeg.hance_strength`).
Measured with the shipped weights, the fast preset's encode at q50, on the three scenes the
network was not trained on, the decoded LF with the map against the post-filter alone:
seahorse +0.212 dB, cotton +0.315, lytro_translucent +0.112, MSSIM higher on each (the full
correction: -0.069 / +0.309 / +0.077 dB; 8 x 8 tiles +0.198 / +0.311 / +0.102). Costs the
encoder the hint and gains of every frame (its reference decoder follows the stream), and a
decode, the network and a warp per level on the frames it measures (the first and every hint
key frame): an option (``Encoder(hance_map=True)``, ``lfstream encode --hance-map``,
``lfstream stream --hance-map``), not the default. A stream with maps names the network in
its header, and a decoder's ``hance="auto"`` runs it there on any device.
"""

from __future__ import annotations

import numpy as np

from lfstream.codec.jpeg import HANCE_LEVELS, MAX_HANCE_TILES, blend_restored
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
    comes closest to the original ``views``: the centre blended at each level
    (:func:`lfstream.codec.jpeg.blend_restored`) and warped as the decoder warps it
    (:func:`lfstream.codec.warp.warp_views`), squared errors summed over the views present and
    the tile's pixels; ties go to the lower level.

    Args:
        views: the original frame, uint8.
        centre: the decoded, post-filtered centre view (the network's input), uint8.
        restored: the network's output for it, uint8.
        disparity: the decoder's centre-view disparity; axes, gains: the decoder's.
        present: ``(U, V)`` views that exist; ``None``: all.
        tiles: tiles a side (at most :data:`lfstream.codec.jpeg.MAX_HANCE_TILES`).
        warped: level 0's warp (``centre`` itself, warped as above) where the caller has it:
            the decoder's light field (the encoder's reference decode), one warp saved.

    Shape:
        - views: ``(U, V, H, W, 3)``; centre, restored: ``(H, W, 3)``; disparity: ``(H, W)``
        - output: ``(min(tiles, H), min(tiles, W))`` uint8
    """
    from lfstream.codec._kernels import squared_error_map
    from lfstream.codec.warp import warp_views

    if not 1 <= tiles <= MAX_HANCE_TILES:
        raise LFValueError(f"tiles: 1..{MAX_HANCE_TILES}, got {tiles!r}")
    u, v, h, w, _ = views.shape
    if centre.shape != (h, w, 3) or restored.shape != centre.shape:
        raise LFValueError(f"centre and restored: ({h}, {w}, 3) like the views, got {centre.shape} and {restored.shape}")
    mask = np.ones((u, v), bool) if present is None else np.asarray(present, bool)
    rows, cols = tile_edges(h, min(tiles, h)), tile_edges(w, min(tiles, w))
    original = np.ascontiguousarray(views)
    errors = np.empty((HANCE_LEVELS + 1, len(rows) - 1, len(cols) - 1), np.int64)
    lf = np.empty(views.shape, np.uint8)
    err = np.empty((h, w), np.int64)
    if warped is not None and warped.shape != views.shape:
        raise LFValueError(f"warped: {views.shape} like the views, got {warped.shape}")
    for level in range(HANCE_LEVELS + 1):
        if level == 0 and warped is not None:  # blend_restored at 0 is the centre exactly
            squared_error_map(np.ascontiguousarray(warped), original, mask, err)
        else:
            blended = blend_restored(centre, restored, level / HANCE_LEVELS)
            warp_views(blended, disparity, (u, v), occlusion=occlusion, gains=gains, axes=axes, out=lf)
            squared_error_map(lf, original, mask, err)  # over the views present and the channels
        errors[level] = np.add.reduceat(np.add.reduceat(err, rows[:-1], axis=0), cols[:-1], axis=1)
    return errors.argmin(axis=0).astype(np.uint8)


__all__ = ["HANCE_MAP_PRESET", "HANCE_MAP_TILES", "tile_edges", "measure_hance_map"]
