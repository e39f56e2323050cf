"""``lfstream models``: the networks, presets, parameter counts and shipped weights."""

from __future__ import annotations

import argparse

from lfstream.cli._common import emit

HELP = "list the networks, their presets, parameter counts and shipped weights"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    from lfstream.models.registry import list_models

    models = list_models()
    emit(args, {"models": models}, "\n".join(
        f"{m['name']:11s} {m['preset']:6s} {m['params']:>11,d} params  weights: {m['weights'] or '-'}" for m in models))
    return 0
