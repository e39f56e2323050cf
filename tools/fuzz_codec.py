"""Long random run of the codec's round trip: encode, encode again, decode.

Draws light fields and videos of random grids, sizes and content (noise, constant, a hard
edge, a texture with parallax along random view axes) and random options (quality, preset,
rate control's target, the residual layer, no hint, JPEG-Hance strength maps, missing
views), and checks that every encode either is refused with an ``LFStreamError`` (an option
the input cannot take, named in one line) or gives the same bytes twice, and that the stream
decodes to uint8 views of the input's shape (with JPEG-Hance too where the encoder sent its
strength maps). The test suite runs the stability test's short random search and a few
of these cases; this is the long run (it found a key hint with an inverted range, which
the decoder refused: a tiny noisy frame whose whole map lay past the range swept).

    python tools/fuzz_codec.py [--cases 300] [--seed 0] [--min-size 8] [--max-size 72]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import lfstream  # noqa: E402
from lfstream.errors import LFStreamError  # noqa: E402

CONTENTS = ("noise", "constant", "edge", "parallax")


@dataclass
class Case:
    """One random input and its encode options."""

    lf: np.ndarray  # (U, V, H, W, 3) or (T, U, V, H, W, 3) uint8
    content: str
    options: dict = field(default_factory=dict)

    def describe(self) -> str:
        opts = {k: ("mask" if k == "present" else v) for k, v in self.options.items()}
        return f"{self.content} {tuple(self.lf.shape)} {opts}"


def draw_case(rng: np.random.Generator, min_size: int = 8, max_size: int = 72) -> Case:
    """A random light field (or video of up to three frames) and encode options."""
    t = int(rng.integers(1, 4))
    u, v = int(rng.integers(1, 6)), int(rng.integers(1, 6))
    h, w = int(rng.integers(min_size, max_size + 1)), int(rng.integers(min_size, max_size + 1))
    content = CONTENTS[int(rng.integers(0, len(CONTENTS)))]
    if content == "noise":
        lf = rng.integers(0, 256, (t, u, v, h, w, 3), dtype=np.uint8)
    elif content == "constant":
        lf = np.full((t, u, v, h, w, 3), int(rng.integers(0, 256)), np.uint8)
    elif content == "edge":
        lf = np.zeros((t, u, v, h, w, 3), np.uint8)
        lf[..., : w // 2, :] = 255
    else:  # a texture shifting by up to 6 px per view step, partly along the other axis
        base = rng.integers(0, 256, (h, w + 40, 3), dtype=np.uint8)
        step = float(rng.uniform(-6, 6))
        one = np.stack([np.stack([np.roll(base, int(round(step * (b - v // 2) + 0.3 * step * (a - u // 2))), axis=1)[:, :w]
                                  for b in range(v)]) for a in range(u)])
        lf = np.stack([np.roll(one, k, axis=3) for k in range(t)])  # the scene moves a pixel a frame
    if t == 1 and rng.random() < 0.5:
        lf = lf[0]  # one light field, not a video of one frame
    options: dict = {"quality": int(rng.integers(1, 101))}
    r = rng.random()
    if r < 0.25:
        options["bpp"] = float(rng.choice([0.01, 0.05, 0.2, 1.0]))
    elif r < 0.45:
        options["preset"] = str(rng.choice(["fast", "balanced", "best"]))
    elif r < 0.55:
        options["preset"], options["residual"] = "fast", int(rng.integers(1, 101))
    elif r < 0.65:
        options["depth_hint"] = False
    elif r < 0.72:
        options["preset"], options["hance_map"] = "fast", True  # JPEG-Hance strength maps
    if lf.ndim == 5 and u * v > 1 and rng.random() < 0.3:
        present = rng.random((u, v)) < 0.7
        present[u // 2, v // 2] = True  # the codec sends the centre view
        options["present"] = present
    return Case(lf, content, options)


def run_case(case: Case) -> str:
    """``"decoded"`` or ``"refused"``; raises AssertionError (or the unexpected exception)
    where the round trip breaks its contract."""
    try:
        data = lfstream.encode(case.lf, **case.options)
    except LFStreamError:
        return "refused"
    assert data == lfstream.encode(case.lf.copy(), **case.options), "the same input gave other bytes"
    frames = case.lf.shape[0] if case.lf.ndim == 6 else 1
    for hance in ("auto", "on") if case.options.get("hance_map") else ("auto",):  # the map is used with the network
        out = lfstream.decode(data, hance=hance)
        assert out.dtype == np.uint8 and out.shape == (frames, *case.lf.shape[-5:]), (out.shape, out.dtype)
    return "decoded"


def fuzz(cases: int, seed: int, min_size: int = 8, max_size: int = 72) -> dict:
    """Runs ``cases`` random round trips; returns the counts and the failures (each with the
    case's description and the error)."""
    rng = np.random.default_rng(seed)
    counts = {"decoded": 0, "refused": 0, "failed": 0}
    failures = []
    for k in range(cases):
        case = draw_case(rng, min_size, max_size)
        try:
            counts[run_case(case)] += 1
        except Exception as exc:  # noqa: BLE001 - every other outcome is a finding, reported
            counts["failed"] += 1
            failures.append(f"case {k}: {case.describe()}: {type(exc).__name__}: {exc}")
    return {**counts, "failures": failures}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--min-size", type=int, default=8, help="smallest view side drawn")
    p.add_argument("--max-size", type=int, default=72, help="largest view side drawn")
    args = p.parse_args(argv)
    if not 1 <= args.min_size <= args.max_size:
        p.error("--min-size and --max-size: 1 <= min <= max")
    t0 = time.perf_counter()
    result = fuzz(args.cases, args.seed, args.min_size, args.max_size)
    for line in result["failures"]:
        print(line)
    print(f"{args.cases} cases in {time.perf_counter() - t0:.0f} s: {result['decoded']} decoded, "
          f"{result['refused']} refused, {result['failed']} failed")
    return 1 if result["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
