"""The README and the docs: their size and order, generated tables that match their JSON,
links that resolve, help on every CLI option, the install's pins, and a project that
speaks of itself rather than of its development."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import pytest

from lfstream.cli import build_parser
from tests.conftest import ROOT

sys.path.insert(0, str(ROOT / "tools"))
import docgen  # noqa: E402 - tools/ is not a package

README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
#: Phrases of development chronology: session ordinals, references to the tracker's issues.
CHRONOLOGY = re.compile(
    r"\b(?:first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|[a-z]+teenth|"
    r"twentieth|thirtieth|fortieth|(?:twenty|thirty|forty)-[a-z]+|this|that|previous|earlier|later|last|next)"
    r"[ -]sessions?\b|\bsessions? \d+|\bissues?\b(?! (?:a|an|the) )|\bdev box\b", re.I)
#: Development machines' CPU names, which belong in measurement data (bench JSON, the
#: manifest, generated tables) and nowhere else.
MACHINE = re.compile(r"\b(?:Zen ?\d|EPYC|Xeon|znver\d)\b")
_GENERATED = re.compile(r"<!-- generated:[a-z-]+ -->.*?<!-- /generated -->", re.S)


def _project_text_files() -> list[Path]:
    files = [README, ROOT / "CONTRIBUTING.md", ROOT / "pyproject.toml", ROOT / "Makefile", *DOCS,
             *(ROOT / "docs").glob("*.py"), *(ROOT / "docs" / "_ext").glob("*.py"), *(ROOT / ".ci").glob("*")]
    for top in ("lfstream", "bench", "tools", "tests"):
        files += [p for p in (ROOT / top).rglob("*") if p.suffix in (".py", ".md", ".sh", ".json", ".txt")
                  and "__pycache__" not in p.parts]
    return [p for p in files if p.is_file() and p.name != "test_docs.py"]


def test_no_development_chronology_anywhere():
    hits = []
    for path in _project_text_files():
        text = path.read_text(errors="replace")
        for m in CHRONOLOGY.finditer(text):
            hits.append(f"{path.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0)!r}")
        if path.suffix != ".json":
            for m in MACHINE.finditer(_GENERATED.sub("", text)):
                hits.append(f"{path.relative_to(ROOT)}: machine name {m.group(0)!r} outside measurement data")
    assert not hits, "\n".join(hits[:40])


def test_the_chronology_scan_catches_what_it_is_for():
    for phrase in ("measured in the thirty-fifth session", "as issue #15 says", "the issue's target",
                   "(earlier session)", "on the 2-core dev box", "the fast-hint issue"):
        assert CHRONOLOGY.search(phrase), phrase
    assert MACHINE.search("2-core Zen 5") and MACHINE.search("Intel Xeon")
    for fine in ("a test session of pytest", "the session's ... ", "it may issue a warning"):
        assert not CHRONOLOGY.search(fine), fine


def test_readme_is_a_product_page():
    lines = README.read_text().splitlines()
    assert len(lines) <= 350, len(lines)
    first_table = next(i for i, line in enumerate(lines) if line.startswith("| scene"))
    assert first_table < 150, first_table
    commands = next(i for i, line in enumerate(lines) if line.startswith("make demo"))
    assert commands < 40 and lines[commands + 1].startswith("make test")
    assert max(len(line) for line in lines if not line.startswith("|")) <= 200


def test_readme_generated_blocks_match_their_json():
    text = README.read_text()
    assert "<!-- generated:results -->" in text and "<!-- generated:zoo -->" in text
    assert docgen.render(text, docgen.readme_blocks()) == text, "run python tools/docgen.py"


def test_results_table_is_made_from_the_json():
    doc = docgen.load("codec")
    table = docgen.results_table(doc)
    ours = next(r for r in doc["results"] if r["method"].startswith("lfstream q50 (default"))
    assert f"{ours['mpsnr']:.2f} / {ours['mssim']:.4f}" in table
    assert doc["metadata"]["device"]["cpu"] in table  # the CPU is named
    # every operating point carries its three anchors
    assert all(len(anchors) == len(docgen.ANCHORS) for *_, anchors in docgen._points(doc))


def test_fast_end_table_is_made_from_the_json():
    """Every scene's decode ratio and every stream run's frames/s appear, each judged
    against its target, under the CPU that measured them."""
    doc = docgen.load("fast_end")
    table = docgen.fast_end_table(doc)
    assert doc["metadata"]["device"]["cpu"] in table
    for r in doc["results"]:
        if "ratio_best" in r:
            assert f"| {r['lf']} |" in table and f"{r['ratio_best']:.2f}×" in table
            assert (r["ratio_best"] >= r["target_ratio"]) == r["meets_target"]
        else:
            assert ", ".join(f"{f:.2f}" for f in r["fps_runs"]) in table
            assert (min(r["fps_runs"]) >= r["target_fps"]) == r["meets_target"]
    assert table in docgen.fast_end_tables()


def test_zoo_table_lists_every_shipped_network_with_its_hash():
    import json

    manifest = json.loads(docgen.MANIFEST.read_text())
    table = docgen.zoo_table(manifest)
    for m in manifest["models"]:
        assert m["sha256"][:16] in table and f"{m['params']:,}" in table


@pytest.mark.parametrize("page", [README, *DOCS], ids=lambda p: p.name)
def test_relative_links_resolve(page):
    text = _GENERATED.sub("", page.read_text())
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    missing = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        if not (page.parent / target.split("#")[0]).exists():
            missing.append(target)
    assert not missing, missing


def test_cli_reference_is_generated_from_the_parsers():
    ref = docgen.cli_reference()
    names = [name for name, _ in docgen.subcommands(build_parser())]
    assert "golden record" in names and "compare" in names
    for name, parser in docgen.subcommands(build_parser()):
        assert f"## `lfstream {name}`" in ref
        for action in parser._actions:
            for flag in (f for f in action.option_strings if f not in ("-h", "--help")):
                assert f"`{flag}`" in ref, (name, flag)


def test_every_cli_option_has_help():
    missing = [(name, a.option_strings or a.dest) for name, p in docgen.subcommands(build_parser()) for a in p._actions
               if not a.help and not isinstance(a, argparse._HelpAction)]
    assert not missing, missing


def test_install_pins_torch_for_this_machine_only():
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert re.search(r'"torch>=\d+\.\d+"', pyproject) and "torch==" not in pyproject
    assert "torch==2.13.0" in (ROOT / "constraints.txt").read_text()
    make = (ROOT / "Makefile").read_text()
    demo = re.search(r"^demo: (.*)$", make, re.M).group(1)
    runtime_rule = re.search(r"^\$\(RUNTIME\):.*\n((?:\t.*\n)+)", make, re.M).group(1)
    assert demo.strip() == "$(RUNTIME)" and "[" not in runtime_rule  # no extras for the demo
    assert "-c constraints.txt" in make


def test_the_public_array_functions_have_google_docstrings():
    """The Python API's functions that take arrays document Args, Returns and Shape."""
    import inspect

    import lfstream
    import lfstream.codec as codec
    import lfstream.metrics as metrics
    import lfstream.refocus as refocus
    import lfstream.testing as testing

    functions = [lfstream.read_lf, lfstream.write_lf, codec.encode, codec.decode, codec.iter_decode,
                 refocus.focal_stack, refocus.all_in_focus, refocus.shift_and_sum, metrics.psnr, metrics.ssim,
                 metrics.mpsnr, metrics.mssim, testing.frame_metrics, testing.assert_lf_close]
    missing = [f"{f.__module__}.{f.__name__}: {section}" for f in functions for section in ("Args:", "Shape:")
               if section not in (inspect.getdoc(f) or "")]
    missing += [f"{f.__module__}.{f.__name__}: Returns:" for f in functions
                if f is not testing.assert_lf_close and "Returns:" not in (inspect.getdoc(f) or "")]
    assert not missing, missing
