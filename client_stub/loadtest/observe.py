"""Counting observers: the light receive mode of the fan-out measurement (issue 18).

Measuring what a server delivers to 8 clients needs receivers cheaper than the server. A load-test connection
(a trio link, a tracker per soldier) costs more per update than the shared encode does, so on a small machine
the generator, not the server, sets the delivered share. A :class:`CountingObserver` is a plain blocking-free
socket with a large receive buffer: after the handshake (done by :class:`protocol.connection.Connection`) it
cuts the stream into frames itself and counts each JOINT_UPDATES frame's soldier-updates from its 8-byte head
(``table: u16, tick: u32, count: u16``, docs/PROTOCOL.md §8, the same in versions 1 and 2), never reading
the indices or decoding the deltas. :func:`observe` runs several of them in one process with a selector.
"""

from __future__ import annotations

import math
import selectors
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from client_stub.link.spawn import cpu_seconds, self_cpu_seconds
from protocol.connection import CLIENT, NEED_DATA, Connection
from protocol.events import ConnectionClosed, Error, Goodbye, Hello, ProtocolError, Ready, Subscribe
from protocol.framing import HEADER as FRAME_HEADER  # length (type byte + payload), type
from protocol.messages import MessageType
from protocol.updates import UPDATE_HEADER

RECV_BYTES = 1 << 22  # one recv takes up to 4 MiB: a 10,000-soldier tick is ~0.4 MB
RCVBUF = 1 << 24  # asked of the kernel (it caps this at net.core.rmem_max)
JOINT_UPDATES = int(MessageType.JOINT_UPDATES)


@dataclass
class FrameCounter:
    """Cuts a byte stream into frames; a JOINT_UPDATES frame is only counted (its tick, soldier count and
    size at its arrival time), every other frame is handed back whole for the protocol connection."""

    ticks: list[int] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    sizes: list[int] = field(default_factory=list)  # bytes on the wire, length prefix included
    times: list[float] = field(default_factory=list)
    buf: bytearray = field(default_factory=bytearray)

    def feed(self, data: bytes | bytearray | memoryview, now: float = 0.0) -> list[bytes]:
        """Take stream bytes; returns the complete frames that are not joint updates (prefix included)."""
        buf = self.buf
        buf += data
        pos, end = 0, len(buf)
        others: list[bytes] = []
        while end - pos >= 5:
            length, mtype = FRAME_HEADER.unpack_from(buf, pos)
            if end - pos < 4 + length:
                break
            if mtype == JOINT_UPDATES and length >= 1 + UPDATE_HEADER.size:
                _table, tick, count = UPDATE_HEADER.unpack_from(buf, pos + 5)
                self.ticks.append(tick)
                self.counts.append(count)
                self.sizes.append(4 + length)
                self.times.append(now)
            else:  # a malformed update is the connection's to refuse
                others.append(bytes(buf[pos : pos + 4 + length]))
            pos += 4 + length
        del buf[:pos]
        return others


class CountingObserver:
    """One observer connection, subscribed to given soldiers, counting what arrives (see the module)."""

    def __init__(self, name: str, version: int = 2) -> None:
        self.name = name
        self.conn = Connection(CLIENT, decode_updates=False)
        self.version = version
        self.counter = FrameCounter()
        self.sock: socket.socket | None = None
        self.ready: Ready | None = None
        self.failure: str | None = None
        self.closed = False

    def connect(self, host: str, port: int, timeout: float = 30.0) -> None:
        """Open the socket and shake hands; returns after READY (raises ConnectionError otherwise)."""
        sock = socket.create_connection((host, port), timeout=timeout)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF)
        self.sock = sock
        sock.sendall(self.conn.send(Hello(self.name, "observer", version=self.version)))
        deadline = time.monotonic() + timeout
        while self.ready is None:
            if self.failure is not None or self.closed or time.monotonic() > deadline:
                raise ConnectionError(f"{self.name}: no READY ({self.failure or 'closed or timed out'})")
            data = sock.recv(RECV_BYTES)
            self._control(self.counter.feed(data) if data else [], eof=not data)
        sock.setblocking(False)

    def subscribe(self, indices: Sequence[int]) -> None:
        assert self.sock is not None
        self.sock.setblocking(True)
        self.sock.sendall(self.conn.send(Subscribe(tuple(int(i) for i in indices))))
        self.sock.setblocking(False)

    def pump(self, now: float) -> None:
        """Read what the socket holds (non-blocking) and count it."""
        assert self.sock is not None
        try:
            data = self.sock.recv(RECV_BYTES)
        except BlockingIOError:
            return
        except OSError as exc:
            self.failure, self.closed = f"{self.name}: {exc}", True
            return
        self._control(self.counter.feed(data, now) if data else [], eof=not data)

    def _control(self, frames: list[bytes], eof: bool) -> None:
        """Control frames go through the protocol connection (ACCEPT, tables, READY, errors, GOODBYE)."""
        for frame in frames:
            self.conn.receive_data(frame)
        if eof:
            self.conn.receive_data(b"")
        while (ev := self.conn.next_event()) is not NEED_DATA:
            if isinstance(ev, Ready):
                self.ready = ev
            elif isinstance(ev, Error | ProtocolError):
                self.failure = f"{self.name}: error {ev.code}: {ev.message}"
            elif isinstance(ev, Goodbye | ConnectionClosed):
                self.closed = True
                break

    def close(self) -> None:
        if self.sock is None:
            return
        try:
            self.sock.setblocking(True)
            if not self.closed:
                self.sock.sendall(self.conn.send(Goodbye("fan-out measurement done")))
        except OSError:
            pass
        self.sock.close()
        self.sock = None


def window_counts(counter: FrameCounter, t0: float, t1: float) -> dict[str, Any]:
    """What arrived in ``[t0, t1)``: soldier-updates, frames, bytes, distinct ticks, and the span of tick
    numbers (last - first + 1: the server's own ticks in the window, whether sent to this client or not)."""
    keep = [k for k, t in enumerate(counter.times) if t0 <= t < t1]
    ticks = [counter.ticks[k] for k in keep]
    return {
        "updates": sum(counter.counts[k] for k in keep),
        "frames": len(keep),
        "bytes": sum(counter.sizes[k] for k in keep),
        "ticks": len(set(ticks)),
        "tick_span": (max(ticks) - min(ticks) + 1) if ticks else 0,
    }


def observe(
    host: str, port: int, indices: Sequence[int], names: Sequence[str], t0: float, t1: float, *,
    version: int = 2, server_pid: int | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Connect one observer per name, subscribe each to ``indices``, count until ``t1`` (``time.monotonic``,
    the same clock in every process of the machine); the counts and CPU of the window ``[t0, t1)``."""
    observers = [CountingObserver(n, version) for n in names]
    sel = selectors.DefaultSelector()
    try:
        for o in observers:
            o.connect(host, port)
            o.subscribe(indices)
            assert o.sock is not None
            sel.register(o.sock, selectors.EVENT_READ, o)
        late = time.monotonic() > t0
        cpu0: tuple[float, float, float, float] | None = None
        while (now := time.monotonic()) < t1:
            if cpu0 is None and now >= t0:
                cpu0 = (now, _cpu(server_pid), self_cpu_seconds(), run_queue_seconds(server_pid))
            for key, _ in sel.select(min(0.05, max(0.0, t1 - now))):
                key.data.pump(time.monotonic())
            if all(o.closed for o in observers):
                break
        end = (time.monotonic(), _cpu(server_pid), self_cpu_seconds(), run_queue_seconds(server_pid))
    finally:
        sel.close()
        for o in observers:
            o.close()
    start = cpu0 or end
    span = end[0] - start[0]
    return {
        "window": [start[0], end[0]],
        "late_start": late,
        "server_cpu_s": end[1] - start[1],
        "observer_cpu_s": end[2] - start[2],
        "server_cpu_pct": round(100 * (end[1] - start[1]) / span, 1) if span > 0 else math.nan,
        "server_wait_pct": round(100 * (end[3] - start[3]) / span, 1) if span > 0 else math.nan,
        "clients": [
            {"name": o.name, "failure": o.failure, "closed": o.closed,
             **window_counts(o.counter, start[0], end[0])}
            for o in observers
        ],
    }  # fmt: skip


def _cpu(pid: int | None) -> float:
    return cpu_seconds(pid) if pid else math.nan


def run_queue_seconds(pid: int | None) -> float:
    """Seconds a process's threads have waited on a run queue, runnable but not running (Linux
    ``/proc/PID/schedstat``, 2nd field): a server starved by its machine, not by its own work."""
    if not pid:
        return math.nan
    try:
        return int(Path(f"/proc/{pid}/schedstat").read_text().split()[1]) / 1e9
    except (OSError, IndexError, ValueError):
        return math.nan
