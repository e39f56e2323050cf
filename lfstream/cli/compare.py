"""``lfstream compare REFERENCE TEST``: two light fields or LF videos, frame by frame.

Exit status 0 when every frame passes, 1 when any frame does not, 2 on bad input.
"""

from __future__ import annotations

import argparse

from lfstream.cli._common import add_read_options, float_in, path_arg

HELP = "compare two light fields or LF videos frame by frame: MPSNR, MSSIM, worst view, largest difference"


def add_thresholds(p: argparse.ArgumentParser) -> None:
    """The thresholds ``compare`` and ``golden check`` share (:class:`lfstream.testing.Thresholds`)."""
    from lfstream.testing.compare import SCOPES

    g = p.add_argument_group("thresholds (none given: frames must be identical)")
    g.add_argument("--min-psnr", type=float_in(-1000, 1000), metavar="DB", help="least PSNR in dB")
    g.add_argument("--min-ssim", type=float_in(-1, 1), metavar="S", help="least SSIM")
    g.add_argument("--max-abs", type=float_in(0, 65535), metavar="L",
                   help="largest absolute difference of any sample, in 8-bit levels")
    g.add_argument("--scope", choices=SCOPES, default="view",
                   help="view: every view must meet --min-psnr/--min-ssim (the worst decides); "
                        "frame: the frame's MPSNR/MSSIM must (default: view)")


def thresholds(args: argparse.Namespace):
    from lfstream.testing import Thresholds

    return Thresholds(min_psnr=args.min_psnr, min_ssim=args.min_ssim, max_abs=args.max_abs, scope=args.scope)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("reference", type=path_arg, help="the expected light field or LF video (any format lfstream reads)")
    p.add_argument("test", type=path_arg, help="the one to judge, with the same view grid and size")
    add_thresholds(p)
    p.add_argument("--html", type=path_arg, metavar="OUT.html",
                   help="also write a self-contained report: metric curve, frame x view PSNR heat map, worst view")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --html report")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _table(report) -> str:
    lines = [f"{'frame':>6} {'MPSNR':>7} {'MSSIM':>7} {'worst view':>10} {'PSNR':>7} {'max|d|':>7}  verdict"]
    for r in report.frames:
        j = r.to_json()
        verdict = "identical" if j["identical"] else ("ok" if r.passed else "FAIL: " + "; ".join(r.failures))
        lines.append(f"{j['frame']:>6} {j['mpsnr']:>7.2f} {j['mssim']:>7.4f} {str(tuple(j['worst_view'])):>10} "
                     f"{j['worst_view_psnr']:>7.2f} {j['max_abs']:>7g}  {verdict}")
    failed = report.failed_frames
    lines.append(f"{len(report.frames)} frames compared, {len(failed)} failed"
                 + (f": {', '.join(map(str, failed[:30]))}{' ...' if len(failed) > 30 else ''}" if failed else ""))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from lfstream.cli._common import emit, read_options
    from lfstream.io.outputs import check_output
    from lfstream.testing import compare_report

    if args.html is not None:
        # before the work, not after it
        check_output(args.html, [args.reference, args.test], overwrite=args.overwrite, kinds=(".html", ".htm"),
                     what="--html")
    report = compare_report(args.reference, args.test, thresholds(args), read_options(args),
                            keep_worst=args.html is not None)
    if args.html is not None:
        from lfstream.testing.html import write_html

        write_html(report, args.html, args.overwrite)
    doc = report.to_json()
    doc["html"] = str(args.html) if args.html is not None else None
    emit(args, doc, lambda _: _table(report))
    return 0 if report.passed else 1
