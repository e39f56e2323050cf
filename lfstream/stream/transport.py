"""Transports between the encoder and the decoder: in-process queue, ``.lfs`` file, TCP.

All three carry the same ``.lfs`` header and packets (:mod:`lfstream.bitstream`). Over
TCP each message is framed as ``tag (4 bytes) | length (uint32, big-endian) | payload``
with tags ``LFSH`` (the stream header), ``LFSP`` (one packet) and ``LFSE`` (end of
stream). A connection opens with a handshake: the sender's ``LFHI`` (JSON: the protocol
version and lfstream's), answered by the receiver's ``LFOK`` or ``LFNO`` (JSON with the
reason), so a sender knows it reached an lfstream receiver that can read it before it sends
anything, and fails in one line otherwise. The receiver checks every length against :class:`Limits` before reading the
payload, every packet's CRC, and the sequence numbers: a lost, duplicated, reordered or
corrupt packet is counted and skipped, never decoded.

Two protocols: a :class:`Sender` (``send_header``, ``send`` per packet, ``close``) and a
:class:`Receiver` (``header``, then ``packets()`` in sequence order, ``stats`` counting what
was lost). Every channel implements both ends or one of them.
"""

from __future__ import annotations

import io
import queue
import socket
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from lfstream.codec.bitstream import (
    Limits,
    Packet,
    StreamHeader,
    StreamWriter,
    pack_header,
    pack_packet,
    read_header,
    read_packet,
)
from lfstream.errors import BitstreamError, LFFileError, LFStreamError, LFValueError
from lfstream.io._fs import temp_sibling

_FRAME = struct.Struct(">4sI")
TAG_HEADER, TAG_PACKET, TAG_END = b"LFSH", b"LFSP", b"LFSE"
TAG_HELLO, TAG_WELCOME, TAG_REFUSE = b"LFHI", b"LFOK", b"LFNO"
#: The TCP protocol's version: a receiver answers a sender of the same version only.
PROTOCOL = 1
_POLL_S = 0.1


class TransportError(LFStreamError, OSError):
    """A connection failed, timed out or spoke something other than lfstream's framing."""


class StoppedError(TransportError):
    """The run was stopped (Ctrl-C, or another stage's failure) while a receiver waited for
    the stream: the end of the wait, not a failure of its own."""


@dataclass
class ReceiveStats:
    """What the receiver saw besides good packets."""

    received: int = 0
    lost: int = 0  # sequence numbers that never arrived
    duplicates: int = 0
    reordered: int = 0  # arrived after a later packet had been delivered (skipped)
    corrupt: int = 0  # CRC or framing damage (skipped)
    events: list[str] = field(default_factory=list)

    def note(self, text: str) -> None:
        if len(self.events) < 100:
            self.events.append(text)

    def as_dict(self) -> dict:
        return {"received": self.received, "lost": self.lost, "duplicates": self.duplicates,
                "reordered": self.reordered, "corrupt": self.corrupt, "events": list(self.events)}


class SequenceFilter:
    """Delivers packets in increasing sequence order; counts and skips everything else."""

    def __init__(self, stats: ReceiveStats) -> None:
        self.stats = stats
        self.next_seq = 0
        self.seen_late: set[int] = set()

    def accept(self, packet: Packet) -> bool:
        s = packet.seq
        if s == self.next_seq:
            self.next_seq += 1
            return True
        if s > self.next_seq:
            gap = s - self.next_seq
            self.stats.lost += gap
            self.seen_late.update(range(self.next_seq, s))
            self.stats.note(f"frames {self.next_seq}..{s - 1} missing before frame {s}")
            self.next_seq = s + 1
            return True
        if s in self.seen_late:
            # counted as lost when the gap opened; it arrived late after all
            self.seen_late.discard(s)
            self.stats.lost -= 1
            self.stats.reordered += 1
            self.stats.note(f"frame {s} arrived out of order and was skipped")
        else:
            self.stats.duplicates += 1
            self.stats.note(f"frame {s} arrived twice; the copy was skipped")
        return False


class Sender(Protocol):
    """The encoder's end of a channel."""

    def send_header(self, header: StreamHeader) -> None: ...

    def send(self, packet: Packet, stop: threading.Event | None = None) -> bool: ...

    def close(self, stop: threading.Event | None = None) -> None: ...


class Receiver(Protocol):
    """The decoder's end of a channel."""

    stats: ReceiveStats

    def header(self, stop: threading.Event | None = None) -> StreamHeader: ...

    def packets(self, stop: threading.Event | None = None) -> Iterator[Packet]: ...


def in_order(arrived: Iterator[Packet], stats: ReceiveStats) -> Iterator[Packet]:
    """The one receive loop: counts every packet that arrived and yields those the
    :class:`SequenceFilter` accepts (in increasing sequence order)."""
    seqf = SequenceFilter(stats)
    for packet in arrived:
        stats.received += 1
        if seqf.accept(packet):
            yield packet


# ----------------------------------------------------------------------------------------
# in-process


class InprocChannel:
    """A bounded in-process queue of packets (the default transport)."""

    def __init__(self, maxsize: int = 4) -> None:
        self._q: queue.Queue = queue.Queue(maxsize)
        self._header: StreamHeader | None = None
        self._header_ready = threading.Event()
        self.stats = ReceiveStats()

    # sender side
    def send_header(self, header: StreamHeader) -> None:
        self._header = header
        self._header_ready.set()

    def send(self, packet: Packet, stop: threading.Event | None = None) -> bool:
        return put_until_stopped(self._q, packet, stop)

    def close(self, stop: threading.Event | None = None) -> None:
        put_until_stopped(self._q, None, stop)

    # receiver side
    def header(self, stop: threading.Event | None = None) -> StreamHeader:
        while not self._header_ready.wait(_POLL_S):
            if stop is not None and stop.is_set():
                raise StoppedError("stopped before the stream header arrived")
        assert self._header is not None
        return self._header

    def packets(self, stop: threading.Event | None = None) -> Iterator[Packet]:
        return in_order(iter(lambda: get_until_stopped(self._q, stop), None), self.stats)


def put_until_stopped(q: queue.Queue, item, stop: threading.Event | None) -> bool:
    """Blocking put that gives up (returns False) when ``stop`` is set, so Ctrl-C never
    hangs on a full queue. Shared by the transports and the pipeline's stages."""
    while True:
        try:
            q.put(item, timeout=_POLL_S)
            return True
        except queue.Full:
            if stop is not None and stop.is_set():
                return False


def get_until_stopped(q: queue.Queue, stop: threading.Event | None):
    """Blocking get that returns ``None`` (the end marker) when ``stop`` is set."""
    while True:
        try:
            return q.get(timeout=_POLL_S)
        except queue.Empty:
            if stop is not None and stop.is_set():
                return None


# ----------------------------------------------------------------------------------------
# file


class _FollowReader(io.RawIOBase):
    """Reads a file that another thread is still writing: blocks until bytes arrive or the
    writer says it is done (then returns what is there: a short read means truncation)."""

    def __init__(self, path: Path, done: threading.Event, stop: threading.Event | None) -> None:
        self._fh = open(path, "rb")
        self._done, self._stop = done, stop

    def readable(self) -> bool:
        return True

    def readinto(self, buf) -> int:
        while True:
            n = self._fh.readinto(buf)
            if n:
                return n
            if self._done.is_set() or (self._stop is not None and self._stop.is_set()):
                return self._fh.readinto(buf) or 0
            time.sleep(0.005)

    def close(self) -> None:
        self._fh.close()
        super().close()


class FileChannel:
    """Writes the stream to an ``.lfs`` file and reads it back while it grows.

    The file is written under a temporary name and renamed to ``path`` when the stream ends,
    so an interrupted run never leaves a file that looks complete; it is a valid ``.lfs``
    of every packet written either way.
    """

    def __init__(self, path: str | Path, limits: Limits = Limits()) -> None:
        self.path = Path(path)
        self._tmp = temp_sibling(self.path, "partial")
        self._limits = limits
        self._done = threading.Event()
        self._started = threading.Event()
        self._writer: StreamWriter | None = None
        self._fh = None
        self.stats = ReceiveStats()

    def send_header(self, header: StreamHeader) -> None:
        try:
            self._fh = open(self._tmp, "wb")
        except OSError as exc:
            raise LFFileError(f"{self._tmp}: cannot write ({exc.strerror or exc})") from exc
        self._writer = StreamWriter(self._fh, header)
        self._fh.flush()
        self._started.set()

    def send(self, packet: Packet, stop: threading.Event | None = None) -> bool:
        assert self._writer is not None and self._fh is not None
        self._writer.write(packet)
        self._fh.flush()
        return True

    def close(self, stop: threading.Event | None = None) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
            self._tmp.replace(self.path)
        self._done.set()
        self._started.set()

    def _open_reader(self, stop):
        while not self._started.wait(_POLL_S):
            if stop is not None and stop.is_set():
                raise StoppedError("stopped before the stream started")
        for path in (self._tmp, self.path):  # the file is renamed when the sender closes it
            try:
                return _FollowReader(path, self._done, stop)
            except FileNotFoundError:
                continue
        # closed without a header: the sender stopped before its first frame
        if stop is not None and stop.is_set():
            raise StoppedError("stopped before the stream started")
        raise TransportError(f"{self.path}: the sender closed the stream before writing its header")

    def header(self, stop: threading.Event | None = None) -> StreamHeader:
        self._reader = io.BufferedReader(self._open_reader(stop))
        self._hdr = read_header(self._reader, self._limits)
        return self._hdr

    def packets(self, stop: threading.Event | None = None) -> Iterator[Packet]:
        """Packets in order; damage inside a file cannot be resynchronised, so it raises
        :class:`BitstreamError` after every complete packet before it."""
        try:
            yield from in_order(iter(lambda: read_packet(self._reader, self._hdr, self._limits), None), self.stats)
        finally:
            self._reader.close()


# ----------------------------------------------------------------------------------------
# TCP


def parse_address(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise LFValueError(f"--to: expected HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


class TcpSender:
    """Sends the stream to a :class:`TcpReceiver` (``lfstream serve``)."""

    def __init__(self, host: str, port: int, timeout_s: float = 10.0) -> None:
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise TransportError(f"cannot connect to {host}:{port} ({exc.strerror or exc})") from exc
        self._sock.settimeout(timeout_s)
        self._addr = f"{host}:{port}"
        self._version = 1  # until send_header
        try:
            self._handshake(timeout_s)
        except BaseException:
            self._sock.close()
            raise

    def _handshake(self, timeout_s: float) -> None:
        """Says hello and waits for the receiver's answer: anything but an lfstream receiver
        of this protocol fails here, before a frame is encoded."""
        import json

        from lfstream.version import __version__

        self._send(TAG_HELLO, json.dumps({"protocol": PROTOCOL, "lfstream": __version__}).encode())
        not_lfstream = f"{self._addr}: not an lfstream receiver (start one with lfstream serve)"
        try:
            head = _recv_exact(self._sock, _FRAME.size)
            if len(head) < _FRAME.size:
                raise TransportError(f"{not_lfstream}: it closed the connection")
            tag, n = _FRAME.unpack(head)
            if tag not in (TAG_WELCOME, TAG_REFUSE) or n > 1 << 16:
                raise TransportError(f"{not_lfstream}: it answered {head[:4]!r}")
            answer = json.loads(_recv_exact(self._sock, n) or b"{}")
        except TimeoutError:
            raise TransportError(f"{not_lfstream}: no answer within {timeout_s:.0f} s") from None
        except (OSError, ValueError) as exc:
            raise TransportError(f"{not_lfstream} ({exc})") from exc
        if tag == TAG_REFUSE:
            raise TransportError(f"{self._addr}: the receiver refused the stream: {answer.get('reason', 'no reason')}")
        self.receiver_version = answer.get("lfstream")

    def _send(self, tag: bytes, payload: bytes) -> None:
        try:
            self._sock.sendall(_frame(tag, payload))
        except OSError as exc:
            raise TransportError(f"{self._addr}: send failed ({exc.strerror or exc})") from exc

    def send_header(self, header: StreamHeader) -> None:
        self._version = header.version  # a packet's layout depends on it
        self._send(TAG_HEADER, pack_header(header))

    def send(self, packet: Packet, stop: threading.Event | None = None) -> bool:
        self._send(TAG_PACKET, pack_packet(packet, self._version))
        return True

    def close(self, stop: threading.Event | None = None) -> None:
        try:
            self._send(TAG_END, b"")
        except TransportError:
            pass
        finally:
            self._sock.close()


def _frame(tag: bytes, payload: bytes) -> bytes:
    return _FRAME.pack(tag, len(payload)) + payload


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(min(n - len(buf), 1 << 20))
        if not chunk:
            break
        buf += chunk
    return bytes(buf)


class TcpReceiver:
    """Accepts one sender and yields its packets (see the module docstring for checks)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, timeout_s: float = 30.0,
                 limits: Limits = Limits()) -> None:
        self._limits = limits
        self._timeout = timeout_s
        try:
            self._server = socket.create_server((host, port))
        except OSError as exc:
            raise TransportError(f"cannot listen on {host}:{port} ({exc.strerror or exc})") from exc
        self._server.settimeout(_POLL_S)
        self.address = self._server.getsockname()[:2]
        self._conn: socket.socket | None = None
        self._header: StreamHeader | None = None
        self.stats = ReceiveStats()
        # accepted and greeted on a thread from the start, so a sender's handshake is answered
        # while this end still loads its kernels
        self._greeted = threading.Event()
        self._greet_stop = threading.Event()
        self._greet_error: BaseException | None = None
        self._greeter = threading.Thread(target=self._greet, name="lfstream-greeter", daemon=True)
        self._greeter.start()

    def _greet(self) -> None:
        import json

        from lfstream.version import __version__

        try:
            conn = self._accept(self._greet_stop)
            self._conn = conn
            head = _recv_exact(conn, _FRAME.size)
            if len(head) < _FRAME.size:
                raise TransportError("the sender closed the connection before its handshake")
            tag, n = _FRAME.unpack(head)
            if tag != TAG_HELLO or n > 1 << 16:
                raise TransportError(f"message tag {head[:4]!r} before a handshake: not an lfstream sender")
            try:
                hello = json.loads(_recv_exact(conn, n) or b"{}")
            except ValueError:
                hello = {}
            if hello.get("protocol") != PROTOCOL:
                reason = f"protocol {hello.get('protocol')!r}; this receiver (lfstream {__version__}) speaks {PROTOCOL}"
                conn.sendall(_frame(TAG_REFUSE, json.dumps({"reason": reason}).encode()))
                raise TransportError(f"a sender of lfstream {hello.get('lfstream', '?')} refused: {reason}")
            conn.sendall(_frame(TAG_WELCOME, json.dumps({"protocol": PROTOCOL, "lfstream": __version__}).encode()))
        except BaseException as exc:  # noqa: BLE001 - reported by header(), on the stage's thread
            self._greet_error = exc
        finally:
            self._greeted.set()

    def _accept(self, stop) -> socket.socket:
        deadline = time.monotonic() + self._timeout
        while True:
            try:
                conn, _ = self._server.accept()
                conn.settimeout(self._timeout)
                return conn
            except TimeoutError:
                if stop is not None and stop.is_set():
                    raise StoppedError(f"stopped before a sender connected to {self.address[0]}:"
                                       f"{self.address[1]}") from None
                if time.monotonic() > deadline:
                    raise TransportError(f"no sender connected to {self.address[0]}:{self.address[1]} "
                                         f"within {self._timeout:.0f} s") from None

    def _message(self) -> tuple[bytes, bytes]:
        assert self._conn is not None
        try:
            head = _recv_exact(self._conn, _FRAME.size)
            if len(head) < _FRAME.size:
                return TAG_END, b""  # sender went away: end of stream
            tag, n = _FRAME.unpack(head)
            if self._header is None:
                limit = 1 << 20  # a header: fixed part plus compressed metadata
            else:
                # image + hint + gains, each bounded by the parser's payload rule, plus metadata
                h, w = self._header.size
                limit = int(3 * (self._limits.max_payload_factor * h * w * 3 + (1 << 20)) + self._limits.max_meta_bytes)
            if tag not in (TAG_HEADER, TAG_PACKET, TAG_END):
                raise TransportError(f"unknown message tag {tag!r}: not an lfstream sender")
            if n > limit:
                raise TransportError(f"message of {n} bytes exceeds the limit of {limit}")
            payload = _recv_exact(self._conn, n)
            if len(payload) < n:
                return TAG_END, b""
            return tag, payload
        except TimeoutError:
            raise TransportError(f"no data for {self._timeout:.0f} s; the sender stalled") from None
        except OSError as exc:
            raise TransportError(f"receive failed ({exc.strerror or exc})") from exc

    def header(self, stop: threading.Event | None = None) -> StreamHeader:
        while not self._greeted.wait(_POLL_S):
            if stop is not None and stop.is_set():
                self._greet_stop.set()
        if self._greet_error is not None:
            raise self._greet_error
        tag, payload = self._message()
        if tag != TAG_HEADER:
            raise TransportError("the sender did not start with a stream header")
        self._header = read_header(io.BytesIO(payload), self._limits)
        return self._header

    def _arrived(self, stop: threading.Event | None) -> Iterator[Packet]:
        """Every well-formed packet message until the end marker; damage is counted and skipped."""
        assert self._header is not None
        while not (stop is not None and stop.is_set()):
            tag, payload = self._message()
            if tag == TAG_END:
                return
            if tag == TAG_HEADER:
                self.stats.corrupt += 1
                self.stats.note("a second stream header was skipped")
                continue
            try:
                packet = read_packet(io.BytesIO(payload), self._header, self._limits)
            except BitstreamError as exc:
                self.stats.corrupt += 1
                self.stats.note(f"corrupt packet skipped: {exc}")
                continue
            if packet is not None:
                yield packet

    def packets(self, stop: threading.Event | None = None) -> Iterator[Packet]:
        try:
            yield from in_order(self._arrived(stop), self.stats)
        finally:
            self.close()

    def close(self) -> None:
        self._greet_stop.set()
        self._greeted.wait(1.0)
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self._server.close()


class LazyTcpSender:
    """A :class:`TcpSender` that connects when the encoder sends the stream header, for a
    loopback stream whose receiver starts listening in the same run."""

    def __init__(self, host: str, port: int) -> None:
        self._addr = (host, port)
        self._sender: TcpSender | None = None

    def send_header(self, header: StreamHeader) -> None:
        self._sender = TcpSender(*self._addr)
        self._sender.send_header(header)

    def send(self, packet: Packet, stop: threading.Event | None = None) -> bool:
        assert self._sender is not None, "send_header first"
        return self._sender.send(packet, stop)

    def close(self, stop: threading.Event | None = None) -> None:
        if self._sender is not None:
            self._sender.close(stop)


__all__ = ["Sender", "Receiver", "in_order", "LazyTcpSender", "InprocChannel", "FileChannel", "TcpSender", "TcpReceiver",
           "ReceiveStats", "SequenceFilter", "TransportError", "StoppedError", "parse_address", "put_until_stopped",
           "get_until_stopped", "TAG_HEADER", "TAG_PACKET", "TAG_END", "TAG_HELLO", "TAG_WELCOME", "TAG_REFUSE",
           "PROTOCOL"]
