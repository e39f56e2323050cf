"""The encoder's depth hint: estimation, compact coding, decoding, and accuracy metrics.

The package is the hint's data flow: :mod:`~lfstream.codec.hint.options` (options and
the payload's framing), :mod:`~lfstream.codec.hint.grids` (what the estimation works on),
:mod:`~lfstream.codec.hint.axes` (the rig's view axes), :mod:`~lfstream.codec.hint.sweep`
(the plane sweep), :mod:`~lfstream.codec.hint.payload` (quantisation, coding, parsing,
up-sampling) and :mod:`~lfstream.codec.hint.tracker` (the encoder's key and delta hints).

Estimation (the encoder has every view, at encode time): a plane sweep at half resolution
(``1 / work_scale``), averaged down to the grid the hint is sent on (``1 / hint_scale``),
over a sparse set of views — the corners and
edge mid-points of the grid, the largest baselines — fused into one parallel numba kernel
(:func:`lfstream.codec.hint.kernels.sweep_cost`) on high-passed luma (vignetting and colour
shading differ between views and would bias the cost); cost aggregation by a box filter
(O(1) per pixel); the cheapest candidate per pixel with a parabolic sub-step. The search
range is the scene's own: a coarse pass at ``1 / coarse_scale`` over ``+-search_limit``
px per view step finds it, or the previous frame's range does in a video
(:class:`HintTracker`).

View axes: a capture whose view grid is not aligned with the image axes (a camera array
with flipped rows, unequal row and column baselines, a rotated rig; see
:func:`lfstream.lightfield.view_offsets`) is detected on a stream's first frame by dense
optical flow from the centre view to the edge mid-point views and a rank-1 fit of the flows
(:func:`estimate_view_axes`); the sweep and the decoder's warp then move points along those
axes. Light fields that follow the convention keep ``A = I`` (the fit must explain the flows
far better than the convention, and change a warped pixel by a quarter of a pixel or more).

Payload (format 6, little-endian)::

    format u8 = 6 | kind u8 (0 full, 1 delta, 2 repeat; + 0x80: view axes follow) | scale u8
    coder u8 (1: context coded, full maps; 0: zstd, deltas) | lo f32 | hi f32 | hs u16 | ws u16
    ref u32 | [A: 4 f32, row-major, with the 0x80 flag] | body

The view axes are sent only when ``A`` is not the identity. ``full``: the ``hs x ws`` map
quantised to 8 bits over ``[lo, hi]``; the body is the map's level step ``k`` (u8: the
values are multiples of ``k`` and 255) and its levels, range coded with context-adaptive
probabilities (:mod:`lfstream.codec._entropy`: median-edge prediction, five activity
contexts; 12-37 % fewer bytes than zstd of the planar prediction residual on the shared
samples' hints, e.g. lytro_bikes 3195 -> 2072 B, and faster). ``delta``: zstd of the
difference (mod 256) to the quantised map of frame ``ref``, on the same grid and range;
``repeat``: frame ``ref``'s map unchanged (no body). Formats 1 to 5 (development builds)
are refused with a line that says so.

Decoding: the quantised map, upsampled to full resolution by joint bilateral upsampling
guided by the decoded centre view (edges of the depth follow edges of the picture).
"""

from lfstream.codec.hint.axes import (
    _AXES_MAX_GAIN as _AXES_MAX_GAIN,
)
from lfstream.codec.hint.axes import (
    _AXES_MIN_SHIFT as _AXES_MIN_SHIFT,
)
from lfstream.codec.hint.axes import (
    _AXES_SAMPLES as _AXES_SAMPLES,
)
from lfstream.codec.hint.axes import (
    _AXES_SCALE as _AXES_SCALE,
)
from lfstream.codec.hint.axes import (
    _AXES_SHADING_BOX as _AXES_SHADING_BOX,
)
from lfstream.codec.hint.axes import (
    _axes_views as _axes_views,
)
from lfstream.codec.hint.axes import (
    _detect_axes as _detect_axes,
)
from lfstream.codec.hint.axes import (
    _fit_axes as _fit_axes,
)
from lfstream.codec.hint.axes import (
    _flows as _flows,
)
from lfstream.codec.hint.axes import (
    estimate_view_axes,
)
from lfstream.codec.hint.axes import (
    warm_axes_fit as warm_axes_fit,
)
from lfstream.codec.hint.grids import (
    KEPT_ARRAY_MAX_BYTES as KEPT_ARRAY_MAX_BYTES,
)
from lfstream.codec.hint.grids import (
    HintMap,
    sweep_views,
)
from lfstream.codec.hint.grids import (
    _coarser as _coarser,
)
from lfstream.codec.hint.grids import (
    _grids as _grids,
)
from lfstream.codec.hint.grids import (
    _high_pass as _high_pass,
)
from lfstream.codec.hint.grids import (
    _kept as _kept,
)
from lfstream.codec.hint.grids import (
    _kept_array as _kept_array,
)
from lfstream.codec.hint.grids import (
    _ring_views as _ring_views,
)
from lfstream.codec.hint.grids import (
    _upsample as _upsample,
)
from lfstream.codec.hint.options import (
    _AXES as _AXES,
)
from lfstream.codec.hint.options import (
    _HEADER as _HEADER,
)
from lfstream.codec.hint.options import (
    _ZSTD_LEVEL as _ZSTD_LEVEL,
)
from lfstream.codec.hint.options import (
    CODER_CONTEXT as CODER_CONTEXT,
)
from lfstream.codec.hint.options import (
    CODER_ZSTD as CODER_ZSTD,
)
from lfstream.codec.hint.options import (
    GEOMETRY_MODES,
    HintOptions,
    HintReferenceError,
    is_standard,
)
from lfstream.codec.hint.options import (
    HINT_FORMAT as HINT_FORMAT,
)
from lfstream.codec.hint.options import (
    KIND_AXES as KIND_AXES,
)
from lfstream.codec.hint.options import (
    KIND_DELTA as KIND_DELTA,
)
from lfstream.codec.hint.options import (
    KIND_FULL as KIND_FULL,
)
from lfstream.codec.hint.options import (
    KIND_REPEAT as KIND_REPEAT,
)
from lfstream.codec.hint.options import (
    MAX_AXIS_ENTRY as MAX_AXIS_ENTRY,
)
from lfstream.codec.hint.payload import (
    _RANGE_LUT as _RANGE_LUT,
)
from lfstream.codec.hint.payload import (
    _RANGE_SIGMA as _RANGE_SIGMA,
)
from lfstream.codec.hint.payload import (
    HintDecoder,
    QuantisedHint,
    decode_hint,
    encode_hint,
    key_payload,
    level_step,
    quantise,
)
from lfstream.codec.hint.payload import (
    _coded_body as _coded_body,
)
from lfstream.codec.hint.payload import (
    _decoded_body as _decoded_body,
)
from lfstream.codec.hint.payload import (
    _expand as _expand,
)
from lfstream.codec.hint.payload import (
    _level_count as _level_count,
)
from lfstream.codec.hint.payload import (
    _level_step_of as _level_step_of,
)
from lfstream.codec.hint.payload import (
    _pack as _pack,
)
from lfstream.codec.hint.payload import (
    _parse as _parse,
)
from lfstream.codec.hint.sweep import (
    _sent_grid as _sent_grid,
)
from lfstream.codec.hint.sweep import (
    _sweep as _sweep,
)
from lfstream.codec.hint.sweep import (
    _sweeps as _sweeps,
)
from lfstream.codec.hint.sweep import (
    disparity_errors,
    estimate_disparity,
    estimate_hint_map,
    scene_range,
    sweeps_on_device,
)
from lfstream.codec.hint.tracker import (
    HintTracker,
)

__all__ = ["HintReferenceError", "HintOptions", "HintMap", "HintTracker", "HintDecoder", "QuantisedHint",
           "sweep_views", "estimate_hint_map", "estimate_disparity", "estimate_view_axes", "is_standard",
           "GEOMETRY_MODES", "encode_hint", "decode_hint", "disparity_errors", "scene_range", "quantise",
           "level_step", "sweeps_on_device", "key_payload"]
