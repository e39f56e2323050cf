"""The streaming pipeline: transports, faults, errors, stop, backpressure, CLI.

Tolerances: reconstructions are compared bit-exactly where the same packets are decoded
(decoding is deterministic); MPSNR values across transports agree exactly.
"""

import dataclasses
import json
import socket
import struct
import threading
import time

import numpy as np
import pytest

from lfstream.cli import main
from lfstream.codec import Decoder, Encoder
from lfstream.codec.bitstream import pack_packet
from lfstream.errors import LFStreamError
from lfstream.io import iter_video_frames
from lfstream.io._fs import prepare_output_dir
from lfstream.stream import Pipeline, PipelineError, StreamConfig, synthetic_source
from lfstream.stream.pipeline import WARMUP_STATUS
from lfstream.stream.transport import PROTOCOL, TAG_END, TAG_HEADER, TAG_HELLO, TAG_PACKET, TAG_WELCOME, TcpReceiver

SMALL = dict(frames=4, views=5, size=(48, 64))


def small_source(frames=4, seed=3):
    return synthetic_source(frames=frames, views=5, size=(48, 64), seed=seed)


def run(tmp_path, name, **cfg):
    out = prepare_output_dir(tmp_path / name)
    config = StreamConfig(refocus=cfg.pop("refocus", "sas"), mssim_every=1, **cfg)
    return Pipeline(small_source(), config, out, stream_file=out / "stream.lfs").run(), out


@pytest.mark.parametrize("transport", ["inproc", "file", "tcp"])
def test_transports_agree_and_outputs_are_valid(tmp_path, transport):
    summary, out = run(tmp_path, transport, transport=transport, save=("mp4", "lf"))
    ref, _ = run(tmp_path, "ref" + transport, transport="inproc", save=())
    assert summary["frames"] == 4 and summary["lost"] == 0
    assert summary["mpsnr"] == ref["mpsnr"] and summary["mssim"] == ref["mssim"]
    assert summary["mpsnr"] > 20 and 0 < summary["bpp"] < 1
    # what the default chose for a 5x5 grid of 48x64 views: an AV1 centre; too few hint
    # cells for the check of its prediction (lfstream.codec.rate.choose_default)
    assert summary["coding"] == {"preset": "balanced", "quality": 50, "depth_hint": True, "hint_scale": 4,
                                 "residual": None, "residual_mode": None, "hance_map": False,
                                 "prediction_db": None}
    # the summary's figures are consistent with what was streamed, not merely present
    assert summary["fps"] == pytest.approx(summary["frames"] / summary["wall_s"], rel=0.01)
    assert summary["mssim_frames"] == [0, 1, 2, 3] and 0.5 < summary["mssim"] <= 1
    assert set(summary["stages"]) >= {"producer", "encoder", "decoder", "refocus", "sink", "metrics"}
    assert all(s["frames"] == 4 for s in summary["stages"].values())
    # each stage's own thread's CPU beside its wall time (a thread cannot spend more CPU than
    # the time it ran), and the whole process's CPU over the run
    assert all(0 <= s["thread_cpu_s"] <= s["time_s"] * 1.05 + 0.01 for s in summary["stages"].values())
    assert summary["process_cpu_s"] >= max(s["thread_cpu_s"] for s in summary["stages"].values())
    assert [row["frame"] for row in summary["per_frame"]] == [0, 1, 2, 3]
    bpp = sum(row["bpp"] for row in summary["per_frame"]) / 4
    assert bpp == pytest.approx(summary["bpp"], rel=1e-3)
    assert len(list(iter_video_frames(out / "plane_00.mp4"))) == 4
    assert len(list(iter_video_frames(out / "reconstructed.avi"))) == 4
    if transport == "file":
        data = (out / "stream.lfs").read_bytes()
        run2, out2 = run(tmp_path, "again", transport="file", save=())
        assert (out2 / "stream.lfs").read_bytes() == data  # the bitstream is reproducible


def _frames(msg_bytes):
    """Splits framed TCP bytes into (tag, payload) messages."""
    out, k = [], 0
    while k < len(msg_bytes):
        tag, n = struct.unpack(">4sI", msg_bytes[k:k + 8])
        out.append((tag, msg_bytes[k + 8:k + 8 + n]))
        k += 8 + n
    return out


def test_tcp_faults_are_detected_and_skipped(tmp_path):
    frames = list(small_source(frames=8, seed=5))
    enc = Encoder()
    header = enc.header((5, 5), (48, 64), 30.0)
    packets = [enc.encode_frame(f, k, k * 1000) for k, f in enumerate(frames)]
    payloads = [pack_packet(p) for p in packets]
    corrupt = bytearray(payloads[3])
    corrupt[40] ^= 0x55
    # 0 ok, 1 lost, 2 duplicated, 3 corrupt, 5 before 4 (4 arrives late), 6, 7 ok
    plan = [payloads[0], payloads[2], payloads[2], bytes(corrupt), payloads[5], payloads[4], payloads[6], payloads[7]]
    receiver = TcpReceiver("127.0.0.1", 0, timeout_s=20)
    out = prepare_output_dir(tmp_path / "served")
    result = {}

    def serve():
        result["summary"] = Pipeline(None, StreamConfig(refocus="none", save=("lf",)), out, receiver=receiver).run()

    t = threading.Thread(target=serve)
    t.start()
    from lfstream.codec.bitstream import pack_header

    with socket.create_connection(receiver.address, timeout=10) as s:  # a faulty "proxy" sender
        hello = json.dumps({"protocol": PROTOCOL}).encode()
        s.sendall(struct.pack(">4sI", TAG_HELLO, len(hello)) + hello)
        assert s.recv(4) == TAG_WELCOME
        s.recv(1 << 16)
        s.sendall(struct.pack(">4sI", TAG_HEADER, len(pack_header(header))) + pack_header(header))
        for p in plan:
            s.sendall(struct.pack(">4sI", TAG_PACKET, len(p)) + p)
        s.sendall(struct.pack(">4sI", TAG_END, 0))
    t.join(30)
    summary = result["summary"]
    tr = summary["transport"]
    assert tr["duplicates"] == 1 and tr["corrupt"] == 1 and tr["reordered"] == 1
    assert summary["lost"] == 2  # frames 1 and 3 never arrived intact (4 came late and was skipped)
    delivered = [0, 2, 5, 6, 7]
    assert summary["frames"] == len(delivered)
    # every delivered frame is exactly what a clean decoder makes of that packet
    dec = Decoder(header, hance="off")
    got = [f for f in iter_video_frames(out / "reconstructed.avi")]
    from lfstream.lightfield import to_mosaic

    for img, k in zip(got, delivered):
        assert (img == to_mosaic(dec.decode_packet(packets[k]).lf)).all(), k


def test_stage_error_names_stage_and_frame_and_keeps_outputs(tmp_path):
    def bad_source():
        for k, f in enumerate(small_source(frames=4)):
            if k == 2:
                f = f.astype(np.float32)
                f[0, 0, 0, 0, 0] = np.nan
            yield f

    out = prepare_output_dir(tmp_path / "err")
    pipe = Pipeline(bad_source(), StreamConfig(refocus="sas", save=("mp4",)), out)
    with pytest.raises(PipelineError, match="stage encoder failed at frame 2") as info:
        pipe.run()
    assert isinstance(info.value, LFStreamError) and info.value.stage == "encoder" and info.value.frame == 2
    # what was written before the failure is a finalised, playable file (frames still in
    # flight when the pipeline stopped are dropped, never half-written)
    n = len(list(iter_video_frames(out / "plane_00.mp4")))
    assert 1 <= n <= 2 and n == pipe.stats["sink"].frames


def _endless(frame):
    while True:
        yield frame


def test_stop_is_prompt_and_backpressure_bounds_the_producer(tmp_path):
    frame = next(iter(small_source(frames=1)))
    out = prepare_output_dir(tmp_path / "stop")
    pipe = Pipeline(_endless(frame), StreamConfig(refocus="sas", queue_size=2, metrics=False), out, sink_delay_s=0.05)
    threading.Timer(1.5, pipe.stop).start()
    t0 = time.perf_counter()
    summary = pipe.run()
    assert time.perf_counter() - t0 < 1.5 + 2.0
    assert summary["interrupted"]
    produced, sunk = pipe.stats["producer"].frames, pipe.stats["sink"].frames
    # a slow sink throttles the producer: at most the queued frames (4 queues of 2 + stages) ahead
    assert produced - sunk <= 4 * 2 + 5, (produced, sunk)
    assert len(list(iter_video_frames(out / "plane_00.mp4"))) == sunk


@pytest.mark.parametrize("transport", ["inproc", "file", "tcp"])
def test_a_stop_before_the_first_frame_is_an_interruption_not_a_failure(tmp_path, transport):
    """Ctrl-C while the first frame is still being read (a large video's first frame takes a
    while): the decoder, waiting for the stream header, ends its wait; the run reports
    ``interrupted`` (exit 130) with a summary, not "stage transport failed" (exit 2, no
    summary), as it did."""
    frame = next(iter(small_source(frames=1)))
    release = threading.Event()

    def slow_first_frame():
        release.wait(10)  # the stop comes while the source still reads frame 0
        yield frame

    out = prepare_output_dir(tmp_path / transport)
    pipe = Pipeline(slow_first_frame(), StreamConfig(refocus="sas", transport=transport, metrics=False), out,
                    stream_file=out / "stream.lfs")

    def stop_then_release():
        pipe.stop()
        time.sleep(0.3)
        release.set()

    threading.Timer(1.0, stop_then_release).start()
    summary = pipe.run()
    assert summary["interrupted"] and summary["frames"] == 0


def test_serve_and_stream_cli_over_tcp(tmp_path, capsys):
    src = tmp_path / "in.npy"
    np.save(src, np.stack(list(small_source(frames=3))))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    res = {}
    t = threading.Thread(target=lambda: res.__setitem__("rc", main(
        ["serve", "--port", str(port), "-o", str(tmp_path / "srv2"), "--refocus", "sas", "--timeout", "30", "--json"])))
    t.start()
    time.sleep(0.5)  # let it bind; the sender's connect would fail loudly otherwise
    assert main(["stream", str(src), "--to", f"127.0.0.1:{port}", "--json"]) == 0
    t.join(60)
    assert res["rc"] == 0
    summary = json.loads((tmp_path / "srv2" / "summary.json").read_text())
    assert summary["frames"] == 3 and summary["lost"] == 0
    assert len(list(iter_video_frames(tmp_path / "srv2" / "plane_00.mp4"))) == 3


@pytest.mark.parametrize("stage", ["producer", "encoder", "decoder", "refocus", "sink", "metrics"])
def test_a_failure_in_any_stage_ends_the_run_promptly_with_its_error(tmp_path, monkeypatch, stage):
    """Any stage's exception stops every stage: the run raises PipelineError naming the
    stage within seconds instead of hanging on a queue."""
    from lfstream.codec.decoder import Decoder
    from lfstream.stream import stages

    def boom(*args, **kwargs):
        raise RuntimeError(f"injected failure in {stage}")

    frames = small_source(frames=6)
    source = frames
    if stage == "producer":
        def failing():
            yield next(frames)
            boom()
        source = failing()
    else:
        target = {"encoder": (stages.EncoderStage, "work"), "decoder": (Decoder, "decode_batch"),
                  "refocus": (stages.RefocusStage, "work"), "sink": (stages.SinkStage, "work"),
                  "metrics": (stages.MetricsStage, "work")}[stage]
        monkeypatch.setattr(*target, boom)
    out = prepare_output_dir(tmp_path / "out")
    result: dict = {}

    def run_it():
        try:
            Pipeline(source, StreamConfig(refocus="sas", mssim_every=0), out).run()
        except Exception as exc:  # noqa: BLE001 - recorded for the assertions below
            result["error"] = exc

    t = threading.Thread(target=run_it, daemon=True)
    t0 = time.perf_counter()
    t.start()
    t.join(timeout=30)
    assert not t.is_alive(), f"the pipeline hung after a failure in {stage}"
    assert time.perf_counter() - t0 < 30
    err = result.get("error")
    assert isinstance(err, PipelineError) and err.stage == stage, err
    assert f"injected failure in {stage}" in str(err)


def test_builtin_clip_cache_that_vanishes_is_no_error(tmp_path, monkeypatch):
    """The cache folder removed while the clip renders (a temporary cache cleaned up before
    the source was collected): the frames still come, closing the source raises nothing,
    and nothing is left behind."""
    import shutil

    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "cache"))
    for stop in (3, 1):  # the whole clip (rename), stopped early (remove)
        source = synthetic_source(frames=3, views=5, size=(32, 48), seed=11)
        got = [next(source) for _ in range(stop)]
        assert len(got) == stop
        shutil.rmtree(tmp_path / "cache")
        if stop == 3:
            assert next(source, None) is None  # the end: the rename fails quietly
        source.close()
        assert not (tmp_path / "cache").exists()


def test_builtin_clip_is_cached_and_identical_to_a_fresh_render(tmp_path, monkeypatch):
    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "cache"))
    fresh = list(synthetic_source(frames=3, views=5, size=(32, 48), seed=9, cache=False))
    first = list(synthetic_source(frames=3, views=5, size=(32, 48), seed=9))  # renders and stores
    stored = list((tmp_path / "cache").glob("builtin-*.npy"))
    assert len(stored) == 1 and not list((tmp_path / "cache").glob(".*"))  # no temporary left
    second = list(synthetic_source(frames=3, views=5, size=(32, 48), seed=9))  # reads the cache
    for a, b, c in zip(fresh, first, second):
        assert np.array_equal(a, b) and np.array_equal(a, c)
    # a stream stopped early leaves no (partial) cache behind
    gen = synthetic_source(frames=3, views=5, size=(32, 48), seed=10)
    next(gen)
    gen.close()
    assert len(list((tmp_path / "cache").glob("*seed10*"))) == 0


def test_builtin_clip_rendered_ahead_is_the_clip_the_source_reads(tmp_path, monkeypatch):
    """render_builtin_clip writes the cache synthetic_source then reads (the same frames as
    a fresh render, memory-mapped: read-only); a second call renders nothing; a stop set
    first renders nothing and leaves no file; without a cache folder it renders nothing."""
    from lfstream.stream import render_builtin_clip

    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "cache"))
    clip = dict(frames=3, views=5, size=(32, 48), seed=13)
    stopped = threading.Event()
    stopped.set()
    assert render_builtin_clip(**clip, stop=stopped) is None
    assert not list((tmp_path / "cache").iterdir())  # no partial cache, no temporary
    path = render_builtin_clip(**clip)
    assert path is not None and path.exists() and not list((tmp_path / "cache").glob(".*"))
    stamp = path.stat().st_mtime_ns
    assert render_builtin_clip(**clip) == path and path.stat().st_mtime_ns == stamp  # not rendered again
    fresh = list(synthetic_source(**clip, cache=False))
    read = list(synthetic_source(**clip))
    assert all(np.array_equal(a, b) for a, b in zip(fresh, read)) and len(read) == 3
    assert not read[0].flags.writeable  # the mapped cache, not a render
    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "cache" / path.name / "below-a-file"))
    assert render_builtin_clip(**clip) is None
    # a clip the disk cannot hold is not cached (a mapped page written past a full disk is
    # a SIGBUS): the source still renders it, frame by frame
    import lfstream.stream.sources as sources

    assert sources._fits_on_disk(tmp_path, 1 << 20) and not sources._fits_on_disk(tmp_path, 1 << 62)
    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "full"))
    monkeypatch.setattr(sources, "_fits_on_disk", lambda folder, nbytes: False)
    monkeypatch.setattr(sources, "_render_clip", lambda *a, **k: pytest.fail("rendered for nothing"))
    assert render_builtin_clip(**clip) is None and not list((tmp_path / "full").iterdir())
    monkeypatch.undo()
    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "full"))
    monkeypatch.setattr(sources, "_fits_on_disk", lambda folder, nbytes: False)
    assert all(np.array_equal(a, b) for a, b in zip(fresh, synthetic_source(**clip)))


def test_prepare_runs_before_the_timed_stream_and_may_fail(tmp_path):
    """A source's prepare runs during the warm-up: it has finished before the producer
    takes the first frame, its time is in warmup_s, not in the frames' count; one that
    raises leaves the stream to run as it would without it."""
    events = []

    def frames():
        events.append("first frame")
        yield from small_source(frames=2)

    def prepare(stop):
        time.sleep(0.3)
        events.append("prepared")

    def failing(stop):
        raise OSError("disk full")

    for name, hook in (("ok", prepare), ("failing", failing)):
        events.clear()
        out = prepare_output_dir(tmp_path / name)
        summary = Pipeline(frames(), StreamConfig(refocus="sas", save=()), out, prepare=hook).run()
        assert summary["frames"] == 2 and not summary["interrupted"]
        if hook is prepare:
            assert events == ["prepared", "first frame"]
            assert summary["warmup_s"] >= 0.3
        else:
            assert events == ["first frame"]


def test_on_warm_runs_once_after_prepare_and_before_the_first_frame(tmp_path):
    """``on_warm`` (where a command settles its process) is called once, on the calling
    thread, after the source's prepare and before the producer takes the first frame."""
    events = []

    def frames():
        events.append("first frame")
        yield from small_source(frames=2)

    def on_warm():
        events.append(("warm", threading.current_thread() is threading.main_thread()))

    out = prepare_output_dir(tmp_path / "warm")
    summary = Pipeline(frames(), StreamConfig(refocus="sas", save=()), out,
                       prepare=lambda stop: events.append("prepared"), on_warm=on_warm).run()
    assert summary["frames"] == 2
    assert events == ["prepared", ("warm", True), "first frame"]


def test_ctrl_c_during_the_warm_up_stops_prepare(tmp_path, monkeypatch):
    """Ctrl-C while the kernels load: the pipeline sets prepare's stop event and waits for
    it to finish (a render stopped so removes its partial cache) before the interrupt goes on.
    The warm-up runs on a thread of its own, so the interrupt reaches the waiting main thread,
    never an import in progress (which would leave that module's import lock held)."""
    import _thread

    import lfstream.stream.warmup as warmup

    seen = {}

    def prepare(stop):
        seen["stopped"] = stop.wait(10.0)
        seen["finished"] = True

    def interrupted(*args, **kwargs):
        seen["warm_thread"] = threading.current_thread() is not threading.main_thread()
        _thread.interrupt_main()  # Ctrl-C, delivered to the main thread as the signal would be
        time.sleep(0.5)

    monkeypatch.setattr(warmup, "warm_kernels", interrupted)
    out = prepare_output_dir(tmp_path / "out")
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        Pipeline(small_source(), StreamConfig(refocus="sas", save=()), out, prepare=prepare).run()
    assert seen == {"warm_thread": True, "stopped": True, "finished": True} and time.perf_counter() - t0 < 5.0


def test_plane_videos_play_everywhere_and_lossless_is_an_option(tmp_path):
    """Odd-sized views (375 x 540 in the default clip): the planes are yuv420p H.264 (not
    High 4:4:4, which browsers and QuickTime refuse), padded to even size with the true
    size recorded and cropped back by the reader; --save mp4-lossless keeps exact planes."""
    import av

    frames = list(synthetic_source(frames=2, views=3, size=(33, 47), seed=4))
    out = prepare_output_dir(tmp_path / "lossy")
    Pipeline(iter(frames), StreamConfig(refocus="sas", save=("mp4",), metrics=False, preset="fast"), out).run()
    with av.open(str(out / "plane_00.mp4")) as c:
        s = c.streams.video[0]
        assert s.codec_context.pix_fmt == "yuv420p" and "4:4:4" not in (s.codec_context.profile or "")
    got = list(iter_video_frames(out / "plane_00.mp4"))
    assert len(got) == 2 and got[0].shape == (33, 47, 3)
    out2 = prepare_output_dir(tmp_path / "lossless")
    Pipeline(iter(frames), StreamConfig(refocus="sas", alphas="seed", save=("mp4-lossless",), metrics=False, preset="fast"),
             out2).run()
    from lfstream.refocus import focal_stack

    exact = focal_stack(Decoder(Encoder().header((3, 3), (33, 47), 30.0)).decode_packet(
        Encoder().encode_frame(frames[0], 0, 0)).lf)
    assert np.array_equal(next(iter(iter_video_frames(out2 / "plane_00.mp4"))), exact[0])


def test_progress_line_shows_frames_rate_and_eta(tmp_path):
    lines = []
    pipe = Pipeline(small_source(frames=4), StreamConfig(refocus="sas", metrics=False, save=()), None,
                    progress=lines.append, total_frames=4)
    pipe.run()
    assert lines and lines[0] == WARMUP_STATUS  # said before the warm-up, which is silent otherwise
    line = pipe.status_line(2.0)
    assert line.startswith("frame 4/4 | 2.0 frames/s | ETA 0 s"), line
    pipe.total_frames = None
    assert pipe.status_line(2.0).startswith("frame 4 | 2.0 frames/s |")


def test_auto_focal_planes_fit_the_scene_and_are_recorded(tmp_path):
    """The default planes span the scene's disparity (not the seed's -7 ... +0.5 slopes),
    a depth of field apart, stay put over a steady clip, and are recorded in the summary,
    in planes.json, in each plane video's metadata and in a contact sheet."""
    import av

    from lfstream.refocus import plane_spacing
    from lfstream.synth import synth_clip

    clip = synth_clip(4, 5, (64, 96), seed=3, motion=0.3, camera_pan=0.1, disparity_range=(-1.0, 1.5))
    out = prepare_output_dir(tmp_path / "auto")
    summary = Pipeline(iter(clip.lf), StreamConfig(refocus="sas", mssim_every=0), out).run()
    slopes = np.array([p["slope"] for p in summary["planes"]])
    gt = clip.disparity[0, 2, 2]
    lo, hi = np.percentile(gt, [2, 98])
    assert 4 <= len(slopes) <= 16 and np.all(np.diff(slopes) > 0)
    assert slopes[0] <= lo + 0.3 and slopes[-1] >= hi - 0.3  # the scene's range is covered ...
    assert slopes[0] > -2.5 and slopes[-1] < 2.5  # ... and not the seed's -7 ... +0.5
    assert np.diff(slopes).max() <= plane_spacing((5, 5)) + 1e-9 or len(slopes) == 16
    assert [u["frame"] for u in summary["plane_updates"]] == [0]  # stable over a steady clip
    for p in summary["planes"]:  # slopes >= 1 (nearer than alpha -> infinity) have no alpha
        assert p["alpha"] == (pytest.approx(1 / (1 - p["slope"]), rel=1e-4) if p["slope"] < 1 else None)
    sidecar = json.loads((out / "planes.json").read_text())
    assert sidecar["planes"] == summary["planes"]
    with av.open(str(out / "plane_00.mp4")) as c:
        assert f"slope={slopes[0]:+.4f}" in c.metadata.get("comment", "")
    assert (out / "contact_sheet.png").exists() and str(out / "contact_sheet.png") in summary["outputs"]
    # the seed's stack on request
    seed = Pipeline(iter(clip.lf), StreamConfig(refocus="sas", alphas="seed", metrics=False, save=()), None).run()
    assert len(seed["planes"]) == 16 and seed["planes"][0]["alpha"] == pytest.approx(0.125)


def test_a_run_stopped_before_its_stages_reports_the_same_keys(tmp_path):
    from lfstream.stream.report import stopped_summary

    full = Pipeline(small_source(frames=1), StreamConfig(refocus="sas", metrics=False, save=()), None).run()
    stopped = stopped_summary("inproc")
    assert set(stopped) == set(full) and stopped["interrupted"] is True and stopped["frames"] == 0
    json.dumps(stopped, allow_nan=False)  # strict JSON too


def test_the_stream_codes_the_views_where_warping_cannot_predict_them(unpredictable):
    """The stream's default makes the encoder's choice on its first frame: views no
    disparity explains are coded as one AV1 sequence (the hint still sent, for the focal
    planes), and the summary says so."""
    frames = [unpredictable, unpredictable]
    summary = Pipeline(iter(frames), StreamConfig(refocus="sas", save=(), mssim_every=1), None).run()
    coding = summary["coding"]
    assert coding["preset"] == "balanced" and coding["residual_mode"] == "views" and coding["depth_hint"]
    assert coding["prediction_db"] < 22.0 and summary["mpsnr"] > 30.0, summary["mpsnr"]


@pytest.mark.parametrize("read_only", [True, False])
def test_warm_up_loads_every_kernel_the_stream_calls(monkeypatch, read_only):
    """The warm-up (excluded from frames/s) must call each numba kernel with the argument
    types the stream then uses: numba compiles one machine-code version per signature, and
    a signature first met in the timed run is loaded there (or, on a fresh install,
    compiled: seconds). Read-only frames (the built-in clip, memory-mapped) and writable ones
    (files) alike. Every kernel call is recorded with its numba types, during the warm-up and
    after it; the run may use no type tuple the warm-up did not."""
    import importlib

    import numba

    import lfstream.stream.warmup as warmup

    calls: list[tuple[str, tuple]] = []
    for name in ("lfstream._kernels", "lfstream.codec.warp.kernels", "lfstream.codec.warp.splat_kernels",
                 "lfstream.codec.hint.kernels", "lfstream.codec.gains_kernels", "lfstream.codec.residual_kernels",
                 "lfstream.codec.centre.hance_kernels", "lfstream.refocus._kernels"):
        module = importlib.import_module(name)
        for attr, fn in list(vars(module).items()):
            if isinstance(fn, numba.core.registry.CPUDispatcher):
                def spy(*args, _fn=fn, _name=f"{name}.{attr}"):
                    calls.append((_name, tuple(numba.typeof(a) for a in args)))
                    return _fn(*args)
                monkeypatch.setattr(module, attr, spy)
    warmed: set = set()
    real_warm = warmup.warm_kernels

    def warm(*args, **kwargs):
        real_warm(*args, **kwargs)
        warmed.update(calls)
        calls.clear()

    monkeypatch.setattr(warmup, "warm_kernels", warm)
    frames = list(synthetic_source(frames=2, views=7, size=(64, 96), seed=4, cache=False))
    for f in frames:
        f.flags.writeable = not read_only
    config = StreamConfig(refocus="sas", mssim_every=1, save=())
    summary = Pipeline(iter(frames), config, None).run()
    assert summary["frames"] == 2 and summary["coding"]["prediction_db"] is not None  # the default's check ran
    assert warmed and calls  # both phases called kernels (the spies are in place)
    missed = sorted({name for name, types in calls if (name, types) not in warmed})
    assert not missed, f"kernels called with types the warm-up did not load: {missed}"


def test_the_warm_up_decodes_on_the_streams_device(monkeypatch):
    """A CUDA stream's warm-up decodes on the GPU (its context and warp kernels start there,
    outside the timed run): the warm-up's decoder gets the stream's device."""
    import lfstream.codec.decoder as decoder_module
    from lfstream.stream.warmup import warm_kernels

    seen = {}

    class Stop(Exception):
        pass

    class Recorder:
        def __init__(self, header, **kwargs):
            seen.update(kwargs)

        def decode_packet(self, packet):
            raise Stop

    config = StreamConfig(refocus="sas", save=())
    config.device = "cuda:7"  # after the config's own check: only where it goes is looked at
    monkeypatch.setattr(decoder_module, "Decoder", Recorder)
    with pytest.raises(Stop):
        warm_kernels(config)
    assert seen["device"] == "cuda:7" and seen["hance"] == "off"


def test_a_stream_with_strength_maps_sends_them_and_its_decoder_runs_the_network(tmp_path):
    """``stream --hance-map``: every packet's JPEG carries the encoder's map, the header names
    its network, the summary says so, and the stream's decoder (``hance`` auto) decodes what
    ``lfstream.decode`` of the stream file decodes with ``hance="on"`` (the summary's MPSNR,
    to 1e-6 dB), not ``"off"``; refused with rate control or a coding the maps do not go with."""
    import lfstream
    from lfstream.codec.bitstream import split_stream
    from lfstream.codec.centre.jpeg import hance_map
    from lfstream.metrics import mpsnr

    frames = list(synthetic_source(frames=2, views=7, size=(48, 64), seed=6, cache=False))
    config = StreamConfig(refocus="sas", save=(), hance_map=True, mssim_every=0, transport="file")
    summary = Pipeline(iter(frames), config, None, stream_file=tmp_path / "stream.lfs").run()
    assert summary["frames"] == 2 and summary["coding"]["hance_map"] is True
    data = (tmp_path / "stream.lfs").read_bytes()
    header, packets = split_stream(data)
    assert header.meta["hance_map"] == "fast" and all(hance_map(p.image) is not None for p in packets)

    def mean_mpsnr(hance):
        return float(np.mean([mpsnr(f, d) for f, d in zip(frames, lfstream.decode(data, hance=hance))]))

    assert summary["mpsnr"] == pytest.approx(mean_mpsnr("on"), abs=1e-6)
    assert abs(mean_mpsnr("on") - mean_mpsnr("off")) > 1e-3
    for bad in ({"bpp": 0.02}, {"preset": "balanced"}, {"residual": 40}):
        with pytest.raises(LFStreamError, match="hance_map"):
            StreamConfig(hance_map=True, **bad).validate()


def test_the_streams_decoder_runs_the_networks_preset_named(tmp_path):
    """``networks="paper"``: the stream's decoder runs JPEG-Hance paper (its MPSNR that of
    ``lfstream.decode(..., preset="paper")`` of the stream it wrote), and the summary names
    the preset; an unknown preset is refused before anything runs."""
    import lfstream
    from lfstream.metrics import mpsnr

    frames = list(synthetic_source(frames=1, views=3, size=(40, 56), seed=2, cache=False))
    config = StreamConfig(refocus="sas", save=(), hance="on", networks="paper", mssim_every=0, transport="file")
    summary = Pipeline(iter(frames), config, None, stream_file=tmp_path / "stream.lfs").run()
    from lfstream.models.device import native_bfloat16

    assert summary["skips"]["jpeg_hance"] == {"mode": "on", "networks": "paper", "ran": True,
                                              "precision": "bfloat16" if native_bfloat16("cpu") else "float32"}
    plain = Pipeline(iter(frames), dataclasses.replace(config, hance="off"), None, stream_file=tmp_path / "off.lfs").run()
    assert plain["skips"]["jpeg_hance"] == {"mode": "off", "networks": "paper", "ran": False, "precision": None}
    data = (tmp_path / "stream.lfs").read_bytes()
    assert summary["mpsnr"] == pytest.approx(mpsnr(frames[0], lfstream.decode(data, hance="on", preset="paper")[0]),
                                             abs=1e-6)
    with pytest.raises(LFStreamError, match="networks"):
        StreamConfig(networks="best").validate()


def test_the_warm_up_runs_the_networks_the_streams_decoder_runs(monkeypatch):
    """With ``--hance on`` and ``--depth net`` the warm-up imports torch and runs both
    networks once on its tiny frame (the first timed frame paid 0.8 s of torch's import
    before); the default stream's warm-up runs neither (its decoder runs none on the CPU)."""
    import lfstream.models.depth_net as depth_net
    import lfstream.models.jpeg_hance as jpeg_hance
    from lfstream.stream.warmup import warm_kernels

    ran = []
    for module, name, label in ((jpeg_hance, "restore_images", "hance"),
                                (depth_net, "predict_view_disparities", "depth")):
        real = getattr(module, name)

        def spy(*args, _fn=real, _label=label, **kwargs):
            ran.append(_label)
            return _fn(*args, **kwargs)
        monkeypatch.setattr(module, name, spy)
    warm_kernels(StreamConfig(refocus="sas", save=(), hance="on", depth="net"))
    assert sorted(ran) == ["depth", "hance"]
    ran.clear()
    warm_kernels(StreamConfig(refocus="sas", save=()))
    assert ran == []


@pytest.mark.parametrize("stored", ["transposed", "rows flipped", "quarter turn"])
def test_the_refocus_stage_focuses_a_grid_stored_off_the_convention_as_its_own_order(stored):
    """A capture whose view grid is flipped or swapped (the hint carries its axes): the
    stream refocuses the views reordered to the convention, so its planes are the focal
    stack of the grid in its own order (measured 35.84-35.85 dB against that stack, the
    (U, V) grid's stream 35.86); refocusing the stored order, as before, gave 31.6-33.1."""
    import queue

    import lfstream
    from lfstream.codec.bitstream import split_stream
    from lfstream.metrics import psnr
    from lfstream.refocus import focal_stack
    from lfstream.stream.report import StageStats
    from lfstream.stream.stages import RefocusStage, RunControl
    from lfstream.synth import synth_clip

    clip = synth_clip(1, 7, (256, 256), seed=0).lf[0]
    lf = {"transposed": clip.transpose(1, 0, 2, 3, 4), "rows flipped": clip[::-1],
          "quarter turn": np.rot90(clip, 1, axes=(0, 1))}[stored]
    header, packets = split_stream(lfstream.encode(np.ascontiguousarray(lf)))
    decoded = Decoder(header).decode_packet(packets[0])
    assert decoded.axes is not None
    stage = RefocusStage(RunControl(), StageStats("refocus"), queue.Queue(), queue.Queue(), StreamConfig(refocus="sas"))
    out = stage.work(decoded)
    assert stage.view_axes is not None  # reported in the summary's refocus record
    truth = focal_stack(clip, slopes=out.slopes)
    assert float(np.mean(psnr(truth, out.stack))) > 35.0
    assert float(np.mean(psnr(truth, focal_stack(np.ascontiguousarray(lf), slopes=out.slopes)))) < 34.0


def test_the_child_compiles_the_warp_and_focal_stack_the_stream_calls(monkeypatch, tmp_path):
    """On a first run the warp and the focal stack compile in a child process beside the
    warm-up (:func:`lfstream.stream.warmup.compile_beside`): its calls must have the numba
    types the stream's warm-up then gives those kernels, or the warm-up compiles them again
    (recorded as in the test above). The child starts only where the marker of compiled
    kernels is missing, exits cleanly, and the warm-up then leaves the marker."""
    import importlib

    import numba

    import lfstream.stream.warmup as warmup

    calls: list[tuple[str, tuple]] = []
    for name, attr in (("lfstream.codec.warp.kernels", "warp_all_views"), ("lfstream.refocus._kernels", "shift_sum_separable")):
        module = importlib.import_module(name)
        fn = getattr(module, attr)

        def spy(*args, _fn=fn, _name=attr):
            calls.append((_name, tuple(numba.typeof(a) for a in args)))
            return _fn(*args)
        monkeypatch.setattr(module, attr, spy)
    warmup.compile_warp_and_focal_stack()
    child = set(calls)
    calls.clear()
    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path))
    monkeypatch.setattr(warmup, "compile_beside", lambda warp, focal: None)  # the types only, here
    warmup.warm_kernels(StreamConfig(refocus="sas", mssim_every=1, save=()))
    assert {name for name, _ in child} == {"warp_all_views", "shift_sum_separable"}
    assert calls and set(calls) <= child, sorted(set(calls) - child)
    monkeypatch.undo()
    monkeypatch.setenv("LFSTREAM_CACHE", str(tmp_path / "fresh"))
    assert warmup.compile_beside(False, False) is None  # nothing to compile beside
    started = warmup.compile_beside(True, True)
    assert started is not None and started.wait(timeout=300) == 0
    warmup.warm_kernels(StreamConfig(save=()))
    assert warmup._compiled_marker().exists() and warmup.compile_beside(True, True) is None
