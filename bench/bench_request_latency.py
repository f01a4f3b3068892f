"""Benchmark: request -> reflecting update latency as if the server had a core of its own, by request phase.

``ttes loadtest`` measures wall time on a shared machine: there the server waits for a CPU (at load 6-11 on
2 cores it gets 15-40 % of one) and one run says more about the machine than about the server. And its mix
driver stepped at 10 Hz, a divisor of the 30 Hz tick, so within one run every request arrived at the same
phase of the tick period: runs differed by where that phase fell (p50 9-18 ms at 5,000 soldiers, issue 16;
its steps are now jittered over their period, so one run mixes the phases this bench separates).

Here the server (``TtesServer``, the shipped library) and the load generator (``LoadSession``, its real
mix and tracker) run in one trio run over loopback TCP, on a clock that advances by the CPU time of the
server's tasks only (a trio Instrument takes every other task's CPU off it) and jumps to the next deadline
when everything waits. So the server computes as on a dedicated core, the load generator costs nothing, and
each request is stamped with its step's scheduled time. As from a client on a core of its own, a step's
frames land in every connection's socket at that time, even while a server task runs (:class:`Landing`),
and a frame arrives when the server's writer hands it to the socket, not when the load generator's reader
next gets to run (:class:`SentAt`). Each run puts the requests at one phase of the tick period after the
tick's scheduled time; the phases sweep the period. What the numbers leave out: the client's wake-up and
the machine's contention.

    python bench/bench_request_latency.py [--soldiers 5000] [--clients 2] [--seconds 5] [--phases 6] [--json]
"""

from __future__ import annotations

import argparse
import bisect
import contextlib
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import trio

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.link import client as link_client
from client_stub.link.client import LinkError
from client_stub.loadtest.client import split_rows
from client_stub.loadtest.mix import MOVING
from client_stub.loadtest.session import LoadSession, LoadTestConfig, _run
from protocol.events import EntityRequests
from server.app import TtesServer
from server.config import ServerConfig

TICK_HZ = 30.0
LEAD = 0.5  # tick periods: a step is computed this long before it lands
KEYS = ("latency_ms_p50", "latency_ms_p99", "latency_ms_max", "latency_samples", "delivered_pct")


class ServerCpuClock(trio.abc.Clock):
    """Trio time = this thread's CPU time less what the non-server tasks used, plus the jumps over waits."""

    def __init__(self) -> None:
        self.offset = 0.0
        self.hold = False  # bytes just landed in a socket: poll once before jumping to the next deadline

    def start_clock(self) -> None:
        self.offset = 1000.0 - time.thread_time()

    def current_time(self) -> float:
        return time.thread_time() + self.offset

    def deadline_to_sleep_time(self, deadline: float) -> float:
        now = self.current_time()
        if self.hold:
            self.hold = False
            return 0.0
        if now < deadline < float("inf"):
            self.offset += deadline - now  # nothing to run: jump to the next deadline
        return 0.0


class OthersFree(trio.abc.Instrument):
    """Takes the CPU of every task that is not the server's (``server.*``) off the clock."""

    def __init__(self, clock: ServerCpuClock) -> None:
        self.clock = clock
        self.started = 0.0
        self.landing: Landing | None = None

    def before_task_step(self, task: trio.lowlevel.Task) -> None:
        self.started = time.thread_time()

    def after_task_step(self, task: trio.lowlevel.Task) -> None:
        if not task.name.startswith("server."):
            self.clock.offset -= time.thread_time() - self.started
        if self.landing is not None:
            self.landing.land(self.clock.current_time())


class Landing:
    """A mix step's request frames, put into the sockets at the step's time: by the driver when it wakes
    then, or, when a server task is running then (the driver cannot run before it yields), right after that
    task's step (:class:`OthersFree`), as a client on a core of its own would have sent them meanwhile. The
    server sees them when it next polls, as on a real machine. Frames go straight to the socket only when
    the link has nothing queued (no frame is split); else they are queued on the link."""

    def __init__(self, session: LoadSession, clock: ServerCpuClock) -> None:
        self.session = session
        self.clock = clock
        self.due = math.inf
        self.frames: list[tuple[int, bytes]] = []
        self.streams: dict[Any, trio.SocketStream] = {}  # link -> its stream (SentAt records them)

    def prepare(self, due: float, rows: Any) -> None:
        """Encode a step's rows for each connection, to land at ``due``."""
        ses = self.session
        self.frames = []
        for k, part in enumerate(split_rows(rows, ses.owner, ses.cfg.clients)):
            if len(part):
                part = part.copy()
                part["index"] = ses.index[part["index"].astype(np.int64)]
                self.frames.append((k, ses.clients[k].link.conn.send(EntityRequests(part))))
        self.due = due

    def land(self, now: float) -> None:
        if now < self.due:
            return
        self.due = math.inf
        self.clock.hold = True  # the server's reader is woken by the next poll, at this time
        for k, data in self.frames:
            link = self.session.clients[k].link
            stream = self.streams.get(link)
            if stream is None or link._written != link._queued:
                with contextlib.suppress(LinkError):  # a closed link is reported by ``failure``
                    link._queue(data)
                continue
            sent = 0
            with contextlib.suppress(BlockingIOError):
                sent = os.write(stream.socket.fileno(), data)
            if sent < len(data):
                link._queue(data[sent:])
        self.frames = []


class SentAt:
    """A frame's arrival time = when the server's writer handed it to the socket, not when the load
    generator's reader next runs: here that reader runs only after the server task that was runnable beside
    it (a tick's sampling: several ms), which a client on a core of its own would not wait for. The server's
    writes to each connection are stamped (bytes so far, time of the write) as ``send_all`` is called; the
    link's reader takes, for the bytes it received, the stamp of the write that completed them (the
    ``trio.current_time`` it reads next, through :class:`_Clock`)."""

    def __init__(self, server_port: int) -> None:
        self.port = server_port
        self.sent: dict[int, tuple[list[int], list[float]]] = {}  # client port -> (bytes so far, times)
        self.got: dict[int, int] = {}
        self.arrival: dict[Any, float] = {}  # reader task -> arrival of what it just received
        self._orig = (trio.SocketStream.send_all, trio.SocketStream.receive_some, link_client.trio)
        self._run = link_client.Client._run
        self.streams: dict[Any, trio.SocketStream] = {}

    def install(self) -> None:
        send_all, receive_some, _ = self._orig
        stamps = self

        async def stamped_send(stream: trio.SocketStream, data: Any) -> None:
            if _ports(stream)[0] == stamps.port:  # the server's side
                sizes, times = stamps.sent.setdefault(_ports(stream)[1], ([], []))
                sizes.append((sizes[-1] if sizes else 0) + len(data))
                times.append(trio.current_time())
            await send_all(stream, data)

        async def stamped_receive(stream: trio.SocketStream, max_bytes: int | None = None) -> Any:
            data = await receive_some(stream, max_bytes)
            if data and _ports(stream)[1] == stamps.port:  # a load client's side
                key = _ports(stream)[0]
                got = stamps.got[key] = stamps.got.get(key, 0) + len(data)
                sizes, times = stamps.sent.get(key, ([], []))
                k = bisect.bisect_left(sizes, got)
                if k < len(sizes):
                    stamps.arrival[trio.lowlevel.current_task()] = times[k]
            return data

        run = self._run

        async def recorded_run(link: link_client.Client, stream: trio.SocketStream) -> None:
            stamps.streams[link] = stream
            await run(link, stream)

        link_client.Client._run = recorded_run  # type: ignore[method-assign]
        trio.SocketStream.send_all = stamped_send  # type: ignore[method-assign]
        trio.SocketStream.receive_some = stamped_receive  # type: ignore[method-assign]
        link_client.trio = _Clock(self)  # type: ignore[attr-defined]

    def uninstall(self) -> None:
        trio.SocketStream.send_all, trio.SocketStream.receive_some, link_client.trio = self._orig  # type: ignore[method-assign]
        link_client.Client._run = self._run  # type: ignore[method-assign]


def _ports(stream: trio.SocketStream) -> tuple[int, int]:
    """(own port, peer's port); (0, 0) once the peer is gone."""
    try:
        return stream.socket.getsockname()[1], stream.socket.getpeername()[1]
    except OSError:
        return 0, 0


class _Clock:
    """``trio`` for the link module, whose reader stamps arrivals with ``trio.current_time()``."""

    def __init__(self, stamps: SentAt) -> None:
        self.stamps = stamps

    def __getattr__(self, name: str) -> Any:
        return getattr(trio, name)

    def current_time(self) -> float:
        t = self.stamps.arrival.pop(trio.lowlevel.current_task(), None)
        return trio.current_time() if t is None else t


def phased_drive(server: TtesServer, phase: float, stamps: SentAt, others: OthersFree) -> Any:
    """``LoadSession.drive`` with its steps at ``phase`` of a tick period after a tick's scheduled time (the
    tick loop's grid, offset from the server's start by however long its start-up ran), each step's requests
    stamped with the step's scheduled time and landing in every connection's socket then (:class:`Landing`:
    computed half a period before)."""

    async def drive(self: LoadSession, until: float) -> None:
        period = 1.0 / TICK_HZ
        landing = others.landing = Landing(self, others.clock)
        landing.streams = stamps.streams
        tick = server._t0 + server.next_tick  # the tick loop's grid (its first tick is not at _t0)
        k = int((trio.current_time() - tick) / period) + 2
        next_t = tick + (k + phase) * period
        await trio.sleep_until(next_t - LEAD * period)
        while self.now() < until:
            self.failed()
            t = next_t - self.t0
            step = self.driver.step(t)
            ch = step.changed
            if len(ch):
                probe = ~MOVING[step.previous] & self.tracker.settled(t, ch)
                self.tracker.activity(t, ch, MOVING[self.driver.activity[ch]], probe)
            landing.prepare(next_t, step.rows)
            await trio.sleep_until(next_t)
            landing.land(trio.current_time())
            self.tracker.rec.requests_sent.append((t, float(len(step.rows))))
            next_t += 1.0 / self.cfg.step_hz
            await trio.sleep_until(max(next_t - LEAD * period, trio.current_time()))
        others.landing = None

    return drive


async def one_phase(
    soldiers: int, clients: int, seconds: float, phase: float, others: OthersFree
) -> dict[str, Any]:
    cfg = ServerConfig(
        host="127.0.0.1", port=0, tick_hz=TICK_HZ, throttle=0.0, max_soldiers_per_client=max(soldiers, 4096)
    )
    server = TtesServer(cfg)
    server.start_world()
    async with trio.open_nursery() as nursery:
        await nursery.start(server.serve)
        host, port = server.addresses[0]
        stamps = SentAt(port)
        stamps.install()
        LoadSession.drive = phased_drive(server, phase, stamps, others)  # type: ignore[method-assign]
        load = LoadTestConfig(
            soldiers=soldiers, clients=clients, rate_hz=TICK_HZ, seconds=seconds, host=host, port=port
        )
        try:
            out = await _run(load, host, port, None, True)
        finally:
            stamps.uninstall()
        server.shutdown()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=5000)
    ap.add_argument("--clients", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=5.0, help="measured seconds per phase")
    ap.add_argument("--phases", type=int, default=6, help="phases of the tick period swept")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    for k in range(args.phases):
        phase = (k + 0.25) / args.phases
        clock = ServerCpuClock()
        others = OthersFree(clock)
        out = trio.run(
            one_phase,
            args.soldiers,
            args.clients,
            args.seconds,
            phase,
            others,
            clock=clock,
            instruments=[others],
        )
        rows.append({"phase": round(phase, 3), **{key: out.get(key) for key in KEYS}})
        if not args.json:
            r = rows[-1]
            print(
                f"phase {r['phase']:.2f} of the tick period: p50 {r['latency_ms_p50']} ms, p99 "
                f"{r['latency_ms_p99']} ms, max {r['latency_ms_max']} ms ({r['latency_samples']} probes, "
                f"delivered {r['delivered_pct']} %)",
                flush=True,
            )
    if args.json:
        print(json.dumps({"soldiers": args.soldiers, "clients": args.clients, "phases": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
