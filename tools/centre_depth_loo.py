"""Leave-one-scene-out evaluation of the seed's Depth-Net (``depth_centre``).

For each shared scene: the network is trained on every other real scene
(``tools/train.py depth_centre --scenes ...``), then the scene's stream without a hint (the
seed's: a JPEG centre view at ``--quality``) is decoded with JPEG-Hance on, once flat (every
view the restored centre) and once with the fold's network; MPSNR and MSSIM of both, and the
hint's decode of the default stream beside them (what lfstream sends instead).

    python tools/centre_depth_loo.py [--steps N] [--scenes a,b] [--quality Q] [--out runs/loo]
                                     [--json docs/results/centre_depth_loo.json]

A fold whose checkpoint exists under ``--out`` is not trained again (``--retrain`` forces it).
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "tools"))


def decoded(data: bytes, depth: str, net=None):
    """The stream's first frame decoded with JPEG-Hance on (``net``: the seed's Depth-Net)."""
    from lfstream.codec.bitstream import iter_packets, read_header
    from lfstream.codec.decoder import Decoder

    fh = io.BytesIO(data)
    header = read_header(fh)
    dec = Decoder(header, depth=depth, hance="on", precision="float32", depth_net=net)
    return dec.decode_packet(next(iter_packets(fh, header))).lf


def evaluate(name: str, lf, net, quality: int) -> dict:
    import lfstream
    from lfstream.metrics import bpp, mpsnr, mssim

    seed_stream = lfstream.encode(lf, quality=quality, depth_hint=False, preset="fast")
    hint_stream = lfstream.encode(lf, quality=quality, preset="fast")
    row = {"scene": name, "bpp_seed": bpp(len(seed_stream), lf.shape), "bpp_hint": bpp(len(hint_stream), lf.shape)}
    for key, rec in (("flat", decoded(seed_stream, "flat")), ("net", decoded(seed_stream, "net", net)),
                     ("hint", decoded(hint_stream, "hint"))):
        row[f"mpsnr_{key}"] = round(float(mpsnr(lf, rec)), 3)
        row[f"mssim_{key}"] = round(float(mssim(lf, rec)), 5)
    row["gain_db"] = round(row["mpsnr_net"] - row["mpsnr_flat"], 3)
    row["mssim_gain"] = round(row["mssim_net"] - row["mssim_flat"], 5)
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--scenes", help="comma-separated scenes to hold out (default: every shared scene)")
    p.add_argument("--quality", type=int, default=50)
    p.add_argument("--out", type=Path, default=Path("runs/centre_depth_loo"))
    p.add_argument("--json", type=Path, help="write the rows here")
    p.add_argument("--retrain", action="store_true")
    args = p.parse_args(argv)

    import numpy as np
    import train
    from rd import scenes

    from lfstream.models.registry import load_model

    held = [s for s in (args.scenes or "").split(",") if s] or list(train.SHARED_SCENES)
    rows = []
    for name, lf in scenes(False, set(held)):
        others = [s for s in train.CENTRE_DEPTH_SCENES if s != name]
        out = args.out / name
        ckpt = out / "depth_centre-fast.pt"
        t0 = time.perf_counter()
        if args.retrain or not ckpt.exists():
            code = train.main(["depth_centre", "--steps", str(args.steps), "--scenes", ",".join(others),
                               "--out", str(out), "--checkpoint-every", "100000"])
            if code:
                return code
        train_s = time.perf_counter() - t0
        net = load_model("depth_centre", "fast", path=ckpt)
        row = evaluate(name, np.ascontiguousarray(lf), net, args.quality)
        row.update({"trained_on": others, "steps": args.steps, "train_s": round(train_s, 1)})
        print(json.dumps(row), flush=True)
        rows.append(row)
    if args.json:
        from _harness import metadata

        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"metadata": metadata(), "quality": args.quality, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
