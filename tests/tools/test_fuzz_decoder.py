"""The coverage-guided decoder fuzzer (tools/fuzz_decoder.py): its seed corpus and every
kept finding replay without a non-LFStreamError exception, its CRC repair lets mutations
reach the payload decoders, and a short atheris run finds nothing."""

import shutil
import subprocess
import sys
import zlib

import pytest

from tests.conftest import ROOT

sys.path.insert(0, str(ROOT / "tools"))
import fuzz_decoder  # noqa: E402

CORPUS = ROOT / "tests" / "fuzz_corpus"


def test_the_corpus_covers_every_target_and_replays_cleanly():
    files = sorted(p for p in CORPUS.iterdir() if p.is_file())
    targets = {fuzz_decoder.TARGETS[p.read_bytes()[0] % len(fuzz_decoder.TARGETS)] for p in files}
    assert targets >= {"stream", "hint", "gains", "residual", "meta"}
    for path in files:
        fuzz_decoder.one_input(path.read_bytes())  # raises on a finding


def test_a_jpeg_declaring_a_huge_frame_is_refused_before_it_is_decoded():
    """The finding kept as regression-oom-jpeg-size: a 500-byte JPEG centre view that declared
    26729 x 28276 pixels made the decoder allocate gigabytes before it checked the size."""
    import resource

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    fuzz_decoder.one_input((CORPUS / "regression-oom-jpeg-size").read_bytes())
    assert (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024 < 300  # MB


def test_crc_repair_makes_a_mutated_stream_pass_its_checksums():
    from lfstream.codec.bitstream import split_stream

    data = bytearray((CORPUS / "stream_jpeg_hint").read_bytes()[1:])
    data[-40] ^= 0x10  # inside the last packet's payload
    with pytest.raises(Exception, match="CRC"):
        split_stream(bytes(data))
    repaired = fuzz_decoder.repair_crcs(bytes(data))
    header, packets = split_stream(repaired)  # the checksums hold now: the payload is what is tested
    assert len(packets) == 2 and zlib.crc32(repaired) != zlib.crc32(bytes(data))


def test_a_short_coverage_guided_run_finds_nothing(tmp_path):
    import resource

    pytest.importorskip("atheris")
    corpus = tmp_path / "corpus"
    shutil.copytree(CORPUS, corpus)
    # a child's peak RSS starts at this process's (inherited across fork): the limit is 1 GB
    # above what the test suite holds
    limit = int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024) + 1024
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "fuzz_decoder.py"), str(corpus), "-runs=3000",
                           f"-rss_limit_mb={limit}", "-timeout=30", f"-artifact_prefix={tmp_path}/"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not list(tmp_path.glob("crash-*")) and not list(tmp_path.glob("oom-*"))


def _decode_leaving_jobs(data: bytes, monkeypatch) -> list:
    """Decodes ``data`` (a damaged stream: raises) and returns the residual decodes it started."""
    import lfstream
    from lfstream.codec.decoder import Decoder
    from lfstream.errors import LFStreamError

    started = []
    real = Decoder._start_residuals

    def recording(self, packets):
        jobs = real(self, packets)
        started.extend(j for j in jobs if j is not None)
        return jobs

    monkeypatch.setattr(Decoder, "_start_residuals", recording)
    with pytest.raises(LFStreamError):
        lfstream.decode(fuzz_decoder.repair_crcs(data[1:]))
    return started


def test_a_frame_that_fails_leaves_no_residual_decode_behind(monkeypatch):
    """The finding kept as regression-abandoned-residual: its JPEG centre view has no frame
    header, so the frame fails at once while its residual (a long AV1 sequence) was decoding
    on a worker thread; the jobs of a run of such streams piled up on the workers, growing
    the fuzzer's memory without bound. Every job is settled when the decode fails."""
    for _ in range(5):
        jobs = _decode_leaving_jobs((CORPUS / "regression-abandoned-residual").read_bytes(), monkeypatch)
        assert jobs and all(j.done() for j in jobs)


@pytest.mark.parametrize("case, message", [("regression-leak-residual-error", "not a decodable AV1 sequence"),
                                           ("regression-leak-residual-frame-size", "header says")])
def test_a_residual_that_fails_keeps_no_decoder_alive_through_its_error(case, message):
    """The findings kept as regression-leak-residual-*: a residual dav1d refuses mid-sequence,
    and one whose decoded frames are not the header's size. The error, chained to PyAV's or
    raised beside the decoder, kept decode_residual's frame (and with it the dav1d context
    and the frames) alive as long as the caller kept the error: kilobytes a stream over a long
    run. It is raised unchained, after they are freed."""
    from lfstream.codec.bitstream import split_stream
    from lfstream.codec.residual import decode_residual
    from lfstream.errors import BitstreamError

    header, packets = split_stream(fuzz_decoder.repair_crcs((CORPUS / case).read_bytes()[1:]))
    p = next(p for p in packets if p.residual)
    with pytest.raises(BitstreamError, match=message) as info:
        decode_residual(p.residual, header.views, header.size, p.seq, p.image)
    assert info.value.__cause__ is None and info.value.__context__ is None
    tb = info.value.__traceback__
    while tb is not None:  # the frame the error was raised in holds neither the decoder nor frames
        if tb.tb_frame.f_code.co_name == "decode_residual":
            assert not {"ctx", "decoded"} & set(tb.tb_frame.f_locals), set(tb.tb_frame.f_locals)
        tb = tb.tb_next
