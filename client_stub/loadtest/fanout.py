"""The fan-out measurement over real TCP: N moving soldiers, C counting observers subscribed to all.

The server runs in its own process (spawned, every tick due: throttle 0, ``max_soldiers_per_client`` raised by
a ``--config``). One controller connection in this process creates the soldiers and sends each one request
of the ``moving`` mix (walking, running, crawling), then sends nothing more: every soldier keeps moving, so a
client should get N soldier-updates per tick. The observers (:mod:`client_stub.loadtest.observe`) run in
``procs`` other processes, count what arrives in a common window of ``time.monotonic`` and sample the
server's CPU over it; delivered % = updates received / (N × tick rate × window), per client.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import trio

from client_stub.link.spawn import ServerProcess, spawn_server
from client_stub.loadtest.client import LoadClient
from client_stub.loadtest.mix import MixDriver
from client_stub.loadtest.observe import observe
from client_stub.loadtest.session import owner_limit, server_args


@dataclass
class FanoutConfig:
    soldiers: int = 10000
    observers: int = 1
    rate_hz: float = 30.0
    seconds: float = 5.0
    warmup_s: float = 5.0  # from the observers' start: connect, full updates, soldiers under way
    version: int = 2  # the observers' protocol version (docs/PROTOCOL.md §8 / §8.5)
    procs: int = 1  # observer processes (observers split among them)
    data: str = "auto"  # the spawned server's motion library: auto | default | synthetic
    figure: str = "DI.fig"
    weapon: str = "AK_47.fig"


def run_fanout(cfg: FanoutConfig) -> dict[str, Any]:
    """Spawn the server, drive the soldiers, count in the observers; the JSON-ready result."""
    with contextlib.ExitStack() as stack:
        args = server_args(cfg.rate_hz, 0.0) + owner_limit(cfg.soldiers, stack)
        server = stack.enter_context(spawn_server(args, data=cfg.data))
        out = trio.run(_drive, cfg, server)
        out["server"] = {"pid": server.pid, "synthetic": server.synthetic}
        return out


async def _drive(cfg: FanoutConfig, server: ServerProcess) -> dict[str, Any]:
    driver = LoadClient(0, lambda *a: None, name="ttes-fanout-driver")
    async with trio.open_nursery() as nursery:
        await driver.connect(nursery, server.host, server.port)
        await driver.wait_ready(60.0)
        rate = driver.link.ready_event.tick_hz if driver.link.ready_event else cfg.rate_hz
        index, _ = await driver.create_soldiers(cfg.soldiers, cfg.figure, cfg.weapon, timeout=120.0)
        mix = MixDriver(cfg.soldiers, mix="moving", seed=1)
        rows = mix.initial()
        rows["index"] = index[rows["index"].astype(np.int64)]
        await driver.requests(rows)
        t0 = time.monotonic() + cfg.warmup_s
        t1 = t0 + cfg.seconds
        parts = await trio.to_thread.run_sync(_observe_all, cfg, server, index.tolist(), t0, t1)
        await driver.goodbye()
        nursery.cancel_scope.cancel()
    return summarise(cfg, rate, parts)


def _observe_all(
    cfg: FanoutConfig, server: ServerProcess, indices: list[int], t0: float, t1: float
) -> list[dict[str, Any]]:
    names = [f"ttes-fanout-{k}" for k in range(cfg.observers)]
    groups = [names[p :: cfg.procs] for p in range(cfg.procs) if names[p :: cfg.procs]]
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(len(groups), mp_context=ctx) as pool:
        futures = [
            pool.submit(observe, server.host, server.port, indices, g, t0, t1, version=cfg.version,
                        server_pid=server.pid)
            for g in groups
        ]  # fmt: skip
        return [f.result() for f in futures]


def summarise(cfg: FanoutConfig, rate: float, parts: list[dict[str, Any]]) -> dict[str, Any]:
    """Per client: delivered % of N × rate × window, bytes/s, bytes per update; the server's CPU (the first
    process's window) and the observers' CPU."""
    first = parts[0]
    span = first["window"][1] - first["window"][0]
    expected = cfg.soldiers * rate * span
    clients = []
    for p in parts:
        w = p["window"][1] - p["window"][0]
        for c in p["clients"]:
            clients.append({
                **c,
                "delivered_pct": round(100 * c["updates"] / (cfg.soldiers * rate * w), 2) if w > 0 else None,
                "bytes_per_s": round(c["bytes"] / w) if w > 0 else None,
                "bytes_per_update": round(c["bytes"] / c["updates"], 2) if c["updates"] else None,
                "updates_per_tick": round(c["updates"] / c["ticks"], 1) if c["ticks"] else None,
            })  # fmt: skip
    ticks = max(c["tick_span"] for c in first["clients"])
    pcts = [c["delivered_pct"] for c in clients if c["delivered_pct"] is not None]
    cpu = first["server_cpu_pct"]
    return {
        "soldiers": cfg.soldiers,
        "observers": cfg.observers,
        "procs": cfg.procs,
        "version": cfg.version,
        "tick_hz": rate,
        "window_s": round(span, 2),
        "expected_updates_per_client": round(expected),
        "delivered_pct_min": min(pcts) if pcts else None,
        "delivered_pct_mean": round(sum(pcts) / len(pcts), 2) if pcts else None,
        "server_cpu_pct": cpu,
        # CPU per server tick run in the window (the tick numbers' span: a starved server runs fewer than
        # rate x window), so a loaded machine does not inflate it
        "server_ms_per_tick": round(1000 * first["server_cpu_s"] / ticks, 2) if ticks else None,
        "server_wait_pct": first["server_wait_pct"],  # runnable but waiting for a CPU (the machine's load)
        "observer_cpu_pct": round(100 * sum(p["observer_cpu_s"] for p in parts) / span, 1) if span else None,
        "late_start": any(p["late_start"] for p in parts),
        "clients": clients,
    }
