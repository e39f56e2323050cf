"""``lfstream compare`` on a long LF video: frames/s and peak memory, against the time to
read both inputs alone (the floor a comparison cannot beat).

A 1,000-frame 5x5x128x128 clip (a moving textured scene) and a copy with noise on every
tenth frame, both as ``.npy`` files (1.2 GB each, memory-mapped by ``compare``); the command
runs in a child process whose peak RSS is read from the kernel.

    python bench/compare.py [--json [FILE]] [--frames N] [--quick]
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _harness import ROOT, emit, parser


def make_clip(path_ref: str, path_test: str, frames: int, views: int = 5, size: int = 128) -> None:
    """Writes the two clips frame by frame (never whole in memory)."""
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, size=(views, views, size + frames // 4 + 8, size + 8, 3), dtype=np.uint8)
    ref = np.lib.format.open_memmap(path_ref, "w+", np.uint8, (frames, views, views, size, size, 3))
    test = np.lib.format.open_memmap(path_test, "w+", np.uint8, (frames, views, views, size, size, 3))
    for t in range(frames):
        y = t // 4
        frame = base[:, :, y:y + size, 4:4 + size]
        ref[t] = frame
        if t % 10 == 3:
            noisy = frame.astype(np.int16) + rng.integers(-6, 7, size=frame.shape, dtype=np.int16)
            test[t] = np.clip(noisy, 0, 255).astype(np.uint8)
        else:
            test[t] = frame
    ref.flush()
    test.flush()
    del ref, test


def run_child(argv: list[str]) -> tuple[float, float, int, str]:
    """Wall seconds, peak RSS in MB (this child's own), exit status and stdout of ``argv``."""
    with tempfile.TemporaryFile("w+") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.DEVNULL, cwd=ROOT)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        return wall, usage.ru_maxrss / 1024, proc.returncode, out.read()


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--frames", type=int, default=1000)
    args = p.parse_args(argv)
    frames = 100 if args.quick else args.frames
    with tempfile.TemporaryDirectory(prefix="lfstream-bench-compare-") as tmp:
        ref, test = Path(tmp) / "ref.npy", Path(tmp) / "test.npy"
        # in a child: the clips' pages would count in the RSS the timed children inherit at fork
        subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
                        f"import compare; compare.make_clip({str(ref)!r}, {str(test)!r}, {frames})"], check=True)
        cli = str(Path(sys.executable).parent / "lfstream")
        lfs = [cli, "compare", str(ref), str(test), "--min-psnr", "40", "--json"]
        run_child([cli, "compare", str(ref), str(ref), "--max-frames", "2"])  # warm: the kernels load from cache
        read = [sys.executable, "-c", "import sys\nfrom lfstream.testing.compare import open_frames\n"
                "a, b = open_frames(sys.argv[1]), open_frames(sys.argv[2])\n"
                "for x, y in zip(a.frames, b.frames): pass\n", str(ref), str(test)]
        t_read, _, _, _ = run_child(read)
        wall, rss, code, out = run_child(lfs)
    import json

    doc = json.loads(out)
    result = {"name": "compare", "frames": frames, "views": [5, 5], "size": [128, 128], "wall_s": wall,
              "fps": frames / wall, "peak_rss_mb": rss, "exit_status": code,
              "failed_frames": len(doc["failed_frames"]), "read_only_s": t_read, "read_only_fps": frames / t_read}
    print(f"compare: {frames} frames of 5x5x128x128 in {wall:.2f} s = {frames / wall:.0f} frames/s, peak RSS "
          f"{rss:.0f} MB, exit {code}, {len(doc['failed_frames'])} frames failed; reading both alone "
          f"{frames / t_read:.0f} frames/s")
    return emit(args, [result])


if __name__ == "__main__":
    main()
