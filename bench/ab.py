"""Is a change faster? Two revisions timed in alternating processes on a shared machine.

On the shared 2-core development machines the same encode measures 25-41 ms from one batch
of runs to the next, and its CPU time moves as much (the host's load, not the code): two
numbers taken minutes apart cannot show a 5-10 % change. This script runs the operation in
a fresh process per revision and round, alternating the order each round (A B, B A, ...), so
slow spells of the host fall on both; it reports each revision's median over the rounds'
medians, the per-round ratio head / base and a bootstrap interval of its median, and whether
the two revisions' outputs are identical (the digest of the stream, or of the decoded views).

    python bench/ab.py [--base REV] [--head REV] [--what encode|decode|stream]
                       [--scenes a,b] [--rounds N] [--runs M] [--quick] [--json [FILE]]

``--base`` defaults to ``HEAD``; ``--head`` to the working tree as it is (uncommitted changes
included). A revision other than the working tree is checked out into a temporary git
worktree (removed afterwards); each process imports lfstream from its tree and compiles its
numba kernels there on a first, uncounted round. ``encode``: ``lfstream.encode`` of each scene
(the default configuration); ``decode``: ``lfstream.decode`` of that revision's own stream;
``stream``: ``lfstream stream`` with no arguments (the README's first command; its summary's
frames/s, reported as seconds a frame). Scenes as in bench/rd.py (``synthetic`` and the
shared samples); default the 7x7 ones.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULT_PREFIX = "AB-RESULT "
DEFAULT_SCENES = ("synthetic", "lytro_bikes", "lytro_translucent")
WHATS = ("encode", "decode", "stream")


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(fn, runs: int) -> dict:
    """Median wall and process-CPU seconds of ``runs`` calls after two warm-up calls, and the
    digest of the last call's output."""
    import numpy as np

    out = fn()
    fn()
    walls, cpus = [], []
    for _ in range(runs):
        c0, t0 = _cpu_s(), time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(_cpu_s() - c0)
    return {"wall_s": float(np.median(walls)), "min_s": float(min(walls)), "cpu_s": float(np.median(cpus)),
            "digest": _digest(out)}


def _digest(out) -> str:
    import numpy as np

    h = hashlib.sha256()
    if isinstance(out, (bytes, bytearray)):
        h.update(out)
    else:
        h.update(np.ascontiguousarray(out).tobytes())
    return h.hexdigest()[:16]


def child(tree: Path, what: str, scenes: list[str], runs: int, quick: bool) -> dict:
    """Runs in a fresh process: lfstream imported from ``tree``, the scenes read through this
    checkout's bench/rd.py (the same inputs for both revisions)."""
    # the tree first; this checkout's root appended so that bench/_harness does not put it
    # in front (it inserts ROOT at 0 only when absent)
    sys.path[:0] = [str(tree), str(ROOT / "bench")]
    sys.path.append(str(ROOT))
    import lfstream

    if not Path(lfstream.__file__).resolve().is_relative_to(tree.resolve()):
        raise SystemExit(f"ab: imported lfstream from {lfstream.__file__}, not from {tree}")
    if what == "stream":
        from lfstream.cli import main

        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "out"
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                rc = main(["stream", "-o", str(out)])
            if rc:
                raise SystemExit(f"ab: lfstream stream exited with {rc}")
            summary = json.loads((out / "summary.json").read_text())
        fps = float(summary["fps"])
        return {"stream": {"wall_s": 1.0 / fps, "min_s": 1.0 / fps, "cpu_s": float("nan"), "fps": fps,
                           "digest": f"{summary['bytes']}B {summary['mpsnr']:.4f}dB"}}
    from rd import scenes as load_scenes

    results = {}
    for name, lf in load_scenes(quick, set(scenes)):
        if what == "encode":
            results[name] = _timed(lambda: lfstream.encode(lf), runs)
        else:
            data = lfstream.encode(lf)
            results[name] = _timed(lambda: lfstream.decode(data), runs)
    return results


def _run_child(tree: Path, args: argparse.Namespace, runs: int) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(tree), "--what", args.what,
           "--scenes", ",".join(args.scenes), "--runs", str(runs)] + (["--quick"] if args.quick else [])
    proc = subprocess.run(cmd, cwd=tempfile.gettempdir(), capture_output=True, text=True, check=False)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(RESULT_PREFIX)]
    if proc.returncode or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise SystemExit(f"ab: the run in {tree} failed (exit {proc.returncode}): " + " | ".join(tail))
    return json.loads(lines[-1][len(RESULT_PREFIX):])


def summarise(base: list[dict], head: list[dict], seed: int = 0, resamples: int = 2000) -> dict:
    """Per scene: each revision's median over its rounds' medians, the per-round ratios head /
    base (rounds paired as they ran), their median with a bootstrap 90 % interval (rounds
    resampled), how many rounds head was faster, and whether the outputs were identical.

    Args:
        base, head: one dict per round, scene -> ``{"wall_s", "cpu_s", "digest", ...}``.
    """
    import numpy as np

    rng = np.random.default_rng(seed)
    out = {}
    for scene in base[0]:
        a = np.array([r[scene]["wall_s"] for r in base])
        b = np.array([r[scene]["wall_s"] for r in head])
        ratio = b / a
        boot = np.median(ratio[rng.integers(0, len(ratio), (resamples, len(ratio)))], axis=1)
        lo, hi = np.percentile(boot, [5, 95])
        digests = {r[scene]["digest"] for r in base} | {r[scene]["digest"] for r in head}
        out[scene] = {"base_s": float(np.median(a)), "head_s": float(np.median(b)),
                      "base_cpu_s": float(np.median([r[scene]["cpu_s"] for r in base])),
                      "head_cpu_s": float(np.median([r[scene]["cpu_s"] for r in head])),
                      "ratio": float(np.median(ratio)), "ratio_90": [float(lo), float(hi)],
                      "head_faster_rounds": int(np.sum(ratio < 1.0)), "rounds": len(ratio),
                      "identical_outputs": len(digests) == 1}
    return out


def _worktree(rev: str, into: Path) -> Path:
    proc = subprocess.run(["git", "worktree", "add", "--detach", "--force", str(into), rev], cwd=ROOT,
                          capture_output=True, text=True, check=False)
    if proc.returncode:
        raise SystemExit(f"ab: cannot check out {rev!r}: {' '.join(proc.stderr.strip().splitlines()[-1:])}")
    return into


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--base", default="HEAD", help="the revision to compare against (default HEAD)")
    p.add_argument("--head", default=None, help="the revision measured (default: the working tree as it is)")
    p.add_argument("--what", choices=WHATS, default="encode")
    p.add_argument("--scenes", type=lambda s: [x for x in s.split(",") if x], default=list(DEFAULT_SCENES))
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--runs", type=int, default=9, help="timed calls per scene in each process")
    p.add_argument("--quick", action="store_true", help="smaller scenes (bench/rd.py's quick sizes)")
    p.add_argument("--json", type=Path, nargs="?", const=Path("-"))
    p.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child is not None:
        print(RESULT_PREFIX + json.dumps(child(args.child, args.what, args.scenes, args.runs, args.quick)),
              flush=True)
        return {}
    if args.rounds < 2 or args.runs < 1:
        p.error("--rounds: at least 2; --runs: at least 1")
    tmp = Path(tempfile.mkdtemp(prefix="lfstream-ab-"))
    made = []
    try:
        trees = {}
        for label, rev in (("base", args.base), ("head", args.head)):
            if rev is None:
                trees[label] = ROOT
            else:
                trees[label] = _worktree(rev, tmp / label)
                made.append(trees[label])
        load = [os.getloadavg()[0]]
        for label in ("base", "head"):  # compiles each tree's kernels; not counted
            _run_child(trees[label], args, 1)
        rounds = {"base": [], "head": []}
        for r in range(args.rounds):
            for label in (("base", "head") if r % 2 == 0 else ("head", "base")):
                rounds[label].append(_run_child(trees[label], args, args.runs))
            print(f"round {r + 1}/{args.rounds}: " + "  ".join(
                f"{s} {1e3 * rounds['base'][-1][s]['wall_s']:.1f} / {1e3 * rounds['head'][-1][s]['wall_s']:.1f} ms"
                for s in rounds["base"][-1]), flush=True)
        load.append(os.getloadavg()[0])
    finally:
        for tree in made:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, capture_output=True,
                           check=False)
        shutil.rmtree(tmp, ignore_errors=True)
    summary = summarise(rounds["base"], rounds["head"])
    unit = "s a frame" if args.what == "stream" else "ms"  # lower is better either way
    print(f"\n{args.what}: base {args.base}, head {args.head or 'the working tree'}; {args.rounds} rounds "
          f"of {args.runs} runs alternating; load average {load[0]:.2f} -> {load[1]:.2f}")
    if args.rounds < 4:
        print("  (fewer than 4 rounds: the interval says little; the same code measured against itself "
              "moved by 10-20 % in 2 rounds here)")
    for scene, s in summary.items():
        scale = 1.0 if args.what == "stream" else 1e3
        if args.what == "stream":
            print(f"  frames/s: base {1.0 / s['base_s']:.2f}, head {1.0 / s['head_s']:.2f}")
        print(f"  {scene:18s} base {scale * s['base_s']:8.2f} {unit}  head {scale * s['head_s']:8.2f} {unit}  "
              f"head/base {s['ratio']:.3f} (90 %: {s['ratio_90'][0]:.3f}-{s['ratio_90'][1]:.3f}), faster in "
              f"{s['head_faster_rounds']}/{s['rounds']} rounds, outputs "
              f"{'identical' if s['identical_outputs'] else 'differ'}"
              + ("" if args.what == "stream" else
                 f"; CPU {scale * s['base_cpu_s']:.1f} / {scale * s['head_cpu_s']:.1f} {unit}"))
    doc = {"what": args.what, "base": args.base, "head": args.head, "rounds": args.rounds, "runs": args.runs,
           "load_average": load, "results": summary, "raw": rounds}
    if args.json is not None:
        text = json.dumps(doc, indent=1)
        print(text) if str(args.json) == "-" else args.json.write_text(text)
    return doc


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:  # the worktrees are removed by main's finally
        print("ab: interrupted", file=sys.stderr)
        sys.exit(130)
