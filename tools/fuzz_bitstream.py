"""Long fuzz run of the .lfs parser and decoder (the test suite runs a short one).

Mutates valid streams — bit flips, truncation, absurd 32-bit values at random offsets,
appended garbage — and checks that every outcome is either a decoded light field of the
right shape or an ``LFStreamError``: never another exception, a crash or a hang.

    python tools/fuzz_bitstream.py [--cases 20000] [--seed 0]
"""

from __future__ import annotations

import argparse
import struct
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from lfstream.codec import decode, encode  # noqa: E402
from lfstream.errors import LFStreamError  # noqa: E402
from lfstream.synth import synth_clip  # noqa: E402

KINDS = ("bitflip", "truncate", "length", "garbage")


def mutate(data: bytes, rng: np.random.Generator, kind: str) -> bytes:
    """One random mutation of ``data`` of the given kind."""
    out = bytearray(data)
    if kind == "bitflip":
        for _ in range(int(rng.integers(1, 4))):
            pos = int(rng.integers(0, len(out)))
            out[pos] ^= 1 << int(rng.integers(0, 8))
    elif kind == "truncate":
        out = out[: int(rng.integers(0, len(out)))]
    elif kind == "length":
        pos = int(rng.integers(0, max(1, len(out) - 4)))
        struct.pack_into("<I", out, pos, int(rng.integers(0, 2**32)))
    elif kind == "garbage":
        out += rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8).tobytes()
    else:
        raise ValueError(f"unknown mutation {kind!r}")
    return bytes(out)


def fuzz(streams: list[bytes], cases: int, seed: int) -> dict:
    """Runs ``cases`` mutations; returns counts. Raises on any unexpected exception."""
    rng = np.random.default_rng(seed)
    counts = {"decoded": 0, "rejected": 0}
    for case in range(cases):
        data = mutate(streams[case % len(streams)], rng, KINDS[case % len(KINDS)])
        try:
            out = decode(data)
            assert out.ndim == 6 and out.dtype == np.uint8
            counts["decoded"] += 1
        except LFStreamError:
            counts["rejected"] += 1
    return counts


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--cases", type=int, default=20000)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    streams = [encode(synth_clip(3, 5, (40, 48), seed=1).lf, quality=60, preset="fast"),
               encode(synth_clip(2, 3, (32, 32), seed=2, vignetting=0.6).lf, depth_hint=True, preset="fast"),
               encode(synth_clip(1, 3, (32, 32), seed=4).lf, residual=50),  # a residual layer
               # the views as one AV1 sequence keyed by the centre payload
               encode(synth_clip(1, 3, (32, 32), seed=5).lf, preset="balanced", quality=50, residual=50,
                      residual_mode="views")]
    t0 = time.perf_counter()
    counts = fuzz(streams, args.cases, args.seed)
    print(f"{args.cases} cases in {time.perf_counter() - t0:.1f} s: {counts['decoded']} decoded, "
          f"{counts['rejected']} rejected with LFStreamError, 0 other failures")
    return 0


if __name__ == "__main__":
    sys.exit(main())
