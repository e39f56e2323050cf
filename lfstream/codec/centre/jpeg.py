"""The JPEG layer of the codec: the centre view (and, later, reference views) as baseline
JPEG through OpenCV/libjpeg, deterministic for the same input and quality."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import cv2
import numpy as np

from lfstream.errors import BitstreamError, LFValueError

#: JPEG quality range the encoder accepts (libjpeg's).
QUALITY_RANGE = (1, 100)
# what libjpeg writes after SOI: APP0 "JFIF\0" 1.1, no units, 1:1 density, no thumbnail
_JFIF_APP0 = b"\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"


def encode_jpeg(img: np.ndarray, quality: int) -> bytes:
    """Baseline JPEG of a uint8 RGB image (4:2:0, OpenCV/libjpeg), deterministic.

    Huffman tables are optimised for the image (libjpeg's second pass): the same pixels in
    3-36 % fewer bytes on the shared samples' centre views at q30-80 (most where large flat
    areas make the standard tables wasteful: seahorse q50 6830 -> 4401 bytes) for about
    0.5 ms more; still baseline JPEG, decoded as fast as before.
    """
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR),
                           [int(cv2.IMWRITE_JPEG_QUALITY), int(quality), int(cv2.IMWRITE_JPEG_OPTIMIZE), 1])
    if not ok:  # pragma: no cover - OpenCV fails only on invalid input, checked by callers
        raise LFValueError("JPEG encoding failed")
    data = buf.tobytes()
    # libjpeg's JFIF APP0 segment (version, pixel density) is optional and changes no pixel:
    # 18 bytes a frame less (0.1-0.4 % of the default streams)
    return data[:2] + data[2 + len(_JFIF_APP0):] if data[2:2 + len(_JFIF_APP0)] == _JFIF_APP0 else data


#: Start-of-frame markers (baseline, progressive, lossless, arithmetic): their segment holds
#: the image's size.
_SOF_MARKERS = frozenset({0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """``(H, W)`` from a JPEG's start-of-frame segment, read before anything is decoded;
    ``None`` where the bytes are not a JPEG whose size can be found before its scan."""
    if len(data) < 4 or data[0] != 0xFF or data[1] != 0xD8:
        return None
    pos = 2
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            return None
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # no length
            pos += 2
            continue
        length = (data[pos + 2] << 8) | data[pos + 3]
        if marker in _SOF_MARKERS:
            if length < 8 or pos + 9 > len(data):
                return None
            h = (data[pos + 5] << 8) | data[pos + 6]
            w = (data[pos + 7] << 8) | data[pos + 8]
            return h, w
        if marker in (0xDA, 0xD9) or length < 2:  # the scan, or the end, before any frame header
            return None
        pos += 2 + length
    return None


def decode_jpeg(data: bytes, size: tuple[int, int], frame: int | None = None) -> np.ndarray:
    """JPEG bytes to uint8 RGB ``(H, W, 3)``; checks the size the stream header promised
    before decoding (a few hundred bytes can declare a frame of gigabytes)."""
    declared = jpeg_size(data)
    if declared is None:
        raise BitstreamError("centre view is not a decodable JPEG (no frame header before its scan)", frame)
    if declared != tuple(size):
        raise BitstreamError(f"centre view is {declared[0]}x{declared[1]}, header says {size[0]}x{size[1]}", frame)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise BitstreamError("centre view is not a decodable JPEG", frame)
    if img.shape[:2] != tuple(size):
        raise BitstreamError(f"centre view is {img.shape[0]}x{img.shape[1]}, header says {size[0]}x{size[1]}", frame)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


#: libjpeg's standard luminance quantisation table (ITU-T T.81 Annex K), natural order;
#: the order does not matter for the ratio :func:`jpeg_quality_scale` takes.
_STANDARD_LUMA = np.array([
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99], np.float64)


@dataclass(frozen=True)
class PostFilter:
    """One setting of the decoder's JPEG post-filter: a bilateral filter ``diameter`` pixels
    wide with spatial sigma ``spatial_sigma`` and range sigma ``range_factor * scale``
    levels, ``scale`` the JPEG's own quality scale (:func:`jpeg_quality_scale`)."""

    diameter: int
    range_factor: float
    spatial_sigma: float


#: The post-filters a stream can name, by index. 0 is the default (what a JPEG without the
#: encoder's choice gets); the encoder picks another where it measures better
#: (:func:`choose_post_filter`). Measured on the shared scenes' default encodes (decoded
#: light fields, q30/50/70): 1, lighter, suits fine texture (dino q50 MSSIM 0.8989 ->
#: 0.9017); 2, wider and stronger, noisy and smooth images (synthetic q50 0.8445 -> 0.8555,
#: seahorse 0.9892 -> 0.9899) and over-smooths texture (bikes 0.9002 -> 0.8836), which is
#: why the choice is the encoder's, which has the original.
POST_FILTERS = (PostFilter(5, 0.25, 2.0), PostFilter(5, 0.15, 2.0), PostFilter(7, 0.45, 3.0))
#: The largest black floor a stream may name (a flat black block decodes at most about
#: ``Q_dc / 16`` levels above 0, ``Q_dc <= 255``).
MAX_BLACK_FLOOR = 16


@dataclass(frozen=True)
class PostFilterChoice:
    """What the encoder names for the decoder's post-filter of one JPEG.

    Attributes:
        index: the filter, into :data:`POST_FILTERS`.
        black_floor: after filtering, pixels whose three channels are all at or below it
            become 0 (0: none). JPEG reconstructs a flat black block at ``128 + round(-1024
            / Q) * Q / 8`` levels, above 0 wherever the luma DC step ``Q`` does not divide
            1024 (quality 15, 40, 70 with libjpeg's tables: seahorse's black background
            decodes at 1 or 2, its SSIM 0.89 at q40 and q70 against 0.99 at q50); the
            encoder, which sees the black, names the level it decodes at.
    """

    index: int = 0
    black_floor: int = 0

    @property
    def valid(self) -> bool:
        return 0 <= self.index < len(POST_FILTERS) and 0 <= self.black_floor <= MAX_BLACK_FLOOR

    def __str__(self) -> str:
        return (f"post-filter {self.index} with black floor {self.black_floor} (filters 0..{len(POST_FILTERS) - 1}, "
                f"floors 0..{MAX_BLACK_FLOOR})")


#: The JPEG comment segment that names a :class:`PostFilterChoice`: ``FF FE``, length 8,
#: ``LFPF``, the filter index, the black floor. Placed right after SOI; libjpeg and every
#: other decoder skip comments, so the payload stays a plain JPEG and a decoder that
#: predates the segment filters it as if it named the default.
POST_FILTER_TAG = b"LFPF"
_POST_FILTER_SEGMENT = b"\xff\xfe\x00\x08" + POST_FILTER_TAG
_NAMED = len(b"\xff\xd8" + _POST_FILTER_SEGMENT)  # offset of the index; the floor follows


def jpeg_quality_scale(data: bytes) -> float | None:
    """libjpeg's quality scale of a JPEG (100 at quality 50, ``5000 / q`` below it, ``200 -
    2 q`` above), read from its first quantisation table as the median ratio to the standard
    luminance table; ``None`` when the bytes hold no 8-bit table (then nothing is filtered).
    Read from the image itself, not the stream header, so frames whose quality a stream's
    rate control moved are filtered at their own strength."""
    i = data.find(b"\xff\xdb")
    if i < 0 or i + 5 + 64 > len(data) or data[i + 4] >> 4 != 0:  # 16-bit tables: not libjpeg's baseline
        return None
    table = np.frombuffer(data, np.uint8, 64, i + 5).astype(np.float64)
    unclipped = table < 255  # baseline tables saturate at 255 (below quality ~15)
    ratios = (table / _STANDARD_LUMA)[unclipped] if unclipped.any() else table / _STANDARD_LUMA
    return float(np.median(ratios) * 100.0)


#: The widest bilateral filter OpenCV runs through IPP here: wider ones run OpenCV's own code,
#: which gives the same bytes faster. Measured on a 375 x 540 view (OpenCV 5.0, IPP 2026.0
#: AVX-512, two threads): 7 x 7 3.12 ms with IPP against 1.88 without, the same output; 5 x 5
#: 0.58 against 0.81 (IPP faster), so those keep it.
IPP_BILATERAL_MAX_DIAMETER = 5


@contextmanager
def _without_ipp():
    """OpenCV without IPP on this thread meanwhile: ``cv::ipp::setUseIPP`` keeps its switch in
    thread-local data, so other threads' OpenCV calls are not touched."""
    was = cv2.ipp.useIPP()
    cv2.ipp.setUseIPP(False)
    try:
        yield
    finally:
        cv2.ipp.setUseIPP(was)


def deblock_jpeg(img: np.ndarray, scale: float, post_filter: PostFilter = POST_FILTERS[0]) -> np.ndarray:
    """The decoder's post-filter for a JPEG-decoded view: an edge-preserving bilateral filter
    whose range sigma follows the quantisation, ``post_filter.range_factor * scale`` levels
    (:func:`jpeg_quality_scale`): it smooths block edges and ringing, whose amplitude grows
    with the quantiser step, and leaves edges stronger than that.

    The default (5 x 5, spatial sigma 2, range factor 0.25), measured on the centre views of
    the seven shared scenes (synthetic, seahorse, dino, cotton, lytro_bikes,
    lytro_translucent, toys_array): PSNR and SSIM rise at every quality from 10 to 95 on
    every one (q50: +0.33 to +0.91 dB, mean +0.54; SSIM +0.002 to +0.02; q95: +0.02 to +0.2
    dB), and it beats the JPEG-Hance fast network trained on synthetic renders on each scene
    it was measured against (q10 / 30 / 50: +0.50..+0.83 / +0.45..+1.11 / +0.38..+0.91 dB
    against -0.08..+0.43 / -0.34..+0.25).
    Its strength was chosen among 0.15, 0.2 and 0.25 on those views.

    Shape:
        - img: ``(H, W, 3)`` uint8; output the same
    """
    if scale <= 0:
        return img
    args = (np.ascontiguousarray(img), post_filter.diameter, post_filter.range_factor * float(scale),
            post_filter.spatial_sigma)
    if post_filter.diameter <= IPP_BILATERAL_MAX_DIAMETER:
        return cv2.bilateralFilter(*args)
    with _without_ipp():
        return _bilateral_in_pieces(*args)


#: OpenCV's own bilateral filter splits an image into ``pixels / 2**16`` stripes of rows
#: (rounded) for its threads: a 375 x 540 view is 3 stripes, which two threads finish in the
#: time of two, not one and a half.
_CV_STRIPE_PIXELS = 1 << 16


def _bilateral_in_pieces(img: np.ndarray, diameter: int, sigma_color: float, sigma_space: float) -> np.ndarray:
    """``cv2.bilateralFilter`` of ``img`` (OpenCV's own code), called once per piece of rows
    of about ``threads * 2**16`` pixels, so each call is as many stripes as OpenCV has
    threads; each piece with ``diameter // 2`` context rows of its neighbours (a piece at the
    image's edge keeps that edge's border): the same bytes as one call, with no thread idle
    on a last odd stripe.

    Shape:
        - img: ``(H, W, 3)`` uint8, C-contiguous; output the same
    """
    h, w = img.shape[:2]
    pieces = min(h, int(round(h * w / (max(1, cv2.getNumThreads()) * _CV_STRIPE_PIXELS))))
    if pieces <= 1:
        return cv2.bilateralFilter(img, diameter, sigma_color, sigma_space)
    pad = diameter // 2
    out = np.empty_like(img)
    cuts = [round(k * h / pieces) for k in range(pieces + 1)]
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        a, b = max(0, lo - pad), min(h, hi + pad)
        out[lo:hi] = cv2.bilateralFilter(img[a:b], diameter, sigma_color, sigma_space)[lo - a:hi - a]
    return out


def _names_post_filter(data: bytes) -> bool:
    """Whether the JPEG ``data`` begins with a whole post-filter segment."""
    return data.startswith(b"\xff\xd8" + _POST_FILTER_SEGMENT) and len(data) >= _NAMED + 2


def named_post_filter(data: bytes, frame: int | None = None) -> PostFilterChoice:
    """The post-filter a JPEG payload names (:data:`POST_FILTER_TAG` right after SOI); the
    default where it names none."""
    if not _names_post_filter(data):
        return PostFilterChoice()
    choice = PostFilterChoice(data[_NAMED], data[_NAMED + 1])
    if not choice.valid:
        raise BitstreamError(f"centre view names {choice}, beyond what this decoder knows", frame)
    return choice


def with_post_filter(data: bytes, choice: PostFilterChoice) -> bytes:
    """The JPEG ``data`` naming ``choice`` (the default: the bytes without the segment,
    which is what a JPEG without it gets anyway)."""
    if not choice.valid:
        raise LFValueError(f"post-filter choice: {choice} out of range")
    body = data[_NAMED + 2:] if _names_post_filter(data) else data[2:]
    segment = _POST_FILTER_SEGMENT + bytes([choice.index, choice.black_floor]) if choice != PostFilterChoice() else b""
    return data[:2] + segment + body


#: The JPEG comment segment that carries a JPEG-Hance strength map (:func:`with_hance_map`):
#: ``FF FE``, its length, ``LFHS``, rows, columns, then the tiles' levels (row-major, the
#: strength ``level / HANCE_LEVELS``) three to a byte in base 5 (a 16 x 16 map in 86 bytes).
#: After SOI and the post-filter segment, if any; decoders skip comments, and one that
#: predates the map restores at full strength.
HANCE_MAP_TAG = b"LFHS"
#: Strength levels of a map: 0 (the post-filtered JPEG kept) to this (the network's output).
HANCE_LEVELS = 4
#: The largest map side a stream may carry, in tiles.
MAX_HANCE_TILES = 64


def _segment_start(data: bytes) -> int:
    """Where lfstream's segments after the post-filter's begin (right after SOI without one)."""
    return _NAMED + 2 if _names_post_filter(data) else 2


def hance_map(data: bytes, frame: int | None = None) -> np.ndarray | None:
    """The JPEG-Hance strength levels ``(rows, cols)`` uint8 (0..:data:`HANCE_LEVELS`) a JPEG
    payload carries (:data:`HANCE_MAP_TAG`), ``None`` where it carries none.

    Raises:
        BitstreamError: a damaged or out-of-range map (names ``frame``).
    """
    at = _segment_start(data)
    if data[at:at + 2] != b"\xff\xfe" or data[at + 4:at + 8] != HANCE_MAP_TAG:
        return None
    if at + 10 > len(data):
        raise BitstreamError("centre view's JPEG-Hance map: truncated", frame)
    length = int.from_bytes(data[at + 2:at + 4], "big")
    rows, cols = data[at + 8], data[at + 9]
    if not (1 <= rows <= MAX_HANCE_TILES and 1 <= cols <= MAX_HANCE_TILES) \
            or length != 8 + _packed_size(rows * cols) or at + 2 + length > len(data):
        raise BitstreamError(f"centre view's JPEG-Hance map: {rows}x{cols} tiles in a {length}-byte segment", frame)
    packed = np.frombuffer(data, np.uint8, _packed_size(rows * cols), at + 10)
    if packed.max() >= _BASE ** 3:
        raise BitstreamError(f"centre view's JPEG-Hance map: a byte {int(packed.max())} beyond three levels", frame)
    levels = np.stack([packed % _BASE, packed // _BASE % _BASE, packed // _BASE ** 2], axis=1).reshape(-1)
    return levels[: rows * cols].reshape(rows, cols).astype(np.uint8)


_BASE = HANCE_LEVELS + 1  # levels are packed three to a byte in this base


def _packed_size(tiles: int) -> int:
    return (tiles + 2) // 3


def with_hance_map(data: bytes, levels: np.ndarray | None) -> bytes:
    """The JPEG ``data`` carrying the strength ``levels`` ``(rows, cols)`` (``None``: none),
    replacing any map it carried; its post-filter segment stays first."""
    at = _segment_start(data)
    body = data[at:]
    old = hance_map(data)
    if old is not None:
        body = body[10 + _packed_size(old.size):]
    if levels is None:
        return data[:at] + body
    levels = np.asarray(levels)
    if levels.ndim != 2 or not (1 <= min(levels.shape) and max(levels.shape) <= MAX_HANCE_TILES) \
            or levels.min() < 0 or levels.max() > HANCE_LEVELS:
        raise LFValueError(f"JPEG-Hance map: (rows, cols) levels 0..{HANCE_LEVELS}, at most {MAX_HANCE_TILES} a side, "
                           f"got {levels.shape}")
    rows, cols = levels.shape
    flat = np.zeros(3 * _packed_size(rows * cols), np.int64)
    flat[: rows * cols] = levels.reshape(-1)
    triples = flat.reshape(-1, 3)
    packed = (triples[:, 0] + _BASE * triples[:, 1] + _BASE ** 2 * triples[:, 2]).astype(np.uint8)
    segment = b"\xff\xfe" + (8 + packed.size).to_bytes(2, "big") + HANCE_MAP_TAG + bytes([rows, cols]) \
        + packed.tobytes()
    return data[:at] + segment + body


def hance_strength(levels: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A strength map's levels as strengths in [0, 1] over a ``size`` ``(H, W)`` view: the
    tiles' values bilinearly up-sampled from their centres (so tiles leave no seams), in
    float32 numpy, the same on every machine.

    Shape:
        - levels: ``(rows, cols)``; output: ``(H, W)`` float32
    """
    from lfstream.codec.gains import resize_taps

    h, w = size
    tiles = np.asarray(levels, np.float32) / np.float32(HANCE_LEVELS)
    rows, row_w = resize_taps(h, tiles.shape[0])
    cols, col_w = resize_taps(w, tiles.shape[1])
    across = tiles[:, cols[:, 0]] * col_w[:, 0] + tiles[:, cols[:, 1]] * col_w[:, 1]
    return (across[rows[:, 0]] * row_w[:, 0, None] + across[rows[:, 1]] * row_w[:, 1, None]).astype(np.float32)


def blend_restored(filtered: np.ndarray, restored: np.ndarray, strength: np.ndarray | float) -> np.ndarray:
    """``filtered + strength * (restored - filtered)``, rounded to uint8: the network's
    correction at a strength (a map ``(H, W)`` or one value); 1 gives ``restored`` and 0
    ``filtered`` exactly.

    Shape:
        - filtered, restored: ``(H, W, 3)`` uint8; output the same
    """
    s = np.asarray(strength, np.float32)
    s = s[..., None] if s.ndim == 2 else s
    a = filtered.astype(np.float32)
    return np.clip(np.rint(a + s * (restored.astype(np.float32) - a)), 0, 255).astype(np.uint8)


def _snap_black(img: np.ndarray, floor: int) -> np.ndarray:
    """``img`` with the pixels whose channels are all at or below ``floor`` set to 0."""
    if floor:
        img = img.copy()
        img[(img <= floor).all(axis=-1)] = 0
    return img


def post_filter_jpeg(img: np.ndarray, data: bytes, frame: int | None = None) -> np.ndarray:
    """A decoded JPEG ``img`` post-filtered as the decoder shows it: at its own quality
    scale, with the filter and black floor its payload ``data`` names
    (:class:`PostFilterChoice`; the default filter where it names none). A JPEG without
    8-bit tables is returned as it is.

    Shape:
        - img: ``(H, W, 3)`` uint8; output the same
    """
    scale = jpeg_quality_scale(data)
    if scale is None:
        return img
    choice = named_post_filter(data, frame)
    return _snap_black(deblock_jpeg(img, scale, POST_FILTERS[choice.index]), choice.black_floor)


#: Rows the encoder's choice measures: this many bands spread over the view, each this many
#: rows of SSIM windows.
CHOICE_BANDS, CHOICE_BAND_ROWS = 6, 16
#: A filter other than the default is chosen only for at least this much SSIM on the sample,
#: and never for more than this loss of PSNR.
CHOICE_MIN_SSIM_GAIN, CHOICE_MAX_PSNR_LOSS = 5e-4, 0.15


def choose_post_filter(original: np.ndarray, data: bytes, bands: int = CHOICE_BANDS,
                       band_rows: int = CHOICE_BAND_ROWS) -> PostFilterChoice:
    """The post-filter that brings the JPEG ``data`` of ``original`` closest to it: the
    highest SSIM on a sample of the view (``bands`` row bands of ``band_rows`` rows of SSIM
    windows, each filtered with its own context rows, so a band is exactly what the whole
    view filtered shows there), without losing more than :data:`CHOICE_MAX_PSNR_LOSS` dB of
    PSNR against the default filter; then, where the sample has black (0, 0, 0) pixels the
    JPEG decodes above 0, the black floor they decode at, kept by the same rule. The
    default where nothing measured is better by :data:`CHOICE_MIN_SSIM_GAIN` or the view
    is too small to measure.

    Shape:
        - original: ``(H, W, 3)`` uint8
    """
    from lfstream.metrics import SSIM_WINDOW, ssim

    h, w = original.shape[:2]
    scale = jpeg_quality_scale(data)
    if scale is None or w < SSIM_WINDOW or h < SSIM_WINDOW:
        return PostFilterChoice()
    decoded = decode_jpeg(data, (h, w))
    rows = min(band_rows + SSIM_WINDOW - 1, h)  # a band's rows and its windows' margins
    n = max(1, min(bands, h // rows))
    starts = sorted({min(max(int(round((k + 0.5) * h / n - rows / 2)), 0), h - rows) for k in range(n)})
    pad = max(f.diameter for f in POST_FILTERS) // 2
    # each band covers half the columns, left and right halves alternating (twice the rows
    # sampled for the cost), where the view is wide enough for two halves of SSIM windows
    half = w // 2 if w // 2 >= max(SSIM_WINDOW, 4 * pad) else w
    cols = [(0, half) if k % 2 == 0 else (w - half, w) for k in range(len(starts))]
    spans = [(max(0, a - pad), min(w, b + pad)) for a, b in cols]
    width = max(hi - lo for lo, hi in spans)
    spans = [(lo, lo + width) if lo == 0 else (hi - width, hi) for lo, hi in spans]  # equal widths to stack
    chunks = [(max(0, s - pad), min(h, s + rows + pad)) for s in starts]
    # one filter call per candidate: the bands with their context rows and columns, stacked;
    # a band's pixels see only their own chunk, and a chunk at the view's edge keeps that
    # edge's border, so a band is exactly what the whole view filtered shows there
    stacked = np.ascontiguousarray(np.concatenate([decoded[lo:hi, x0:x1] for (lo, hi), (x0, x1) in zip(chunks, spans)]))
    offsets = np.cumsum([0] + [hi - lo for lo, hi in chunks])[:-1]
    reference = np.stack([original[s:s + rows, a:b] for s, (a, b) in zip(starts, cols)])
    reference_f = reference.astype(np.float32)

    def score(sample: np.ndarray) -> tuple[float, float]:
        mse = float(np.mean(np.square(reference_f - sample)))
        return float(np.mean(ssim(reference, sample))), -10.0 * np.log10(max(mse, 1e-10) / 255.0**2)

    samples = []
    for pf in POST_FILTERS:
        out = deblock_jpeg(stacked, scale, pf)
        samples.append(np.stack([out[o + s - lo:o + s - lo + rows, a - x0:b - x0]
                                 for o, s, (lo, _), (a, b), (x0, _) in zip(offsets, starts, chunks, cols, spans)]))
    scores = [score(x) for x in samples]
    choices = [PostFilterChoice(i) for i in range(len(POST_FILTERS))]
    black = (reference[..., 0] | reference[..., 1] | reference[..., 2]) == 0  # (x == 0).all(-1) took 0.7 ms
    if black.mean() >= 0.01:  # where black decodes above 0: the level most of it decodes at
        decoded_bands = np.stack([decoded[s:s + rows, a:b] for s, (a, b) in zip(starts, cols)])
        levels = np.bincount(decoded_bands[black].max(axis=-1), minlength=1)
        floor = int(np.argmax(levels))
        if 0 < floor <= MAX_BLACK_FLOOR:
            best = max(range(len(scores)), key=lambda i: scores[i][0])
            scores.append(score(_snap_black(samples[best], floor)))
            choices.append(PostFilterChoice(best, floor))
    best = max(range(len(scores)),
               key=lambda i: scores[i][0] if scores[i][1] >= scores[0][1] - CHOICE_MAX_PSNR_LOSS else -np.inf)
    return choices[best] if scores[best][0] >= scores[0][0] + CHOICE_MIN_SSIM_GAIN else PostFilterChoice()


@dataclass
class PostFilterChooser:
    """The encoder's post-filter choice in a video: measured (:func:`choose_post_filter`)
    on the first frame and then every ``interval`` frames (the hint's key frames), named by
    every frame until the next measurement, so frames between cost no more than before."""

    interval: int = 30
    choice: PostFilterChoice = PostFilterChoice()
    _age: int | None = None

    def mark(self, original: np.ndarray, data: bytes) -> bytes:
        """The JPEG ``data`` of this frame's ``original`` view naming the current choice."""
        if self._age is None or self._age >= self.interval:
            self.choice, self._age = choose_post_filter(original, data), 0
        self._age += 1
        return with_post_filter(data, self.choice)


def jpeg_roundtrip(img: np.ndarray, quality: int, deblock: bool = False) -> np.ndarray:
    """A uint8 RGB image through JPEG at ``quality`` and back: unfiltered by default (what
    the paper JPEG-Hance takes), or with ``deblock`` as lfstream's decoder shows it: through
    the post-filter the encoder chooses for it (:func:`choose_post_filter`, named in the
    payload, applied by :func:`post_filter_jpeg`), which is what a network trained after the
    filter takes at decode time."""
    data = encode_jpeg(img, quality)
    out = decode_jpeg(data, img.shape[:2])
    if not deblock:
        return out
    return post_filter_jpeg(out, with_post_filter(data, choose_post_filter(img, data)))


__all__ = ["QUALITY_RANGE", "PostFilter", "POST_FILTERS", "MAX_BLACK_FLOOR", "PostFilterChoice", "POST_FILTER_TAG",
           "encode_jpeg", "decode_jpeg", "jpeg_quality_scale", "deblock_jpeg", "named_post_filter", "with_post_filter",
           "post_filter_jpeg",
           "choose_post_filter", "PostFilterChooser", "jpeg_roundtrip", "HANCE_MAP_TAG", "HANCE_LEVELS",
           "MAX_HANCE_TILES", "hance_map", "with_hance_map", "hance_strength", "blend_restored"]
