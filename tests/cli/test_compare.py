"""``lfstream compare`` and ``lfstream golden``: exit statuses 0 / 1 / 2, the JSON schema,
and that the inputs are left as they were."""

import hashlib
import json

import numpy as np
import pytest

from lfstream.cli import main

FRAME_KEYS = {"frame", "mpsnr", "mssim", "worst_view", "worst_view_psnr", "worst_view_ssim", "max_abs", "identical",
              "passed", "failures"}


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def clips(tmp_path):
    rng = np.random.default_rng(5)
    ref = rng.integers(0, 256, size=(5, 3, 3, 20, 24, 3), dtype=np.uint8)
    test = ref.copy()
    test[3] = np.clip(ref[3].astype(int) + rng.integers(-30, 31, ref[3].shape), 0, 255).astype(np.uint8)
    np.save(tmp_path / "ref.npy", ref)
    np.save(tmp_path / "test.npy", test)
    return tmp_path / "ref.npy", tmp_path / "test.npy"


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_compare_exits_1_naming_exactly_the_degraded_frame(capsys, clips, tmp_path):
    ref, test = clips
    before = _digest(ref), _digest(test)
    code, out, err = run(capsys, "compare", ref, test, "--min-psnr", 40, "--json")
    assert code == 1 and err == ""
    doc = json.loads(out)
    assert doc["passed"] is False and doc["failed_frames"] == [3]
    assert [f["frame"] for f in doc["frames"]] == [0, 1, 2, 3, 4]
    assert all(set(f) == FRAME_KEYS for f in doc["frames"])
    assert doc["frames"][3]["worst_view_psnr"] < 40 and doc["frames"][0]["identical"]
    assert (_digest(ref), _digest(test)) == before


def test_compare_identical_exits_0_every_frame_identical(capsys, clips):
    ref, _ = clips
    code, out, _ = run(capsys, "compare", ref, ref, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["passed"] and all(f["identical"] for f in doc["frames"])
    code, out, _ = run(capsys, "compare", ref, ref)
    assert code == 0 and "5 frames compared, 0 failed" in out


def test_compare_frame_range_and_schema_stable(capsys, clips):
    ref, test = clips
    code, out, _ = run(capsys, "compare", ref, test, "--max-abs", 0, "--first-frame", 1, "--max-frames", 2, "--json")
    doc = json.loads(out)
    assert code == 0 and [f["frame"] for f in doc["frames"]] == [1, 2]
    code, out2, _ = run(capsys, "compare", ref, ref, "--json")
    assert set(json.loads(out2)) == set(doc)


@pytest.mark.parametrize("case", ["shape", "missing", "garbage"])
def test_compare_bad_input_exits_2_in_one_line(capsys, clips, tmp_path, case):
    ref, _ = clips
    if case == "shape":
        np.save(tmp_path / "other.npy", np.zeros((5, 3, 3, 20, 20, 3), np.uint8))
        other = tmp_path / "other.npy"
    elif case == "missing":
        other = tmp_path / "nope.npy"
    else:
        other = tmp_path / "garbage.npy"
        other.write_bytes(b"not an array")
    code, out, err = run(capsys, "compare", ref, other)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert str(other.name) in err


def test_compare_html_report_and_its_output_rules(capsys, clips, tmp_path):
    ref, test = clips
    code, out, _ = run(capsys, "compare", ref, test, "--min-psnr", 40, "--html", tmp_path / "r.html", "--json")
    assert code == 1 and json.loads(out)["html"].endswith("r.html") and (tmp_path / "r.html").stat().st_size > 0
    code, _, err = run(capsys, "compare", ref, test, "--html", tmp_path / "r.html")  # exists: refused first
    assert code == 2 and "already exists" in err
    code, _, err = run(capsys, "compare", ref, test, "--html", ref.with_suffix(".txt"))
    assert code == 2 and ".html" in err


def test_golden_record_then_check(capsys, clips, tmp_path):
    ref, test = clips
    g = tmp_path / "g.json"
    code, out, _ = run(capsys, "golden", "record", test, "-o", g, "--reference", ref, "--json")
    assert code == 0 and json.loads(out)["frames"] == 5
    code, out, _ = run(capsys, "golden", "check", test, g, "--json")  # the golden's own reference
    doc = json.loads(out)
    assert code == 0 and doc["identical"] == [0, 1, 2, 3, 4]
    changed = np.load(test)
    changed[3, 0, 0, 0, 0, 0] ^= 1  # one sample of the lossy frame: within tolerance
    changed[4] = 0
    np.save(tmp_path / "now.npy", changed)
    code, out, _ = run(capsys, "golden", "check", tmp_path / "now.npy", g, "--json")
    doc = json.loads(out)
    assert code == 1 and doc["changed"] == [3] and doc["regressed"] == [4] and doc["failed_frames"] == [4]
    code, _, err = run(capsys, "golden", "record", test, "-o", g)  # never overwritten unasked
    assert code == 2 and "already exists" in err
    code, _, err = run(capsys, "golden", "check", test, ref)  # not a golden file
    assert code == 2 and "not a golden file" in err
