"""Figures for the README and the docs from bench JSON (matplotlib, the ``docs`` extra).

    python bench/plots.py [--results docs/results] [--out docs/figures]

``codec.png``: every scene's operating points from ``bench/codec.py`` — MPSNR against bpp
(left) and encode time against MPSNR (right), lfstream beside the anchors at the same size.
``rd_SCENE.png`` for each scene in ``rd.json`` when ``bench/rd.py --json docs/results/rd.json``
has been run: the rate-distortion curves of every method. Each figure names its CPU and date.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
METHOD_STYLE = {"lfstream": ("tab:red", "o"), "x265 medium": ("tab:blue", "s"), "x265 ultrafast": ("tab:cyan", "v"),
                "SVT-AV1 p8": ("tab:green", "^")}


def _save(fig, path: Path) -> Path:
    """Writes a figure as PNG without a timestamp or version in it (the same JSON gives the
    same file)."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)
    return path


def _machine(doc: dict) -> str:
    meta = doc["metadata"]
    return f"{meta['device']['cpu']}, {meta['device']['cores']} cores, {meta['time'][:10]}"


def _family(method: str) -> str:
    if method.startswith("lfstream"):
        return "lfstream"
    return method.split(" @")[0]


def _operating_points(doc: dict) -> list[tuple[str, str, list[dict]]]:
    """(scene, point, rows) per operating point: lfstream's row then the anchors at its size."""
    out, cur = [], None
    for r in doc["results"]:
        if "flat" in r["method"]:
            continue
        if r["method"].startswith("lfstream"):
            cur = (r["lf"], "--bpp" if "--bpp" in r["method"] else "default", [r])
            out.append(cur)
        elif cur is not None and r["lf"] == cur[0]:
            cur[2].append(r)
    return out


def codec_figure(doc: dict, out: Path) -> Path:
    """Every method's MPSNR margin over x265 medium at the same size against its encode speed
    relative to x265 medium, one marker per scene and operating point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    seen = set()
    for scene, point, rows in _operating_points(doc):
        ref = next((r for r in rows if r["method"].startswith("x265 medium")), None)
        if ref is None:
            continue
        for r in rows:
            fam = _family(r["method"])
            if fam == "x265 medium":
                continue
            colour, marker = METHOD_STYLE.get(fam, ("grey", "x"))
            label = f"lfstream {point}" if fam == "lfstream" else fam
            if fam == "lfstream" and point == "--bpp":
                marker = "D"
            speed = ref["encode_s"] / r["encode_s"]
            ax.scatter(speed, r["mpsnr"] - ref["mpsnr"], c=colour, marker=marker, s=36,
                       label=None if label in seen else label, edgecolors="black" if fam == "lfstream" else "none",
                       linewidths=0.5)
            seen.add(label)
            if fam == "lfstream":
                ax.annotate(scene, (speed, r["mpsnr"] - ref["mpsnr"]), fontsize=7, xytext=(4, 2),
                            textcoords="offset points")
    ax.axhline(0, color="tab:blue", lw=1)
    ax.axvline(1, color="tab:blue", lw=1)
    ax.text(1.05, ax.get_ylim()[0], "x265 medium", color="tab:blue", fontsize=8, va="bottom")
    ax.set_xscale("log")
    ax.set_xlabel("encode speed relative to x265 medium (×, log; right is faster)")
    ax.set_ylabel("MPSNR − x265 medium's at the same bpp (dB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(f"bench/codec.py — {_machine(doc)}", fontsize=9)
    return _save(fig, out)


def rd_figure(scene: str, curves: dict[str, list[dict]], machine: str, path: Path) -> Path:
    """One scene's rate-distortion curves: MPSNR and MSSIM against bpp for every method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for method, pts in curves.items():
        pts = sorted(pts, key=lambda q: q["bpp"])
        style = "-" if method.startswith("lfstream") else "--"
        for ax, key in zip(axes, ("mpsnr", "mssim")):
            ax.plot([q["bpp"] for q in pts], [q[key] for q in pts], style, marker=".", label=method)
    for ax, label in zip(axes, ("MPSNR (dB)", "MSSIM")):
        ax.set_xscale("log")
        ax.set_xlabel("bits per pixel (log)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{scene} — {machine}", fontsize=9)
    return _save(fig, path)


def rd_figures(doc: dict, out_dir: Path) -> list[Path]:
    return [rd_figure(r["scene"], r["curves"], _machine(doc), out_dir / f"rd_{r['scene']}.png")
            for r in doc.get("results", [])]


def main(argv: Sequence[str] | None = None) -> list[Path]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", type=Path, default=ROOT / "docs" / "results")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    args = p.parse_args(argv)
    written = []
    codec = args.results / "codec.json"
    if codec.exists():
        written.append(codec_figure(json.loads(codec.read_text()), args.out / "codec.png"))
    rd = args.results / "rd.json"
    if rd.exists():
        written += rd_figures(json.loads(rd.read_text()), args.out)
    for path in written:
        print(path)
    return written


if __name__ == "__main__":
    main()
