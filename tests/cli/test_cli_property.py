"""A property of the whole command line: whatever the arguments — numbers out of range, NaN,
negative values, paths that are missing, empty, too long, unwritable or the input itself,
sizes beyond memory — a command exits 0, 1 or 2 (one line on stderr), never with a
traceback, never changing an input, and in bounded memory."""

from __future__ import annotations

import hashlib
import resource

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lfstream.cli import main

#: Peak memory the process may reach over the whole property run (the inputs are tiny; a
#: request beyond memory must be refused before it allocates).
MAX_RSS_MB = 3000

NUMBERS = st.sampled_from(["0", "-1", "1", "2", "50", "-0.5", "nan", "inf", "-inf", "1e9", "1e-9", "100000", "abc",
                           "3x3", "-1,0,1", ""])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    import lfstream
    from lfstream.synth import synth_clip

    folder = tmp_path_factory.mktemp("prop")
    lf = synth_clip(2, 3, (16, 20), seed=1).lf
    np.save(folder / "in.npy", lf)
    (folder / "in.lfs").write_bytes(lfstream.encode(lf))
    (folder / "text.txt").write_text("not a light field")
    return folder


def _paths(folder):
    return st.sampled_from([
        str(folder / "in.npy"), str(folder / "in.lfs"), str(folder / "text.txt"), str(folder / "missing.npy"), "",
        str(folder), "/proc/x.npy", str(folder / ("n" * 300 + ".npy")), str(folder / "out" / "deep" / "x.npy"),
    ])


def _outputs(folder, n):
    return st.sampled_from([
        str(folder / f"o{n}.npy"), str(folder / f"o{n}.lfs"), str(folder / f"o{n}.avi"), str(folder / f"o{n}"),
        str(folder / f"o{n}.txt"), str(folder / "in.npy"), str(folder / "in.lfs"), "", "/proc/o.npy",
        str(folder / f"o{n}.html"), str(folder / f"o{n}.json"),
    ])


def _argv(folder):
    p = _paths(folder)
    flags = {
        "info": st.tuples(st.just("info"), p),
        "encode": st.tuples(st.just("encode"), p, st.just("-o"), _outputs(folder, "e"),
                            st.sampled_from(["--quality", "--bpp"]), NUMBERS),
        "decode": st.tuples(st.just("decode"), p, st.just("-o"), _outputs(folder, "d"),
                            st.sampled_from(["--max-frames", "--first-frame", "--batch"]), NUMBERS),
        "refocus": st.tuples(st.just("refocus"), p, st.just("-o"), _outputs(folder, "r"),
                             st.sampled_from(["--slopes", "--alphas", "--aperture"]), NUMBERS, st.just("--no-viewer")),
        "refocus-range": st.tuples(st.just("refocus"), p, st.just("-o"), _outputs(folder, "rr"),
                                   st.just("--slope-range"), NUMBERS, NUMBERS, NUMBERS, st.just("--no-viewer")),
        "convert": st.tuples(st.just("convert"), p, st.just("-o"), _outputs(folder, "c"),
                             st.sampled_from(["--fps", "--max-frames"]), NUMBERS),
        "synth": st.tuples(st.just("synth"), st.just("-o"), _outputs(folder, "s"), st.just("--size"),
                           st.sampled_from(["16x16", "0x0", "16384x16384", "-4x4", "nan"]),
                           st.sampled_from(["--grid", "--frames"]), st.sampled_from(["3", "64", "0", "-1", "100001"])),
        "compare": st.tuples(st.just("compare"), p, p, st.sampled_from(["--min-psnr", "--max-abs", "--min-ssim"]),
                             NUMBERS),
        "golden": st.tuples(st.just("golden"), st.just("record"), p, st.just("-o"), _outputs(folder, "g")),
        "optics": st.tuples(st.just("optics"), st.just("--focal-length"), NUMBERS, st.just("--f-number"), NUMBERS,
                            st.just("--microlenses"), NUMBERS, st.just("--pixels-per-lens"), NUMBERS),
        "view": st.tuples(st.just("view"), p, st.just("--fps"), NUMBERS),
    }
    return st.one_of(*flags.values())


def _digest(folder) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()
            if p.name in ("in.npy", "in.lfs", "text.txt")}


def test_every_argument_vector_ends_in_0_1_or_2_without_a_traceback(files, capsys):
    before = _digest(files)

    @settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(argv=_argv(files))
    def check(argv):
        try:
            code = main(list(argv))
        except SystemExit as exc:  # the parser's usage errors
            code = exc.code
        err = capsys.readouterr().err
        assert code in (0, 1, 2), (argv, code, err)
        if code == 2:
            assert len(err.strip().splitlines()) <= 1 and "Traceback" not in err, (argv, err)
        assert _digest(files) == before, argv  # no input changed
        assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 < MAX_RSS_MB, argv

    check()
