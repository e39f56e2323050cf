"""``lfstream golden record|check``: golden files of per-frame digests and metrics.

``record INPUT -o GOLDEN.json [--reference REF]`` pins every frame of INPUT; ``check INPUT
GOLDEN.json`` says which frames are identical, changed within tolerance, or regressed.
Exit status 0 when none regressed, 1 when any did, 2 on bad input.
"""

from __future__ import annotations

import argparse

from lfstream.cli._common import add_read_options, path_arg

HELP = "record golden files of an LF video's frames, or check a video against one"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from lfstream.cli.compare import add_thresholds

    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True, parser_class=type(p),
                           help="record: write a golden file; check: compare against one")
    rec = sub.add_parser("record", help="write a golden file of INPUT's frames",
                         description="write a golden file of INPUT's frames: each frame's SHA-256 and, with "
                                     "--reference, its MPSNR, MSSIM, worst view and largest difference against it")
    rec.add_argument("input", type=path_arg, help="the light field or LF video to pin (any format lfstream reads)")
    rec.add_argument("-o", "--output", type=path_arg, required=True, help="the golden file (.json)")
    rec.add_argument("--reference", type=path_arg, help="record metrics against this light field or video too")
    rec.add_argument("--overwrite", action="store_true", help="replace an existing golden file")
    add_read_options(rec)
    rec.add_argument("--json", action="store_true", help="print one JSON object")
    chk = sub.add_parser("check", help="check INPUT's frames against a golden file",
                         description="check INPUT's frames against a golden file: identical, changed within "
                                     "tolerance, or regressed")
    chk.add_argument("input", type=path_arg, help="the light field or LF video to check")
    chk.add_argument("golden", type=path_arg, help="the golden file")
    chk.add_argument("--reference", type=path_arg, help="the reference for the metrics (default: the golden's own)")
    chk.add_argument("--strict", action="store_true",
                     help="a metric better than its golden value by more than its tolerance also fails")
    add_thresholds(chk)
    add_read_options(chk)
    chk.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    return _record(args) if args.action == "record" else _check(args)


def _record(args: argparse.Namespace) -> int:
    from lfstream.cli._common import emit, read_options
    from lfstream.io.outputs import check_output
    from lfstream.testing import golden

    check_output(args.output, [args.input, args.reference], overwrite=args.overwrite, kinds=(".json",))
    opts = read_options(args)
    settings = {"command": "lfstream golden record", "reading": {k: v for k, v in vars(opts).items() if v}}
    g = golden.record(args.input, args.reference, opts, settings)
    g.write(args.output, args.overwrite)
    doc = {"golden": str(args.output), "input": str(args.input), "frames": len(g.frames),
           "reference": g.reference, "metrics": sorted({k for f in g.frames for k in f.metrics})}
    emit(args, doc, f"{args.output}: {len(g.frames)} frames recorded"
         + (f", metrics against {g.reference}" if g.reference else " (digests only)"))
    return 0


def _check(args: argparse.Namespace) -> int:
    from lfstream.cli._common import emit, read_options
    from lfstream.cli.compare import thresholds
    from lfstream.testing import golden

    g = golden.load_golden(args.golden)
    report = golden.check(args.input, g, args.reference, read_options(args), thresholds(args), args.strict)

    def text(_) -> str:
        lines = [f"frame {f.frame}: {f.status}" + (f" ({'; '.join(f.reasons)})" if f.reasons else "")
                 for f in report.frames if f.status != "identical"]
        counts = ", ".join(f"{len(report.frames_with(s))} {s}" for s in golden.STATUSES)
        return "\n".join([*lines, f"{len(report.frames)} frames checked: {counts}"])

    emit(args, report.to_json(), text)
    return 0 if report.passed else 1
