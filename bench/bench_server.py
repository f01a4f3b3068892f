"""Benchmark: the whole server end to end over loopback TCP — N soldiers, a few clients, real time.

The server (``server.app.TtesServer`` on the synthetic motion library) runs in this process with trio's real
clock at ``--tick-hz``; the clients run in a child process (so their CPU is not the server's): one controller
that sets a realistic mix (resting, walking, running, backwards, crawling, posture changes) and re-sends about
2 % of the soldiers' requests every tick, plus observers; every client subscribes to every soldier and reads
as fast as it can (``--decode`` also decodes the joint updates, as an image generator would).

Reports per tick (manager advance + sample + wire conversion): mean / p50 / p99 / max milliseconds and the
ticks that overran the period; the server process's CPU share; bytes and joint-update batches per second per
client.

    python bench/bench_server.py [--soldiers 2000] [--clients 3] [--seconds 8] [--tick-hz 30] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# (share, appearance, weapon, speed m/s, backward) — the same mix as bench_server_core.py
MIX = [
    (0.35, 2, 1, 0.0, False),  # resting
    (0.05, 3, 2, 0.0, False),  # kneeling, firing
    (0.25, 2, 1, 1.4, False),  # walking
    (0.10, 2, 1, 4.0, False),  # running
    (0.05, 2, 1, 0.8, True),  # walking backwards
    (0.10, 4, 1, 0.4, False),  # crawling
    (0.10, 2, 2, 0.0, False),  # posture changes (cycled)
]
CHANGE_SHARE = 0.02


def mix_requests(n: int, rng: np.random.Generator, first: int = 0) -> np.ndarray:
    from protocol.entity import make_entity_requests

    shares = np.array([m[0] for m in MIX])
    kind = rng.choice(len(MIX), n, p=shares / shares.sum())
    app = np.array([MIX[k][1] for k in kind])
    wpn = np.array([MIX[k][2] for k in kind])
    speed = np.array([MIX[k][3] for k in kind]) * np.where([MIX[k][4] for k in kind], -1.0, 1.0)
    hdg = rng.uniform(0.0, 360.0, n)
    h = np.radians(hdg)
    vel = np.stack([speed * np.sin(h), speed * np.cos(h), np.zeros(n)], 1)
    return make_entity_requests(np.arange(first, first + n), app, wpn, vel, hdg)


# -- the client process --------------------------------------------------------------------------------------
def client_process(
    port: int, soldiers: int, clients: int, seconds: float, decode: bool, out: mp.Queue
) -> None:
    import trio

    from protocol.connection import CLIENT, NEED_DATA, Connection
    from protocol.events import EntityRequests, Hello, JointUpdates, Ready, Subscribe

    stats = [{"bytes": 0, "batches": 0, "soldier_updates": 0} for _ in range(clients)]

    async def one(k: int, start: trio.Event) -> None:
        stream = await trio.open_tcp_stream("127.0.0.1", port)
        conn = Connection(CLIENT)
        await stream.send_all(conn.send(Hello(f"bench-{k}", "controller" if k == 0 else "observer")))
        ready = False
        while not ready:
            data = await stream.receive_some(1 << 16)
            conn.receive_data(bytes(data))
            while (ev := conn.next_event()) is not NEED_DATA:
                ready = ready or isinstance(ev, Ready)
        await stream.send_all(conn.send(Subscribe(tuple(range(soldiers)))))
        rng = np.random.default_rng(k)
        if k == 0:
            await stream.send_all(conn.send(EntityRequests(mix_requests(soldiers, rng))))
        start.set()
        s = stats[k]

        async def control() -> None:  # the controller: ~2 % of the soldiers change every tick
            per_tick = max(1, int(soldiers * CHANGE_SHARE))
            while True:
                await trio.sleep(1 / 30)
                idx = rng.choice(soldiers, per_tick, replace=False)
                rows = mix_requests(per_tick, rng)
                rows["index"] = idx
                await stream.send_all(conn.send(EntityRequests(rows)))

        with trio.move_on_after(seconds):
            async with trio.open_nursery() as n:
                if k == 0:
                    n.start_soon(control)
                while True:
                    data = await stream.receive_some(1 << 20)
                    if not data:
                        break
                    s["bytes"] += len(data)
                    if decode:
                        conn.receive_data(bytes(data))
                        while (ev := conn.next_event()) is not NEED_DATA:
                            if isinstance(ev, JointUpdates):
                                s["batches"] += 1
                                s["soldier_updates"] += len(ev.indices)
                n.cancel_scope.cancel()
        await stream.aclose()

    async def main() -> None:
        async with trio.open_nursery() as n:
            for k in range(clients):
                ev = trio.Event()
                n.start_soon(one, k, ev)
                await ev.wait()

    trio.run(main)
    out.put(stats)


# -- the server (this process) ------------------------------------------------------------------------------
def instrument(server: object) -> dict[str, list[float]]:
    """Wrap the server's hot spots to split its CPU per tick: ``advance`` (manager tick: advance + sample),
    ``publish`` (PoseBoard.publish: wire conversion + quantisation + change detection), ``encode`` (every
    session's joint-update encoding, summed over clients); the rest of the process's CPU (socket writes,
    reading requests, trio's scheduling) is reported as ``other``."""
    from server.pose_board import PoseBoard
    from server.session import Session

    cost: dict[str, list[float]] = {k: [0.0, 0] for k in ("advance", "publish", "encode")}

    def timed(fn, key: str):  # type: ignore[no-untyped-def]
        def wrapper(*a, **kw):  # type: ignore[no-untyped-def]
            t = time.process_time()
            try:
                return fn(*a, **kw)
            finally:
                c = cost[key]
                c[0] += time.process_time() - t
                c[1] += 1

        return wrapper

    m = server.world.manager  # type: ignore[attr-defined]
    m.tick = timed(m.tick, "advance")
    PoseBoard.publish = timed(PoseBoard.publish, "publish")  # type: ignore[method-assign]
    Session._joint_updates = timed(Session._joint_updates, "encode")  # type: ignore[method-assign]

    return cost


def run(soldiers: int, clients: int, seconds: float, tick_hz: float, decode: bool) -> dict[str, object]:
    import trio

    from protocol.events import DEFAULT_MAX_SOLDIERS
    from server.app import TtesServer
    from server.config import ServerConfig
    from server.startup import ServerWorld, write_synthetic_data_dir

    tmp = tempfile.TemporaryDirectory(prefix="bench-server-")
    synth = write_synthetic_data_dir(tmp.name, soldiers=1)
    cfg = ServerConfig(
        port=0,
        data_dir=synth.path,
        startup_script=synth.startup_script,
        tick_hz=tick_hz,
        throttle=1 / 30,
        max_soldiers=max(DEFAULT_MAX_SOLDIERS, soldiers),
        max_requests_per_s=1e7,
    )
    t0 = time.perf_counter()
    server = TtesServer(cfg, ServerWorld(cfg.data_dir, max_soldiers=cfg.max_soldiers))
    server.start_world()
    for _ in range(soldiers - 1):
        server.world.create_soldier("DI.fig", "AK_47.fig")
    startup_s = time.perf_counter() - t0
    tick_s: list[float] = []
    plain_tick = server.run_tick

    async def timed_tick(scheduled: float | None = None) -> None:
        await plain_tick(scheduled)
        tick_s.append(server.last_tick_seconds)  # its sampling and publish, not the readers let in between

    server.run_tick = timed_tick  # type: ignore[method-assign]
    cost = instrument(server)
    result: dict[str, object] = {}

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            await nursery.start(server.serve)
            port = server.addresses[0][1]
            q: mp.Queue = mp.get_context("spawn").Queue()
            proc = mp.get_context("spawn").Process(
                target=client_process, args=(port, soldiers, clients, seconds + 3.0, decode, q)
            )
            proc.start()
            while len(server.sessions) < clients:  # wait for every client to connect and subscribe
                await trio.sleep(0.05)
            await trio.sleep(1.0)  # warm-up: the first full updates, the initial requests
            tick_s.clear()
            for v in cost.values():
                v[:] = [0.0, 0]
            bytes0 = sum(s.bytes_out for s in server.sessions.values())
            batches0 = sum(s.batches_out for s in server.sessions.values())
            over0, skipped0 = server.tick_overruns, server.ticks_skipped
            w0, c0 = time.perf_counter(), time.process_time()
            await trio.sleep(seconds)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            spent = {k: v[0] for k, v in cost.items()}
            encode_calls = cost["encode"][1]
            sessions = list(server.sessions.values())
            bytes_out = sum(s.bytes_out for s in sessions) - bytes0
            batches = sum(s.batches_out for s in sessions) - batches0
            ms = sorted(1e3 * t for t in tick_s)
            stats = await trio.to_thread.run_sync(q.get)
            await trio.to_thread.run_sync(proc.join)
            period_ms = 1e3 / tick_hz
            m = server.world.manager
            assert m is not None
            ticks = max(1, len(ms))
            split = {k: round(1e3 * v / ticks, 3) for k, v in spent.items()}
            split["other"] = round(1e3 * cpu / ticks - sum(split.values()), 3)
            result.update(
                soldiers=soldiers,
                clients=clients,
                seconds=round(wall, 2),
                tick_hz=tick_hz,
                startup_s=round(startup_s, 2),
                ticks=len(ms),
                tick_ms_mean=round(statistics.fmean(ms), 3),
                tick_ms_p50=round(ms[len(ms) // 2], 3),
                tick_ms_p99=round(ms[min(len(ms) - 1, math.ceil(0.99 * len(ms)) - 1)], 3),
                tick_ms_max=round(ms[-1], 3),
                ticks_over_period=sum(t > period_ms for t in ms),
                loop_overruns=server.tick_overruns - over0,
                ticks_skipped=server.ticks_skipped - skipped0,
                server_cpu_share=round(cpu / wall, 3),
                bytes_per_s=round(bytes_out / wall),
                bytes_per_s_per_client=round(bytes_out / wall / max(1, clients)),
                batches_per_s_per_client=round(batches / wall / max(1, clients), 1),
                bytes_received_by_clients=[s["bytes"] for s in stats],
                modes=m.status()["modes"],
                cpu_ms_per_tick=round(1e3 * cpu / ticks, 3),
                cpu_split_ms_per_tick=split,
                encode_calls_per_tick=round(encode_calls / ticks, 2),
            )
            server.shutdown()

    trio.run(main)
    tmp.cleanup()
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--soldiers", type=int, default=2000)
    ap.add_argument("--clients", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--tick-hz", type=float, default=30.0)
    ap.add_argument("--decode", action="store_true", help="clients decode every joint update")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    r = run(args.soldiers, args.clients, args.seconds, args.tick_hz, args.decode)
    if args.json:
        print(json.dumps(r))
        return 0
    print(
        f"server end to end: {r['soldiers']} soldiers, {r['clients']} clients, {r['seconds']} s at "
        f"{r['tick_hz']} Hz (start-up {r['startup_s']} s)"
    )
    print(
        f"  tick (advance + sample + wire conversion): mean {r['tick_ms_mean']} ms, p50 {r['tick_ms_p50']}, "
        f"p99 {r['tick_ms_p99']}, max {r['tick_ms_max']} ms; {r['ticks_over_period']} of {r['ticks']} ticks "
        f"over the period, {r['loop_overruns']} loop overruns"
    )
    print(
        f"  server CPU {100 * float(r['server_cpu_share']):.0f} % of one core "
        "(ticks + encoding for every client)"
    )
    print(
        f"  out: {int(r['bytes_per_s']) / 1e6:.2f} MB/s total, "
        f"{int(r['bytes_per_s_per_client']) / 1e3:.0f} kB/s "
        f"and {r['batches_per_s_per_client']} batches/s per client"
    )
    sp = r["cpu_split_ms_per_tick"]
    print(
        f"  server CPU per tick {r['cpu_ms_per_tick']} ms: "
        + ", ".join(f"{k} {v}" for k, v in sp.items())  # type: ignore[union-attr]
        + f" ms ({r['encode_calls_per_tick']} encode calls per tick)"
    )
    print(f"  modes at the end: {r['modes']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
