"""Benchmark: a single server's request → update latency on a clock only its own CPU moves (issue 16's spike).

``ttes loadtest`` on this 2-core machine, shared with other sessions' builds, shows probes answered after
seconds; each one's account (``worst_probes``) says the server's main thread waited on a run queue for most
of the wait. This takes the machine's other load out: one ``TtesServer`` (the shipped library) and the load
tester itself (``client_stub.loadtest``) in one process on trio's mock clock, which stands still while
anything can run and moves by each server stage's thread CPU / ``--cores`` (``bench_cpu_clock.charge``). A
peer can misbehave beside the load: ``--peer burst`` creates ``--burst`` soldiers in one write every 3 s and
removes them again; ``--peer stall`` subscribes to every soldier and stops reading for 2 s of every 3. If such
a peer stalled the tick, the probes would show it here, where nothing else can::

    python bench/bench_spike.py [--soldiers 5000] [--clients 2] [--seconds 10] [--peer none|burst|stall]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import trio
import trio.testing

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_cpu_clock import charge  # noqa: E402

from client_stub.loadtest.session import LoadTestConfig, _run  # noqa: E402
from protocol import events as ev  # noqa: E402
from protocol.connection import CLIENT, NEED_DATA, Connection  # noqa: E402
from server.app import TtesServer  # noqa: E402
from server.config import ServerConfig  # noqa: E402

KEYS: tuple[str, ...] = ("delivered_pct", "latency_ms_p50", "latency_ms_p99", "latency_ms_max")
KEYS += ("latency_samples", "probes_over_1s", "probes_over_1s_causes", "server_tick_hz", "worst_probes")
PERIOD_S = 3.0  # the peer's cycle


async def _events(stream: trio.SocketStream, conn: Connection) -> list[ev.Event]:
    """The events of the next read (``[]`` at the end of the stream)."""
    data = await stream.receive_some(1 << 20)
    conn.receive_data(bytes(data))
    out: list[ev.Event] = []
    while (e := conn.next_event()) is not NEED_DATA:
        assert isinstance(e, ev.Event)
        out.append(e)
    return out if data else []


async def peer(port: int, kind: str, soldiers: int, burst: int) -> None:
    """A misbehaving client (see the module) until cancelled."""
    stream = await trio.open_tcp_stream("127.0.0.1", port)
    conn = Connection(CLIENT, decode_updates=False)
    role = "observer" if kind == "stall" else "controller"
    await stream.send_all(conn.send(ev.Hello(f"spike-{kind}", role)))
    while not any(isinstance(e, ev.Ready) for e in await _events(stream, conn)):
        pass
    if kind == "stall":
        await stream.send_all(conn.send(ev.Subscribe(tuple(range(soldiers + 64)))))
        while True:
            with trio.move_on_after(PERIOD_S - 2.0):
                while await _events(stream, conn):
                    pass
            await trio.sleep(2.0)  # not reading
    rid = 0
    while True:
        await trio.sleep(PERIOD_S)
        asks = [ev.CreateSoldier(rid + k) for k in range(burst)]
        rid += burst
        await stream.send_all(b"".join(conn.send(a) for a in asks))
        made: list[int] = []
        while len(made) < burst:
            for e in await _events(stream, conn):
                if isinstance(e, ev.SoldierCreated | ev.Error):
                    made.append(e.index if isinstance(e, ev.SoldierCreated) else -1)
        await trio.sleep(1.0)
        await stream.send_all(b"".join(conn.send(ev.RemoveSoldier(i)) for i in made if i >= 0))


async def run(soldiers: int, clients: int, seconds: float, kind: str, burst: int) -> dict[str, Any]:
    room = soldiers + burst + 64
    server = TtesServer(ServerConfig(port=0, throttle=0.0, max_soldiers=room, max_soldiers_per_client=room))
    async with trio.open_nursery() as nursery:
        await nursery.start(server.serve)
        port = server.addresses[0][1]
        if kind != "none":
            nursery.start_soon(peer, port, kind, soldiers, burst)
        cfg = LoadTestConfig(
            soldiers=soldiers, clients=clients, seconds=seconds, throttle=None, timeout_s=600.0
        )
        out = await _run(cfg, "127.0.0.1", port, None, False)
        nursery.cancel_scope.cancel()
    return {"soldiers": soldiers, "clients": clients, "peer": kind, **{k: out.get(k) for k in KEYS}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--soldiers", type=int, default=5000)
    p.add_argument("--clients", type=int, default=2)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--cores", type=float, default=1.0, help="ideal cores the server's stages share")
    p.add_argument("--peer", choices=("none", "burst", "stall"), default="none")
    p.add_argument("--burst", type=int, default=2000, help="soldiers a burst creates in one write")
    a = p.parse_args()
    clock = trio.testing.MockClock(autojump_threshold=0)
    charge(clock, a.cores)
    cpu = time.process_time()
    out = trio.run(run, a.soldiers, a.clients, a.seconds, a.peer, a.burst, clock=clock)
    out |= {"cores": a.cores, "cpu_s": round(time.process_time() - cpu, 1)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
