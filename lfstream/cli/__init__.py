"""The ``lfstream`` command line: one module per subcommand, every one reachable as ``main(argv)``.

Library code raises :class:`~lfstream.errors.LFStreamError`; only this layer turns it into
one line on stderr and a non-zero exit status, and only this layer sets process-wide state
(torch threads).
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
from collections.abc import Sequence
from typing import NoReturn

from lfstream.cli._common import EXIT_INTERRUPTED, EXIT_TERMINATED, int_in, sigterm_as_ctrl_c
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


#: A value that starts with a minus sign: a negative number or a list of numbers (``-1,0,1``),
#: taken as a value after a space as it is after ``=`` (argparse alone knows single numbers).
_NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d)[\d.,eE+\-]*$")


#: Library messages name Python arguments beside the CLI flags (``overwrite=True /
#: --overwrite``); the CLI prints only its own words.
_PYTHON_AND_FLAG = re.compile(r"\b[a-z_]+=(?:True|False) / (--[a-z-]+)")
_PYTHON_ONLY = {"depth='hint'": "--depth hint", "encode with depth_hint=True": "encode without --no-depth-hint"}


def cli_words(message: str) -> str:
    """``message`` with its Python argument names replaced by the CLI's flags."""
    message = _PYTHON_AND_FLAG.sub(r"\1", message)
    for python, flag in _PYTHON_ONLY.items():
        message = message.replace(python, flag)
    return message


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line (the message and a pointer to ``--help``), exit status 2;
    negative numbers and number lists accepted after a space."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def _parse_optional(self, arg_string: str):
        if _NEGATIVE_VALUE.match(arg_string):
            return None
        return super()._parse_optional(arg_string)


def build_parser() -> argparse.ArgumentParser:
    from lfstream.version import __version__

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
    """Runs the CLI; returns the exit status (0 success, 1 a comparison failed, 2 error, 130
    interrupted by Ctrl-C, 143 by SIGTERM)."""
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
    with sigterm_as_ctrl_c() as terminated:
        try:
            code = int(args._run(args) or 0)
        except LFStreamError as exc:
            print(f"lfstream {args.command}: error: {cli_words(str(exc))}", file=sys.stderr)
            code = 2
        except KeyboardInterrupt:
            print(f"lfstream {args.command}: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
            code = EXIT_INTERRUPTED
        except BrokenPipeError:
            code = 0
        except OSError as exc:  # the file system refused a path the library did not name (a name too long, say)
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"lfstream {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
            code = 2
    return EXIT_TERMINATED if terminated and code == EXIT_INTERRUPTED else code


def entry() -> None:
    """Console-script entry point."""
    sys.exit(main())


__all__ = ["COMMANDS", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "build_parser", "main", "entry", "sigterm_as_ctrl_c"]
