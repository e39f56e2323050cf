"""The shared file-system helpers: atomic writes and fresh output folders."""

import pytest

from lfstream.errors import LFFileError
from lfstream.io._fs import atomic_open, atomic_write_bytes, check_new_file, fresh_dir, prepare_output_dir, temp_sibling


def test_atomic_write_replaces_only_when_complete(tmp_path):
    target = tmp_path / "out.bin"
    atomic_write_bytes(target, b"first")
    assert target.read_bytes() == b"first"
    with pytest.raises(RuntimeError):
        with atomic_open(target) as fh:
            fh.write(b"half of the second")
            raise RuntimeError("interrupted")
    assert target.read_bytes() == b"first"  # the good file survives a failed write
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"]  # and no temporary is left


def test_temp_sibling_keeps_the_extension_last(tmp_path):
    tmp = temp_sibling(tmp_path / "clip.mp4")
    assert tmp.parent == tmp_path and tmp.suffix == ".mp4" and tmp.name.startswith(".clip.")


def test_unwritable_target_is_an_lffileerror(tmp_path):
    with pytest.raises(LFFileError, match="missing"):
        atomic_write_bytes(tmp_path / "missing" / "x.bin", b"x")


def test_fresh_dir_never_returns_a_folder_with_results(tmp_path):
    base = tmp_path / "out"
    assert fresh_dir(base) == base
    base.mkdir()
    assert fresh_dir(base) == base  # empty: usable
    (base / "summary.json").write_text("{}")
    assert fresh_dir(base) == tmp_path / "out-2"
    (tmp_path / "out-2").mkdir()
    (tmp_path / "out-2" / "x").write_text("")
    assert fresh_dir(base) == tmp_path / "out-3"


def test_prepare_output_dir_and_check_new_file_refuse_existing_results(tmp_path):
    out = prepare_output_dir(tmp_path / "a" / "b")
    assert out.is_dir()
    (out / "x").write_text("")
    with pytest.raises(LFFileError, match="not an empty folder"):
        prepare_output_dir(out)
    assert prepare_output_dir(out, overwrite=True) == out
    with pytest.raises(LFFileError, match="already exists"):
        check_new_file(out / "x")
    assert check_new_file(out / "x", overwrite=True) == out / "x"
