"""The share of JPEG-Hance's correction its preset applies, measured by leaving each training scene out.

    python tools/hance_strength.py [--preset fast] [--out runs/hance_strength] [--quality 50]

A JPEG-Hance trained on three real scenes over-corrects scenes it has not seen: on the
decoded light field of the held-out samples the best share of the fast network's correction
was 0.45-0.70 on two of them, and above 1 on the third. The preset's ``strength``
(:class:`lfstream.models.jpeg_hance.HanceConfig`) is chosen without looking at the held-out
samples: for each scene the preset trains on (``tools/train.py`` ``HANCE_TRAIN_SCENES``), the
preset's whole recipe is trained on the others (``tools/train.py jpeg_hance --scenes ...``),
the left-out scene is coded by the fast encode at ``--quality`` and decoded with the fold's
network at full strength and without it. The decoded light field is linear in the strength
(the warp is linear in the image it warps; up to rounding), so the strength that serves that
scene best is ``s* = <E, D> / <D, D>``, with ``E`` the decoded light field's error without
the network and ``D`` the network's change to it, over the views present. The preset's
strength is the mean of the folds' ``s*``. A fold takes about 12 minutes on the 2-core CPU
(the 24 x 4 fast network); a fold whose weights are in ``--out`` is not trained again.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1] / "bench")]

import train  # noqa: E402  (tools/train.py)
from _harness import SHARED, SHARED_SCENES  # noqa: E402


def strength_on(name: str, model, quality: int) -> dict:
    """The fast encode of scene ``name`` at ``quality``, decoded without JPEG-Hance and with
    ``model`` at full strength: the best share ``s*`` of its correction and the MPSNR / MSSIM
    gains at full strength and at ``s*``."""
    import lfstream
    from lfstream.codec.bitstream import iter_packets, read_header
    from lfstream.codec.decoder import Decoder
    from lfstream.codec.warp.cpu import warp_views
    from lfstream.metrics import mpsnr, mssim
    from lfstream.models.jpeg_hance import restore_images

    lf, present = lfstream.read_lf(SHARED / SHARED_SCENES[name], return_mask=True)
    data = lfstream.encode(lf, present=None if present.all() else present, preset="fast", quality=quality)
    fh = io.BytesIO(data)
    header = read_header(fh)
    decoder = Decoder(header, hance="off")
    frame = decoder.decode_packet(next(iter_packets(fh, header)))
    full = type(model)(replace(model.config, strength=1.0)).eval()  # the whole trained correction
    full.load_state_dict(model.state_dict())
    restored = restore_images(frame.centre[None], full)[0]
    on = warp_views(restored, frame.disparity, lf.shape[:2], occlusion=decoder.occlusion, gains=frame.gains,
                    axes=frame.axes)
    err = lf[present].astype(np.float64) - frame.lf[present]
    change = on[present].astype(np.float64) - frame.lf[present]
    s_best = float((err * change).sum() / max(float((change * change).sum()), 1e-12))
    at_best = np.clip(np.rint(frame.lf + s_best * (on.astype(np.float64) - frame.lf)), 0, 255).astype(np.uint8)
    base = float(mpsnr(lf, frame.lf, present=present))
    base_ssim = float(mssim(lf, frame.lf, present=present))

    def gains(rec: np.ndarray) -> tuple[float, float]:
        return (round(float(mpsnr(lf, rec, present=present)) - base, 4),
                round(float(mssim(lf, rec, present=present)) - base_ssim, 5))

    (full_db, full_ssim), (best_db, best_ssim) = gains(on), gains(at_best)
    return {"scene": name, "quality": quality, "s_best": round(s_best, 4), "gain_full_db": full_db,
            "mssim_gain_full": full_ssim, "gain_best_db": best_db, "mssim_gain_best": best_ssim}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--preset", default="fast", choices=["fast"])
    p.add_argument("--out", type=Path, default=Path("runs/hance_strength"))
    p.add_argument("--quality", type=int, default=50, help="JPEG quality of the folds' encodes (the default's)")
    args = p.parse_args(argv)
    from lfstream.models.registry import load_model

    folds = []
    for left_out in train.HANCE_TRAIN_SCENES:
        others = [s for s in train.HANCE_TRAIN_SCENES if s != left_out]
        out = args.out / f"without_{left_out}"
        weights = out / f"jpeg_hance-{args.preset}.pt"
        if not weights.exists():
            code = train.main(["jpeg_hance", "--preset", args.preset, "--scenes", ",".join(others), "--out", str(out)])
            if code:
                return code
        model = load_model("jpeg_hance", args.preset, "cpu", path=weights)
        fold = strength_on(left_out, model, args.quality)
        fold["trained_on"] = others
        folds.append(fold)
        print(json.dumps(fold), flush=True)
    strength = float(np.mean([f["s_best"] for f in folds]))
    result = {"preset": args.preset, "quality": args.quality, "strength": round(strength, 3), "folds": folds}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "strength.json").write_text(json.dumps(result, indent=1) + "\n")
    print(f"strength {strength:.3f} (mean of the folds' s*: {', '.join(str(f['s_best']) for f in folds)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
