"""What no input may do: exhaust memory, destroy what the user gave, leave debris, or end
in a traceback; SIGTERM behaving as Ctrl-C; one CLI grammar; a receiver handshake.

The slow cases run the real command in a child process (signals, memory), the rest through
``main(argv)``.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from lfstream.cli import main
from tests.conftest import shared

LFSTREAM = [sys.executable, "-c", "import sys; from lfstream.cli import entry; sys.argv[0] = 'lfstream'; entry()"]


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


def _one_line(err: str) -> bool:
    return len(err.strip().splitlines()) == 1 and "Traceback" not in err


def _digest(path: Path) -> str:
    if path.is_dir():
        return hashlib.sha256(b"".join(p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file())).hexdigest()
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _debris(folder: Path) -> list[str]:
    """Temporary files and locks left anywhere below ``folder``."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if ".tmp" in p.name or p.name.startswith(".lfstream") or ".frames" in p.name)


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A 24-frame 7x7x128x160 LF video as .npy and as .lfs (long enough to stop part way)."""
    import lfstream
    from lfstream.synth import synth_clip

    folder = tmp_path_factory.mktemp("clip")
    lf = synth_clip(24, 7, (128, 160), seed=4, noise=1.0).lf
    np.save(folder / "clip.npy", lf)
    (folder / "clip.lfs").write_bytes(lfstream.encode(lf))
    return folder


def _start(argv, cwd, env=None):
    return subprocess.Popen([*LFSTREAM, *map(str, argv)], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, **(env or {})}, start_new_session=True)


def _wait_for(predicate, timeout=240.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.02)
    return False


# --- memory: sizes are checked before anything is allocated -----------------------------

def test_a_request_beyond_memory_is_refused_at_once_in_little_memory(tmp_path):
    t0 = time.perf_counter()
    proc = subprocess.run([*LFSTREAM, "synth", "-o", "big.npy", "--size", "16384x16384", "--grid", "64", "--frames", "1"],
                          cwd=tmp_path, capture_output=True, text=True)
    # the child's own peak memory (this process's children: only it ran since)
    assert proc.returncode == 2 and _one_line(proc.stderr) and "memory" in proc.stderr
    assert time.perf_counter() - t0 < 30  # interpreter start included; the check itself is instant
    assert not any(tmp_path.iterdir())


def test_plane_counts_are_capped_before_any_file(capsys, tmp_path, clip):
    code, _, err = run(capsys, "refocus", clip / "clip.npy", "-o", tmp_path / "rf", "--slope-range", -1, 1, 100000)
    assert code == 2 and _one_line(err) and "at most" in err and not (tmp_path / "rf").exists()


# --- SIGTERM as Ctrl-C: exit 143, whole frames kept, nothing temporary left ---------------

@pytest.mark.slow
def test_sigterm_during_decode_keeps_the_frames_and_leaves_no_temporary_file(tmp_path, clip):
    proc = _start(["decode", clip / "clip.lfs", "-o", "out.npy"], tmp_path)
    assert _wait_for(lambda: any(".tmp" in p.name for p in tmp_path.iterdir()))  # frames being written
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=240)
    assert proc.returncode == 143, err
    frames = np.load(tmp_path / "out.npy")
    assert 1 <= len(frames) <= 24 and frames.shape[1:] == (7, 7, 128, 160, 3)
    assert _debris(tmp_path) == []


@pytest.mark.slow
def test_sigterm_during_encode_keeps_a_valid_stream_of_the_frames_done(tmp_path, clip):
    import lfstream

    proc = _start(["encode", clip / "clip.npy", "-o", "out.lfs"], tmp_path)
    assert _wait_for(lambda: any(".tmp" in p.name for p in tmp_path.iterdir()))
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=240)
    if proc.returncode == 0:  # finished before the signal arrived: nothing to judge
        pytest.skip("the encode finished first")
    assert proc.returncode == 143, err
    decoded = lfstream.decode((tmp_path / "out.lfs").read_bytes())
    assert 1 <= len(decoded) < 24 and _debris(tmp_path) == []


@pytest.mark.slow
def test_sigterm_during_stream_writes_the_summary_and_leaves_nothing_behind(tmp_path, clip):
    cache = tmp_path / "cache"
    proc = _start(["stream", clip / "clip.lfs", "-o", "st", "--refocus", "sas", "--mssim-every", 1], tmp_path,
                  {"LFSTREAM_CACHE": str(cache)})
    out = tmp_path / "st"
    # the frames are flowing once the sink has begun its outputs
    assert _wait_for(lambda: out.is_dir() and any(p.name != ".lfstream-lock" for p in out.iterdir()))
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=240)
    if proc.returncode == 0:
        pytest.skip("the stream finished first")
    assert proc.returncode == 143, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["frames"] < 24
    assert _debris(out) == [] and (not cache.exists() or _debris(cache) == [])


@pytest.mark.slow
def test_sigterm_during_a_builtin_clip_render_leaves_no_partial_cache(tmp_path):
    cache = tmp_path / "cache"
    proc = _start(["stream", "-o", "st", "--frames", "30"], tmp_path, {"LFSTREAM_CACHE": str(cache)})
    assert _wait_for(lambda: cache.exists() and any(".tmp" in p.name for p in cache.iterdir()))
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=240)
    assert proc.returncode == 143, err
    assert _debris(cache) == [] and (tmp_path / "st" / "summary.json").exists()


@pytest.mark.slow
def test_sigterm_of_serve_exits_143_with_its_summary(tmp_path):
    proc = _start(["serve", "-o", "rx", "--port", "0"], tmp_path)
    line = proc.stderr.readline()
    assert "listening on 127.0.0.1:" in line
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=240)
    assert proc.returncode == 143
    assert json.loads((tmp_path / "rx" / "summary.json").read_text())["interrupted"] is True
    assert _debris(tmp_path / "rx") == []


# --- nothing the user gave is destroyed ------------------------------------------------

@pytest.mark.parametrize("argv", [
    ["encode", "{npy}", "-o", "{npy}", "--overwrite"],
    ["decode", "{lfs}", "-o", "{lfs}", "--overwrite"],
    ["convert", "{npy}", "-o", "{npy}", "--overwrite"],
    ["refocus", "{npy}", "-o", "{dir}", "--overwrite"],
    ["stream", "{npy}", "-o", "{dir}", "--overwrite"],
    ["compare", "{npy}", "{npy}", "--html", "{npy}", "--overwrite"],
    ["golden", "record", "{npy}", "-o", "{npy}", "--overwrite"],
], ids=lambda a: a[0] if a[0] != "golden" else "golden-record")
def test_an_output_that_is_an_input_is_refused_and_the_input_kept(capsys, tmp_path, clip, argv):
    data = tmp_path / "data"
    data.mkdir()
    for name in ("clip.npy", "clip.lfs"):
        (data / name).write_bytes((clip / name).read_bytes())
    subs = {"{npy}": str(data / "clip.npy"), "{lfs}": str(data / "clip.lfs"), "{dir}": str(data)}
    before = _digest(data)
    code, _, err = run(capsys, *[subs.get(a, a) for a in argv])
    assert code == 2 and _one_line(err) and "input" in err
    assert _digest(data) == before


def test_a_second_run_on_a_folder_in_use_is_refused(capsys, tmp_path, clip):
    from lfstream.io.outputs import OutputFolder

    with OutputFolder(tmp_path / "busy"):  # a run of this process holds it
        code, _, err = run(capsys, "stream", clip / "clip.npy", "-o", tmp_path / "busy", "--max-frames", 1)
        assert code == 2 and _one_line(err) and "another lfstream run" in err
    assert not (tmp_path / "busy").exists()  # released, and made by the holder only


def test_a_killed_runs_lock_is_taken_over(tmp_path):
    from lfstream.io.outputs import LOCK_NAME, OutputFolder

    (tmp_path / "old").mkdir()
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (tmp_path / "old" / LOCK_NAME).write_text(proc.stdout.strip())  # a process that is gone
    with OutputFolder(tmp_path / "old", overwrite=True) as claim:
        assert claim.path == tmp_path / "old"


@pytest.mark.parametrize("argv, kind", [
    (["decode", "{lfs}", "-o", "d.txt"], ".txt"),
    (["encode", "{npy}", "-o", "x.npy"], ".npy"),
    (["synth", "-o", "x.lfs"], ".lfs"),
    (["golden", "record", "{npy}", "-o", "g.yaml"], ".yaml"),
])
def test_an_output_kind_a_command_does_not_write_is_refused(capsys, tmp_path, clip, argv, kind):
    subs = {"{npy}": str(clip / "clip.npy"), "{lfs}": str(clip / "clip.lfs")}
    code, _, err = run(capsys, *[subs.get(a, str(tmp_path / a) if "." in a and "{" not in a else a) for a in argv])
    assert code == 2 and _one_line(err) and kind in err
    assert not any(tmp_path.iterdir())


# --- missing views are carried, never invented silently --------------------------------

def test_missing_views_travel_through_the_stream(capsys, tmp_path):
    dino = shared("hci_star", "dino")
    code, out, _ = run(capsys, "info", dino, "--allow-missing", "--json")
    source_missing = json.loads(out)["missing_views"]
    assert len(source_missing) == 48
    assert run(capsys, "encode", dino, "--allow-missing", "-o", tmp_path / "d.lfs")[0] == 0
    code, out, _ = run(capsys, "info", tmp_path / "d.lfs", "--json")
    assert code == 0 and json.loads(out)["missing_views"] == source_missing
    code, out, _ = run(capsys, "decode", tmp_path / "d.lfs", "-o", tmp_path / "views", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["missing_views"] == source_missing and doc["synthesized_views"] == []
    assert len(list((tmp_path / "views").glob("*.png"))) == 33  # the present views only
    arr = lfstream_decode(tmp_path / "d.lfs")
    assert all(not arr[0, r, c].any() for r, c in source_missing)  # zero, as the reader's convention
    code, out, _ = run(capsys, "decode", tmp_path / "d.lfs", "-o", tmp_path / "all", "--synthesize-missing", "--json")
    assert json.loads(out)["synthesized_views"] == source_missing
    assert len(list((tmp_path / "all").glob("*.png"))) == 81


def lfstream_decode(path: Path) -> np.ndarray:
    import lfstream

    return lfstream.decode(path.read_bytes())


# --- messages: one line, the right thing named, in CLI words, before the work -----------

@pytest.mark.parametrize("case", ["too-long", "unwritable", "no-folder", "empty", "nan"])
def test_bad_outputs_and_values_are_one_line_naming_them(capsys, tmp_path, clip, case):
    output = {"too-long": str(tmp_path / ("a" * 300 + ".lfs")), "unwritable": "/proc/x.lfs",
              "no-folder": str(tmp_path / "nope" / "x.lfs"), "empty": "", "nan": str(tmp_path / "x.lfs")}[case]
    argv = ["encode", clip / "clip.npy", "-o", output] + (["--bpp", "nan"] if case == "nan" else [])
    try:
        code, _, err = run(capsys, *argv)
    except SystemExit as exc:  # refused by the parser: a usage error
        code, err = exc.code, capsys.readouterr().err
    assert code == 2 and _one_line(err), err
    assert ("-o" in err or "--bpp" in err) and "cannot read" not in err and "=True" not in err
    assert not any(p.suffix == ".lfs" for p in tmp_path.iterdir())


def test_cli_messages_use_cli_words(capsys, tmp_path, clip):
    (tmp_path / "x.lfs").write_bytes(b"")
    code, _, err = run(capsys, "encode", clip / "clip.npy", "-o", tmp_path / "x.lfs")
    assert code == 2 and "--overwrite" in err and "overwrite=True" not in err


# --- one grammar ---------------------------------------------------------------------

def test_negative_values_after_a_space(capsys, tmp_path, clip):
    code, out, _ = run(capsys, "refocus", clip / "clip.npy", "-o", tmp_path / "r", "--slopes", "-1,0,1",
                       "--max-frames", 1, "--no-viewer", "--no-sweep", "--json")
    assert code == 0 and [p["slope"] for p in json.loads(out)["planes"]] == [-1.0, 0.0, 1.0]


def test_outputs_are_named_by_o_everywhere(capsys, tmp_path, clip):
    assert run(capsys, "synth", "-o", tmp_path / "s.npy", "--frames", 1, "--size", "16x16", "--grid", "3")[0] == 0
    assert np.load(tmp_path / "s.npy").shape == (1, 3, 3, 16, 16, 3)
    assert run(capsys, "convert", tmp_path / "s.npy", "-o", tmp_path / "s.avi")[0] == 0
    assert run(capsys, "convert", tmp_path / "s.npy", tmp_path / "t.avi")[0] == 0  # the older form still works
    code, _, err = run(capsys, "convert", tmp_path / "s.npy", tmp_path / "u.avi", "-o", tmp_path / "v.avi")
    assert code == 2 and "two outputs" in err


@pytest.mark.parametrize("command", ["info", "encode", "decode", "refocus"])
def test_json_schemas_are_the_same_for_every_input(capsys, tmp_path, command):
    """The keys of ``--json`` do not depend on the input (a key that does not apply is null)."""
    import lfstream
    from lfstream.synth import synth_clip

    inputs = []
    for k, (views, frames) in enumerate(((3, 1), (5, 2))):
        lf = synth_clip(frames, views, (32, 40), seed=k).lf
        np.save(tmp_path / f"in{k}.npy", lf if frames > 1 else lf[0])
        (tmp_path / f"in{k}.lfs").write_bytes(lfstream.encode(lf))
        inputs.append(k)
    keys = []
    for k in inputs:
        src = tmp_path / (f"in{k}.lfs" if command == "decode" else f"in{k}.npy")
        extra = {"info": [], "encode": ["-o", tmp_path / f"o{k}.lfs"], "decode": ["-o", tmp_path / f"o{k}.npy"],
                 "refocus": ["-o", tmp_path / f"r{k}", "--no-viewer"]}[command]
        code, out, _ = run(capsys, command, src, *extra, "--json")
        assert code == 0
        keys.append(sorted(json.loads(out)))
    assert keys[0] == keys[1]


# --- the receiver handshake ------------------------------------------------------------

def test_stream_to_something_that_is_not_an_lfstream_receiver_fails_clearly(capsys):
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    accepted = []

    def accept():
        conn, _ = server.accept()
        accepted.append(conn)
        conn.sendall(b"HTTP/1.0 200 OK\r\n\r\n")  # a web server, say

    threading.Thread(target=accept, daemon=True).start()
    try:
        code, out, err = run(capsys, "stream", "--frames", 1, "--to", f"127.0.0.1:{port}")
    finally:
        server.close()
        for c in accepted:
            c.close()
    assert code == 2 and _one_line(err) and "not an lfstream receiver" in err


# --- the built-in clip's cache: one copy for every length ------------------------------

def test_clips_of_any_length_share_one_cache_file(tmp_path, monkeypatch):
    from lfstream.stream.sources import synthetic_source

    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path))
    two = [f.copy() for f in synthetic_source(frames=2, views=3, size=(24, 32), seed=5)]
    three = [f.copy() for f in synthetic_source(frames=3, views=3, size=(24, 32), seed=5)]
    again = [f.copy() for f in synthetic_source(frames=2, views=3, size=(24, 32), seed=5)]  # read from the cache
    files = sorted(p.name for p in tmp_path.glob("builtin-*.npy"))
    assert len(files) == 1, files  # the longest rendered, serving both lengths
    assert np.load(tmp_path / files[0], mmap_mode="r").shape[0] == 3
    for a, b, c in zip(two, three, again):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
    assert _debris(tmp_path) == []
