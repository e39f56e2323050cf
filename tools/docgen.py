"""Generated documentation: tables from bench JSON and the model manifest, the CLI reference
from the argparse parsers, and the README's generated blocks.

The README and the docs site show measured numbers only through this module, so a table
cannot drift from the JSON it was made from; ``tests/test_docs.py`` checks the README's
blocks against it.

    python tools/docgen.py            # rewrite the README's generated blocks
    python tools/docgen.py --check    # exit 1 if they are stale (what the test checks)
"""

from __future__ import annotations

import argparse
import functools
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
README = ROOT / "README.md"
MANIFEST = ROOT / "lfstream" / "models" / "weights" / "manifest.json"
#: The anchors the results table sets beside lfstream, in column order.
ANCHORS = ("x265 medium", "x265 ultrafast", "SVT-AV1 p8")
_BLOCK = re.compile(r"(<!-- generated:(?P<name>[a-z-]+) -->\n)(?P<body>.*?)(<!-- /generated -->)", re.S)


def load(name: str) -> dict:
    """One bench JSON document from ``docs/results`` (``{"metadata": ..., "results": [...]}``)."""
    return json.loads((RESULTS / f"{name}.json").read_text())


def machine(doc: dict) -> str:
    """The CPU, its cores and the date of a bench document, for a table's caption."""
    meta = doc["metadata"]
    dev = meta["device"]
    gpu = f", {dev['cuda']}" if dev.get("cuda") else ""
    flags = dev.get("flags") or []
    simd = " (AVX-512)" if "avx512f" in flags else (" (AVX2)" if "avx2" in flags else "")
    return f"{dev['cpu']}{simd}, {dev['cores']} cores{gpu}; {meta['time'][:10]}"


def _cell(row: dict | None) -> str:
    if row is None:
        return "—"
    return (f"{row['mpsnr']:.2f} / {row['mssim']:.4f} · {row['encode_s'] * 1e3:.0f} / "
            f"{row['decode_s'] * 1e3:.0f} ms")


def _points(doc: dict) -> list[tuple[str, str, dict, dict[str, dict]]]:
    """(scene, point label, lfstream's row, anchors by name) for every operating point."""
    out = []
    rows = doc["results"]
    for i, r in enumerate(rows):
        method = r["method"]
        if method.startswith("lfstream q50 (default"):
            label, suffix = "default (q50)", "@ default bpp"
        elif method.startswith("lfstream --bpp"):
            label, suffix = method.removeprefix("lfstream "), "@ --bpp bpp"
        else:
            continue
        anchors = {}
        for other in rows[i + 1:]:
            if other["lf"] != r["lf"] or other["method"].startswith("lfstream --bpp"):
                break
            for name in ANCHORS:
                if other["method"] == f"{name} {suffix}":
                    anchors[name] = other
        out.append((r["lf"], label, r, anchors))
    return out


def results_table(doc: dict) -> str:
    """The README's results table: every scene at the default's and at ``--bpp``'s size, each
    cell MPSNR (dB) / MSSIM · encode / decode ms."""
    head = ["scene", "point", "bpp", "lfstream", *ANCHORS]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene, label, ours, anchors in _points(doc):
        point = f"`{label}`" if label.startswith("--") else label
        cells = [scene, point, f"{ours['bpp']:.4f}", f"**{_cell(ours)}**", *(_cell(anchors.get(a)) for a in ANCHORS)]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"Each cell: MPSNR dB / MSSIM · encode / decode ms; anchors coded as one pseudo-sequence "
                 f"searched to lfstream's size. `bench/codec.py` on {machine(doc)}.")
    return "\n".join(lines) + "\n"


def speed_table(doc: dict) -> str:
    """Per operating point: the speed ratios against x265 medium (encode) and HEVC (decode)
    and the MPSNR / MSSIM margins over each anchor."""
    head = ["scene", "point", "encode vs x265 medium", "decode vs HEVC", *(f"Δ vs {a} (dB / MSSIM)" for a in ANCHORS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene, label, ours, anchors in _points(doc):
        med = anchors.get("x265 medium")
        enc = f"{med['encode_s'] / ours['encode_s']:.2f}×" if med else "—"
        dec = f"{med['decode_s'] / ours['decode_s']:.2f}×" if med else "—"
        deltas = []
        for a in ANCHORS:
            other = anchors.get(a)
            deltas.append("—" if other is None else
                          f"{ours['mpsnr'] - other['mpsnr']:+.2f} / {ours['mssim'] - other['mssim']:+.4f}")
        point = f"`{label}`" if label.startswith("--") else label
        lines.append("| " + " | ".join([scene, point, enc, dec, *deltas]) + " |")
    return "\n".join(lines) + "\n"


def rate_table(doc: dict) -> str:
    """``bench/rate.py``: every scene, target and rate-control row with its margins over x265
    medium and SVT-AV1 preset 4 at the same size and its speed against x265 medium, then the
    video row."""
    head = ["scene", "T", "rate control", "family", "bpp", "MPSNR / MSSIM", "Δ vs x265 medium (dB / MSSIM)",
            "Δ vs SVT-AV1 p4 (dB / MSSIM)", "encode s", "encode vs x265 medium", "decode vs HEVC"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in doc["results"]:
        for p in r["points"]:
            a, b = p["vs x265 medium"], p["vs SVT-AV1 p4"]
            lines.append("| " + " | ".join([
                r["scene"], f"{p['target_bpp']:g}", f"`{p['row']}`", p["family"], f"{p['bpp']:.4f}",
                f"{p['mpsnr']:.2f} / {p['mssim']:.4f}", f"{a['mpsnr_db']:+.2f} / {a['mssim']:+.4f}",
                f"{b['mpsnr_db']:+.2f} / {b['mssim']:+.4f}", f"{p['encode_s']:.2f}", f"{a['encode_speed']:.2f}×",
                f"{a['decode_speed']:.2f}×"]) + " |")
    video = doc.get("video")
    if video:
        lines += ["", f"Video: the synthetic clip ({video['frames']} frames of {video['shape'][1]}×{video['shape'][2]}×"
                      f"{video['shape'][3]}×{video['shape'][4]}) at `--bpp {video['target_bpp']:g}`: "
                      f"{video['bpp']:.4f} bpp overall, the largest frame {video['max_frame_over_target']:.2f}× the target, "
                      f"{video['encode_s_per_frame']:.2f} s a frame against x265 medium's "
                      f"{video['x265_medium_s_per_frame']:.2f} s ({video['family']} family)."]
    lines += ["", f"`bench/rate.py` on {machine(doc)}."]
    return "\n".join(lines) + "\n"


def bd_table(doc: dict) -> str:
    """``bench/rd.py``: per scene and method, the BD-rates (MPSNR / MSSIM; negative: fewer
    bits for the same quality) against x265 medium and against SVT-AV1 preset 4."""
    head = ["scene", "method", "BD-rate vs x265 medium (PSNR / SSIM)", "BD-rate vs SVT-AV1 p4 (PSNR / SSIM)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cell(row: dict | None) -> str:
        if row is None:
            return "—"
        vals = [row.get("bd_rate_psnr_pct"), row.get("bd_rate_ssim_pct")]
        return " / ".join("n/a" if v is None else f"{v:+.1f} %" for v in vals)

    for r in doc["results"]:
        vs_x265, vs_p4 = r["bjontegaard_vs_x265_medium"], r.get("bjontegaard_vs_svt_av1_p4", {})
        for method in [m for m in r["curves"] if m not in ("x265 medium", "SVT-AV1 p4")]:
            lines.append(f"| {r['scene']} | {method} | {cell(vs_x265.get(method))} | {cell(vs_p4.get(method))} |")
    lines += ["", f"`bench/rd.py` on {machine(doc)}."]
    return "\n".join(lines) + "\n"


def generic_table(doc: dict, columns: Sequence[str] | None = None, limit: int = 60) -> str:
    """Any bench document's results as a table of their scalar fields."""
    rows = doc["results"]
    if columns is None:
        columns = []
        for r in rows:
            for k, v in r.items():
                if k not in columns and isinstance(v, (int, float, str, bool)) and not k.startswith("_"):
                    columns.append(k)
        columns = columns[:9]

    def fmt(v) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return "—" if v is None else str(v)

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows[:limit]:
        lines.append("| " + " | ".join(fmt(r.get(c)) for c in columns) + " |")
    return "\n".join(lines) + "\n"


def loo_table(doc: dict) -> str:
    """The seed's Depth-Net held out scene by scene (``tools/centre_depth_loo.py``): the
    stream without a hint decoded flat and with the network (JPEG-Hance on in both), and the
    hint's decode of the default stream."""
    lines = ["| held-out scene | bpp (no hint) | flat MPSNR / MSSIM | Depth-Net MPSNR / MSSIM | gain | "
             "bpp (hint) | hint MPSNR / MSSIM |", "|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        lines.append(f"| {r['scene']} | {r['bpp_seed']:.4f} | {r['mpsnr_flat']:.2f} / {r['mssim_flat']:.4f} | "
                     f"{r['mpsnr_net']:.2f} / {r['mssim_net']:.4f} | {r['gain_db']:+.2f} dB | {r['bpp_hint']:.4f} | "
                     f"{r['mpsnr_hint']:.2f} / {r['mssim_hint']:.4f} |")
    steps = {r["steps"] for r in doc["rows"]}
    lines += ["", f"JPEG q{doc['quality']}; each network trained for {', '.join(map(str, sorted(steps)))} steps on "
              f"every other real scene; `tools/centre_depth_loo.py` on {machine(doc)}."]
    return "\n".join(lines) + "\n"


def seed_table(doc: dict) -> str:
    """``bench/networks.py --seed``: the seed's pipeline against lfstream's default and the
    anchors at the seed stream's size."""
    lines = ["| scene | method | bpp | MPSNR | MSSIM | encode ms | decode ms |", "|---|---|---|---|---|---|---|"]
    for r in doc["results"]:
        lines.append(f"| {r['lf']} | {r['method']} | {r['bpp']:.4f} | {r['mpsnr']:.2f} | {r['mssim']:.4f} | "
                     f"{r['encode_ms']:.0f} | {r['decode_ms']:.0f} |")
    lines += ["", f"`bench/networks.py --seed` on {machine(doc)}."]
    return "\n".join(lines) + "\n"


def fast_end_table(doc: dict) -> str:
    """``bench/throughput.py --fast-end``: the default decode against HEVC's decode to RGB per
    scene, and ``lfstream stream``'s frames/s per run, each against its target."""
    rows = doc["results"]
    decode = [r for r in rows if "ratio_best" in r]
    stream = [r for r in rows if "fps_runs" in r]
    lines = []
    if decode:
        target = decode[0]["target_ratio"]
        lines += [f"| scene | views | lfstream ms | HEVC ms | ratio (best of {decode[0]['runs']}) | per-round median "
                  f"(range) | ≥ {target:g}× |", "|---|---|---|---|---|---|---|"]
        for r in decode:
            u, v, h, w = r["shape"][:4]
            lines.append(f"| {r['lf']} | {u}×{v}×{h}×{w} | {r['lfstream_best_ms']:.1f} | {r['hevc_best_ms']:.1f} | "
                         f"{r['ratio_best']:.2f}× | {r['ratio_median']:.2f}× ({r['ratio_range'][0]:.2f}–"
                         f"{r['ratio_range'][1]:.2f}) | {'yes' if r['meets_target'] else 'no'} |")
        lines.append("")
    if stream:
        target = stream[0]["target_fps"]
        lines += [f"| `lfstream stream` of | frames/s, each run | CPU ms a frame | ≥ {target:g} every run |",
                  "|---|---|---|---|"]
        for r in stream:
            lines.append(f"| {r['lf']} | {', '.join(f'{f:.2f}' for f in r['fps_runs'])} | "
                         f"{r['process_cpu_ms_per_frame']:.0f} | {'yes' if r['meets_target'] else 'no'} |")
        lines.append("")
    lines.append(f"`bench/throughput.py --fast-end` on {machine(doc)}; the ratios hold for this CPU.")
    return "\n".join(lines) + "\n"


def fast_end_tables() -> str:
    """Every ``docs/results/fast_end*.json`` (one a CPU measured), each under its machine."""
    return "\n".join(fast_end_table(json.loads(path.read_text())) for path in sorted(RESULTS.glob("fast_end*.json")))


def zoo_table(manifest: dict | None = None) -> str:
    """The model zoo from the weights manifest: name, preset, parameters, SHA-256 and the
    reference metrics it records."""
    manifest = manifest if manifest is not None else json.loads(MANIFEST.read_text())
    lines = ["| network | preset | parameters | SHA-256 | reference |", "|---|---|---|---|---|"]
    for m in manifest["models"]:
        ref = m.get("reference_metrics", {})
        bits = []
        gains = ref.get("default_encode_lf_mpsnr_gain_db")
        if gains:
            bits.append("held-out LF gain " + ", ".join(f"{k} {v:+.2f} dB" for k, v in gains.items()))
        dec = ref.get("decoded_mpsnr_db")
        if dec:
            held = {k: v for k, v in dec.items() if "train" not in k}
            bits.append("held-out hint→net " + ", ".join(
                f"{k} {v['net_1/4'] - v['hint_1/4']:+.3f} dB" for k, v in held.items() if "net_1/4" in v))
        loo = ref.get("loo_mpsnr_gain_db_vs_flat")
        if loo:
            bits.append("held-out (leave-one-out) vs flat " + ", ".join(f"{k} {v:+.2f} dB" for k, v in loo.items()))
        seen = ref.get("trained_on_mpsnr_gain_db_vs_flat")
        if seen:
            bits.append("trained-on scenes vs flat " + ", ".join(f"{k} {v:+.2f} dB" for k, v in seen.items()))
        sas = ref.get("synthetic_psnr_vs_sas_db_heldout6")
        if sas:
            bits.append(f"vs shift-and-sum {min(sas):.1f}–{max(sas):.1f} dB PSNR (held-out synthetic)")
        ms = [f"{k.split('_')[-1]} {v:.0f} ms" for k, v in ref.items() if k.startswith("cpu_ms_375x540_")]
        if ms:
            bits.append("CPU a 375×540 view: " + ", ".join(ms))
        lines.append(f"| {m['name']} | {m['preset']} | {m['params']:,} | `{m['sha256'][:16]}…` | {'; '.join(bits) or '—'} |")
    return "\n".join(lines) + "\n"


def subcommands(parser: argparse.ArgumentParser, prefix: str = "") -> list[tuple[str, argparse.ArgumentParser]]:
    """``(name, parser)`` of every subcommand, nested ones (``golden record``) included."""
    out = []
    for act in parser._actions:
        if isinstance(act, argparse._SubParsersAction):
            for name, p in act.choices.items():
                out.append((f"{prefix}{name}", p))
                out += subcommands(p, f"{prefix}{name} ")
    return out


def cli_reference() -> str:
    """Markdown for every subcommand, taken from the parsers themselves."""
    sys.path.insert(0, str(ROOT))
    from lfstream.cli import build_parser

    parser = build_parser()
    out = ["```text", parser.format_help().rstrip(), "```", ""]
    for name, p in subcommands(parser):
        out += [f"{'###' if ' ' in name else '##'} `lfstream {name}`", "", p.description or "", ""]
        out += ["| option | help | default |", "|---|---|---|"]
        for act in p._actions:
            if isinstance(act, argparse._HelpAction):
                continue
            flags = ", ".join(f"`{s}`" for s in act.option_strings) or f"`{act.metavar or act.dest}`"
            if act.choices and not isinstance(act.choices, dict):
                flags += " {" + ",".join(str(c) for c in act.choices) + "}"
            default = "" if act.default in (None, argparse.SUPPRESS, False) or act.option_strings == [] else f"`{act.default}`"
            text = p._get_formatter()._expand_help(act) if act.help else ""
            text = text.replace("|", "\\|").replace("\n", " ")
            out.append(f"| {flags} | {text} | {default} |")
        out += ["", "```text", p.format_usage().strip(), "```", ""]
    return "\n".join(out)


def bench_sections() -> str:
    """Every bench document in ``docs/results`` other than the codec's: its script, machine
    and results."""
    out = []
    for path in sorted(RESULTS.glob("*.json")):
        # these have tables of their own
        if path.stem in ("codec", "rate", "rd", "centre_depth_loo", "networks_seed") or path.stem.startswith("fast_end"):
            continue
        doc = json.loads(path.read_text())
        out += [f"### `bench/{path.stem}.py`", "", f"Measured on {machine(doc)}.", "", generic_table(doc)]
    return "\n".join(out) + "\n"


def readme_blocks() -> dict[str, str]:
    """The README's generated blocks by name."""
    return {"results": results_table(load("codec")), "zoo": zoo_table()}


@functools.lru_cache(maxsize=1)
def docs_blocks() -> dict[str, str]:
    """The docs pages' generated blocks by name (made once a build)."""
    codec = load("codec")
    return {"results": results_table(codec), "speed": speed_table(codec), "zoo": zoo_table(), "rate": rate_table(load("rate")),
            "bd": bd_table(load("rd")) if (RESULTS / "rd.json").exists() else "",
            "cli": cli_reference(), "bench": bench_sections(), "machine": f"Measured on {machine(codec)}.\n",
            "loo": loo_table(load("centre_depth_loo")) if (RESULTS / "centre_depth_loo.json").exists() else "",
            "seed": seed_table(load("networks_seed")) if (RESULTS / "networks_seed.json").exists() else "",
            "fast-end": fast_end_tables()}


def render(text: str, made: dict[str, str]) -> str:
    """``text`` with every ``<!-- generated:NAME -->`` block replaced by ``made[NAME]``."""

    def sub(m: re.Match) -> str:
        name = m.group("name")
        if name not in made:
            raise KeyError(f"unknown generated block {name!r}")
        return m.group(1) + made[name] + m.group(4)

    return _BLOCK.sub(sub, text)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="exit 1 if the README's generated blocks are stale")
    args = p.parse_args(argv)
    text = README.read_text()
    new = render(text, readme_blocks())
    if args.check:
        if new != text:
            print("README.md: generated blocks are stale; run python tools/docgen.py", file=sys.stderr)
            return 1
        return 0
    if new != text:
        README.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
