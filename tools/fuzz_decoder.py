"""Coverage-guided fuzzing of the ``.lfs`` parser and decoder with atheris (libFuzzer).

Random mutation rarely gets past the CRCs to the payload decoders, so each input is first
repaired: the header's and every packet's CRC are recomputed over the mutated bytes (the
lengths stay as mutated, so the parser's bounds are still what is fuzzed). The first byte
chooses the target: a whole stream through :func:`lfstream.decode`, or one payload decoder
alone (the depth hint, the gain maps, the residual layer, the context-coded levels, the
metadata JSON) with the rest of the input as its payload.

Any exception other than :class:`lfstream.LFStreamError` is a finding, as are a hang, an
input that raises the process's peak memory by more than :data:`MAX_INPUT_GROWTH_MB` (a
single huge allocation; the slow growth of a long run's caches is not one) and memory past
libFuzzer's ``-rss_limit_mb``; libFuzzer writes the input that caused it (``crash-...``).
Keep each finding as a regression case in ``tests/fuzz_corpus/regressions/``.

    python tools/fuzz_decoder.py --seeds tests/fuzz_corpus           # write the seed corpus
    python tools/fuzz_decoder.py CORPUS_DIR -max_total_time=3600 -rss_limit_mb=4096 -timeout=20
    python tools/fuzz_decoder.py --replay tests/fuzz_corpus           # every file once, no fuzzing

Needs ``pip install atheris`` (not a dependency of lfstream).
"""

from __future__ import annotations

import struct
import sys
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: The most one input may raise the process's peak memory, in MB.
MAX_INPUT_GROWTH_MB = 1024
#: Targets the first input byte chooses from (modulo their count).
TARGETS = ("stream", "hint", "gains", "residual", "levels", "meta")


def repair_crcs(data: bytes) -> bytes:
    """``data`` with the header's and each packet's CRC-32 recomputed where the layout
    allows finding them; bytes past what can be parsed are left as they are."""
    from lfstream.codec.bitstream import _HEADER_FIXED as _HEADER  # the container's own layouts
    from lfstream.codec.bitstream import _PACKET_FIXED as _PACKET

    out = bytearray(data)
    if len(out) < _HEADER.size:
        return bytes(out)
    meta_len = _HEADER.unpack_from(out)[-1]
    end = _HEADER.size + meta_len
    if end + 4 > len(out):
        return bytes(out)
    struct.pack_into("<I", out, end, zlib.crc32(out[:end]))
    pos = end + 4
    layout = _PACKET
    while pos + layout.size <= len(out):
        lengths = layout.unpack_from(out, pos)[3:]
        stop = pos + layout.size + sum(lengths)
        if stop + 4 > len(out) or sum(lengths) > len(out):
            break
        struct.pack_into("<I", out, stop, zlib.crc32(out[pos:stop]))
        pos = stop + 4
    return bytes(out)


def one_input(data: bytes) -> None:
    """Runs one input; returns quietly or raises a finding (an unexpected exception, or a
    jump in peak memory of more than :data:`MAX_INPUT_GROWTH_MB`)."""
    import resource

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    _run_input(data)
    grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    if grown > MAX_INPUT_GROWTH_MB:
        raise MemoryError(f"one input raised the peak memory by {grown:.0f} MB")


def _run_input(data: bytes) -> None:
    import numpy as np

    from lfstream.errors import LFStreamError

    if not data:
        return
    target = TARGETS[data[0] % len(TARGETS)]
    body = data[1:]
    try:
        if target == "stream":
            import lfstream

            out = lfstream.decode(repair_crcs(body))
            assert out.ndim == 6 and out.dtype == np.uint8 and out.size > 0
        elif target == "hint":
            from lfstream.codec.hint import decode_hint

            h, w = 8 + (body[:1] or b"\0")[0] % 57, 8 + (body[1:2] or b"\0")[0] % 57
            out = decode_hint(body[2:], (h, w))
            assert out.shape == (h, w) and np.isfinite(out).all()
        elif target == "gains":
            from lfstream.codec.gains import decode_gains

            u, v = 1 + (body[:1] or b"\0")[0] % 9, 1 + (body[1:2] or b"\0")[0] % 9
            out = decode_gains(body[2:], (u, v))
            assert np.isfinite(out).all()
        elif target == "residual":
            from lfstream.codec.residual import decode_residual

            u, v = 1 + (body[:1] or b"\0")[0] % 5, 1 + (body[1:2] or b"\0")[0] % 5
            if u * v > 1:
                decode_residual(body[2:], (u, v), (16, 16))
        elif target == "levels":
            from lfstream.codec._entropy import OK, decode_coded_levels

            h, w = 1 + (body[:1] or b"\0")[0] % 64, 1 + (body[1:2] or b"\0")[0] % 64
            levels, status = decode_coded_levels(body[2:], (h, w), 256)
            # a status other than OK says the map is not to be used (its callers refuse it)
            assert status != OK or (levels.shape == (h, w) and 0 <= levels.min() and levels.max() < 256)
        else:
            from lfstream.codec.bitstream import _decompress_json

            _decompress_json(body, 1 << 20, "fuzz")
    except LFStreamError:
        pass


def seed_streams() -> dict[str, bytes]:
    """Small valid streams of every layout the encoder writes, and payloads of each target."""
    import numpy as np

    import lfstream
    from lfstream.codec.bitstream import split_stream
    from lfstream.synth import synth_clip

    clip = synth_clip(2, 3, (32, 40), seed=3, noise=2.0, vignetting=0.3).lf
    streams = {
        "jpeg_hint": lfstream.encode(clip, quality=40),
        "flat": lfstream.encode(clip, quality=40, depth_hint=False),
        "av1": lfstream.encode(clip[:1], quality=40, preset="balanced"),
        "residual": lfstream.encode(clip[:1], quality=40, residual=30),
    }
    out = {f"stream_{k}": bytes([TARGETS.index("stream")]) + v for k, v in streams.items()}
    header, packets = split_stream(streams["residual"])
    p = packets[0]
    out["hint"] = bytes([TARGETS.index("hint"), 32 - 8, 40 - 8]) + p.hint
    out["gains"] = bytes([TARGETS.index("gains"), 2, 2]) + p.gain
    out["residual"] = bytes([TARGETS.index("residual"), 2, 2]) + p.residual
    out["meta"] = bytes([TARGETS.index("meta")]) + b"\x28\xb5\x2f\xfd" + np.zeros(8, np.uint8).tobytes()
    return out


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv if argv is None else [sys.argv[0], *argv])
    if "--seeds" in argv:
        folder = Path(argv[argv.index("--seeds") + 1])
        folder.mkdir(parents=True, exist_ok=True)
        for name, data in seed_streams().items():
            (folder / name).write_bytes(data)
            print(folder / name, len(data))
        return 0
    if "--replay" in argv:
        files = sorted(p for f in argv[argv.index("--replay") + 1:] for p in Path(f).rglob("*") if p.is_file())
        for path in files:
            one_input(path.read_bytes())
        print(f"{len(files)} inputs replayed, no finding")
        return 0
    import atheris

    with atheris.instrument_imports():
        import lfstream  # noqa: F401 - instrumented for coverage
        import lfstream.codec.bitstream  # noqa: F401
        import lfstream.codec.decoder  # noqa: F401
        import lfstream.codec.gains  # noqa: F401
        import lfstream.codec.hint  # noqa: F401
        import lfstream.codec.residual  # noqa: F401
    atheris.Setup(argv, one_input)
    atheris.Fuzz()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
