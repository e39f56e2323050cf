"""Every command line the README and the docs pages show as an example runs as printed:
each is parsed by the real parser (running them all would take minutes), and the inputs it
names exist."""

import re
import shlex
from pathlib import Path

import pytest

from lfstream.cli import build_parser
from tests.conftest import ROOT

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _examples() -> list[str]:
    lines = []
    text = "\n".join(page.read_text() for page in PAGES)
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.split("  #")[0].strip()
            if line.startswith("lfstream "):
                lines.append(line)
    return lines


EXAMPLES = _examples()


def test_readme_has_examples_for_every_command():
    named = {shlex.split(line)[1] for line in EXAMPLES}
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert set(sub.choices) - named <= {"serve"}, set(sub.choices) - named  # serve waits for a sender


@pytest.mark.parametrize("line", EXAMPLES)
def test_readme_example_parses(line, capsys):
    argv = shlex.split(line)[1:]
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # pragma: no cover - the failure message says which line
        pytest.fail(f"documented example does not parse: {line}\n{capsys.readouterr().err}")
        raise exc
    for value in vars(args).values():
        if isinstance(value, Path) and str(value).startswith("../shared"):
            if not (ROOT / value).exists():
                pytest.skip(f"sample {value} not present here")
