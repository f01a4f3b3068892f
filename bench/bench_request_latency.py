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
each request is stamped with its step's scheduled time (sent then from a core of its own, it waits in the
socket while the server works). Each run puts the requests at one phase of the tick period; the phases
sweep the period. What the numbers leave out: the client's wake-up and the machine's contention.

    python bench/bench_request_latency.py [--soldiers 5000] [--clients 2] [--seconds 5] [--phases 6] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import trio

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.loadtest.mix import MOVING
from client_stub.loadtest.session import LoadSession, LoadTestConfig, _run
from server.app import TtesServer
from server.config import ServerConfig

TICK_HZ = 30.0
KEYS = ("latency_ms_p50", "latency_ms_p99", "latency_ms_max", "latency_samples", "delivered_pct")


class ServerCpuClock(trio.abc.Clock):
    """Trio time = this thread's CPU time less what the non-server tasks used, plus the jumps over waits."""

    def __init__(self) -> None:
        self.offset = 0.0

    def start_clock(self) -> None:
        self.offset = 1000.0 - time.thread_time()

    def current_time(self) -> float:
        return time.thread_time() + self.offset

    def deadline_to_sleep_time(self, deadline: float) -> float:
        now = self.current_time()
        if now < deadline < float("inf"):
            self.offset += deadline - now  # nothing to run: jump to the next deadline
        return 0.0


class OthersFree(trio.abc.Instrument):
    """Takes the CPU of every task that is not the server's (``server.*``) off the clock."""

    def __init__(self, clock: ServerCpuClock) -> None:
        self.clock = clock
        self.started = 0.0

    def before_task_step(self, task: trio.lowlevel.Task) -> None:
        self.started = time.thread_time()

    def after_task_step(self, task: trio.lowlevel.Task) -> None:
        if not task.name.startswith("server."):
            self.clock.offset -= time.thread_time() - self.started


def phased_drive(server: TtesServer, phase: float) -> Any:
    """``LoadSession.drive`` with its steps at ``phase`` of a tick period after a tick, each step's requests
    stamped with the step's scheduled time."""

    async def drive(self: LoadSession, until: float) -> None:
        period = 1.0 / TICK_HZ
        k = int((trio.current_time() - server._t0) / period) + 2
        next_t = server._t0 + (k + phase) * period
        await trio.sleep_until(next_t)
        while self.now() < until:
            self.failed()
            t = next_t - self.t0
            step = self.driver.step(t)
            ch = step.changed
            if len(ch):
                probe = ~MOVING[step.previous] & self.tracker.settled(t, ch)
                self.tracker.activity(t, ch, MOVING[self.driver.activity[ch]], probe)
            await self._send(step.rows)
            next_t += 1.0 / self.cfg.step_hz
            await trio.sleep_until(max(next_t, trio.current_time()))

    return drive


async def one_phase(soldiers: int, clients: int, seconds: float, phase: float) -> dict[str, Any]:
    cfg = ServerConfig(
        host="127.0.0.1", port=0, tick_hz=TICK_HZ, throttle=0.0, max_soldiers_per_client=max(soldiers, 4096)
    )
    server = TtesServer(cfg)
    server.start_world()
    async with trio.open_nursery() as nursery:
        await nursery.start(server.serve)
        host, port = server.addresses[0]
        LoadSession.drive = phased_drive(server, phase)  # type: ignore[method-assign]
        load = LoadTestConfig(
            soldiers=soldiers, clients=clients, rate_hz=TICK_HZ, seconds=seconds, host=host, port=port
        )
        out = await _run(load, host, port, None, True)
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
        out = trio.run(
            one_phase,
            args.soldiers,
            args.clients,
            args.seconds,
            phase,
            clock=clock,
            instruments=[OthersFree(clock)],
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
