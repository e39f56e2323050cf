"""The ``lfstream`` command line: one module per subcommand, every one reachable as ``main(argv)``.

Library code raises :class:`~lfstream.errors.LFStreamError`; only this layer turns it into
one line on stderr and a non-zero exit status, and only this layer sets process-wide state
(torch threads).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from lfstream.cli._common import int_in
from lfstream.errors import LFStreamError

#: The subcommands, in the order ``--help`` lists them: name -> module. Each module has
#: ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int`` and imports nothing heavy
#: at module level (torch and the numba kernels load when a command runs).
COMMANDS = {
    "info": "lfstream.cli.info",
    "stream": "lfstream.cli.stream",
    "serve": "lfstream.cli.serve",
    "encode": "lfstream.cli.encode",
    "decode": "lfstream.cli.decode",
    "baseline": "lfstream.cli.baseline",
    "batch": "lfstream.cli.batch",
    "convert": "lfstream.cli.convert",
    "refocus": "lfstream.cli.refocus",
    "synth": "lfstream.cli.synth",
    "optics": "lfstream.cli.optics",
    "models": "lfstream.cli.models",
    "demo": "lfstream.cli.demo",
    "view": "lfstream.cli.view",
    "compare": "lfstream.cli.compare",
    "golden": "lfstream.cli.golden",
}


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line (the message and a pointer to ``--help``), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from lfstream import __version__

    parser = _Parser(
        prog="lfstream",
        description="Light-field video: read, simulate, compress, reconstruct and refocus.",
    )
    parser.add_argument("--version", action="version", version=f"lfstream {__version__}")
    parser.add_argument("--threads", type=int_in((1, 1024)), help="torch intra-op threads (default: torch's choice)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the CLI; returns the exit status (0 success, 2 error, 130 interrupted)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    # SVT-AV1 prints its configuration banner at info level; the CLI keeps stderr for errors
    os.environ.setdefault("SVT_LOG", "1")
    try:
        return int(args._run(args) or 0)
    except LFStreamError as exc:
        print(f"lfstream {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lfstream {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


def entry() -> None:
    """Console-script entry point."""
    sys.exit(main())


__all__ = ["COMMANDS", "build_parser", "main", "entry"]
