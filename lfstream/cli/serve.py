"""``lfstream serve``: receive a stream over TCP, decode, refocus and write the outputs."""

from __future__ import annotations

import argparse
import sys

from lfstream.cli import _pipeline
from lfstream.cli._common import float_in, int_in

HELP = "receive a stream over TCP, decode, refocus and write the outputs"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default loopback only)")
    p.add_argument("--port", type=int_in((0, 65535)), default=7820, help="TCP port (0: any free port)")
    p.add_argument("--keep-open", action="store_true", help="serve one sender after another until Ctrl-C")
    p.add_argument("--timeout", type=float_in(0.1, 86400), default=300.0,
                   help="seconds to wait for a sender or for data")
    _pipeline.add_pipeline_options(p)


def run(args: argparse.Namespace) -> int:
    from lfstream.io.outputs import fresh_output_folder
    from lfstream.stream import Pipeline
    from lfstream.stream.report import stopped_summary
    from lfstream.stream.transport import TcpReceiver

    _pipeline.check_output_folder(args.output)
    cfg = _pipeline.pipeline_config(args)
    while True:
        # each sender's outputs in a folder of their own, never one that holds results
        claim = fresh_output_folder(args.output or "lfstream-serve")
        out = claim.path
        receiver = None
        try:
            try:
                receiver = TcpReceiver(args.host, args.port, timeout_s=args.timeout)
                # on stderr whatever --json says: a script needs the port (--port 0) before it sends
                print(f"listening on {receiver.address[0]}:{receiver.address[1]} -> {out}", file=sys.stderr,
                      flush=True)
                with _pipeline.single_threaded_opencv(), _pipeline.frozen_garbage_collector() as on_warm:
                    summary = Pipeline(None, cfg, out, receiver=receiver, progress=_pipeline.progress_callback(args),
                                       on_warm=on_warm).run()
            except KeyboardInterrupt:  # at any moment after the folder is claimed: a labelled summary
                summary = stopped_summary("tcp")
                if receiver is not None:
                    receiver.close()
            summary["address"] = None if receiver is None else [receiver.address[0], receiver.address[1]]
            _pipeline.write_page(args, summary, out)
            _pipeline.report(args, summary, out)
        finally:
            claim.release()
        if not args.keep_open or summary["interrupted"]:
            return 130 if summary["interrupted"] else 0
