"""``lfstream batch``: encode or decode a collection of LF videos, here or on Ray."""

from __future__ import annotations

import argparse
import sys

from lfstream.cli._common import add_read_options, emit, int_in, path_arg, read_options
from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.decoder import DEPTH_MODES, HANCE_MODES, NETWORK_PRESETS
from lfstream.codec.encoder import PRESETS

HELP = "encode or decode a collection of LF videos, in this process or on a Ray cluster"
#: Engines and modes of lfstream.cluster.run (kept here so --help imports nothing heavy).
ENGINES = ("local", "ray")
MODES = ("encode", "decode")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("inputs", type=path_arg, nargs="+", help="LF videos / light fields (encode) or .lfs streams (decode)")
    p.add_argument("-o", "--output", type=path_arg, required=True, help="output folder (files in it are never overwritten "
                   "without --overwrite)")
    p.add_argument("--mode", choices=MODES, default="encode", help="encode inputs to .lfs, or decode .lfs streams")
    p.add_argument("--engine", choices=ENGINES, default="local",
                   help="local: this process; ray: Ray tasks (pip install 'lfstream[ray]')")
    p.add_argument("--address", help="a running Ray cluster (default: a local one for this command)")
    p.add_argument("--workers", type=int_in((1, 4096)), help="CPUs of the local Ray cluster (default: all)")
    p.add_argument("--group", type=int_in((1, 1 << 20)), default=8, help="frames per job (default 8)")
    p.add_argument("--quality", type=int_in(QUALITY_RANGE), default=50, help="encode: JPEG quality of the centre view")
    p.add_argument("--no-depth-hint", action="store_true", help="encode: send only the centre view")
    p.add_argument("--preset", choices=tuple(PRESETS),
                   help="encode: centre-view coding, fast (JPEG), balanced or best (AV1); default: as lfstream "
                   "encode chooses for each input (fast from 7x7 views, AV1 with fewer, the views themselves "
                   "where warping cannot predict them)")
    p.add_argument("--hance-map", action="store_true",
                   help="encode: send JPEG-Hance strength maps with JPEG centre views (as lfstream encode "
                   "--hance-map; measured on each group's first frame)")
    p.add_argument("--depth", choices=DEPTH_MODES, default="auto", help="decode: disparity source")
    p.add_argument("--hance", choices=HANCE_MODES, default="auto", help="decode: JPEG-Hance")
    p.add_argument("--networks", choices=NETWORK_PRESETS, default="fast",
                   help="decode: the networks' shipped weights (fast, or JPEG-Hance paper)")
    p.add_argument("--device", default="cpu", help="decode: where the networks run")
    p.add_argument("--format", default=".npy", help="decode: output extension (.npy, .npz, .avi, .mp4, .mkv or '' / folder "
                   "for folders of views)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")


def _text(r: dict) -> str:
    lines = [f"{r['mode']} on {r['engine']} ({r['workers']} worker(s)): {r['frames']} frame(s), {r['bytes']} bytes, "
             f"{r['wall_s']} s, {r['fps']} frames/s"]
    for f in r["files"]:
        lines.append(f"  {f['status']:6s} {f['input']} -> {f['output']}" + (f"  ({f['error']})" if f["error"] else ""))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from lfstream.cluster import DecodeOptions, EncodeOptions, batch
    from lfstream.io.outputs import FOLDER, OutputFolder, check_output

    # the folder collects many runs' files by design, but one run at a time
    check_output(args.output, args.inputs, overwrite=True, kinds=(FOLDER,))
    with OutputFolder(args.output, overwrite=True):
        report = batch(args.inputs, args.output, mode=args.mode, engine=args.engine, address=args.address,
                       workers=args.workers, group_frames=args.group,
                       encode=EncodeOptions(quality=args.quality, depth_hint=not args.no_depth_hint,
                                            preset=args.preset, hance_map=args.hance_map),
                       decode=DecodeOptions(depth=args.depth, hance=args.hance, device=args.device,
                                            networks=args.networks),
                       read=read_options(args), output_format=args.format, overwrite=args.overwrite)
    emit(args, report.as_dict(), _text)
    if not report.ok:
        failed = [f for f in report.files if f.status != "ok"]
        print(f"lfstream batch: error: {len(failed)} of {len(report.files)} input(s) failed: "
              + "; ".join(f.error or f.input for f in failed), file=sys.stderr)
        return 2
    return 0
