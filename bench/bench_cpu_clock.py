"""Benchmark: bench_shards' load on a clock that only the servers' CPU moves (issue 21): for a loaded box.

A front-end and two shards (``TtesServer`` each, the shipped library) over an in-memory fabric in one
process, driven by the load tester itself (``client_stub.loadtest``), on trio's mock clock: time stands
still while anything can run, and each server stage (``server.stage_cpu``: animate, quantise, requests,
merge, encode, fabric) moves it by the thread CPU it took divided by ``--cores`` — the servers' stages
share that many ideal cores, one at a time, and nothing else (the machine's other work, the fabric's
threads, the sockets, the load generator) costs time. So on a machine loaded by others it measures what
the servers' own CPU does to request → update latency (the neighbours still slow the CPU a little), and
what it leaves out is what a real run adds on top. A real run of 20,000 soldiers on a quiet 2-core box gave
p99 80–135 ms (docs/SCALING.md)::

    python bench/bench_cpu_clock.py [--soldiers 20000] [--seconds 10] [--cores 2]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import trio
import trio.testing

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_fabric_inprocess import Bus, MemoryFabric  # noqa: E402 (the tests' in-memory fabric)

from client_stub.loadtest.session import LoadTestConfig, _run  # noqa: E402
from server import stage_cpu  # noqa: E402
from server.app import TtesServer  # noqa: E402
from server.config import ServerConfig  # noqa: E402
from server.fabric.nodes import FrontNode, Sharding, ShardNode  # noqa: E402

KEYS: tuple[str, ...] = ("delivered_pct", "latency_ms_p50", "latency_ms_p99", "latency_ms_max")
KEYS += (
    "latency_samples",
    "probes_over_1s",
    "probes_superseded",
    "probes_over_1s_superseded",
    "probes_over_1s_sent_s",
)


def charge(clock: trio.testing.MockClock, cores: float) -> None:
    """Every outermost stage of every server moves ``clock`` by its thread CPU / ``cores``."""
    call = stage_cpu.StageCpu.__call__
    depth = [0]

    @contextlib.contextmanager
    def charged(self: stage_cpu.StageCpu, stage: str) -> Iterator[None]:
        t = time.thread_time()
        depth[0] += 1
        try:
            with call(self, stage):
                yield
        finally:
            depth[0] -= 1
            if depth[0] == 0:
                clock.jump((time.thread_time() - t) / cores)

    stage_cpu.StageCpu.__call__ = charged  # type: ignore[method-assign]


async def run(soldiers: int, seconds: float) -> dict[str, Any]:
    bus = Bus()
    token = trio.lowlevel.current_trio_token()
    room = soldiers + 64

    def server() -> TtesServer:
        return TtesServer(ServerConfig(port=0, throttle=0.0, max_soldiers=room, max_soldiers_per_client=room))

    front = server()
    front_node = FrontNode(front, MemoryFabric(bus), 2)
    shards = []
    async with trio.open_nursery() as nursery:
        await nursery.start(front.serve)
        front_node.start(token)
        for k in range(2):
            shard = server()
            node = ShardNode(shard, MemoryFabric(bus), Sharding(k, 2))
            await nursery.start(shard.serve)
            node.keep_own()
            node.start(token)
            shards.append(node)
        cfg = LoadTestConfig(soldiers=soldiers, clients=2, seconds=seconds, throttle=None, timeout_s=600.0)
        out = await _run(cfg, "127.0.0.1", front.addresses[0][1], None, False)
        nursery.cancel_scope.cancel()
    return {
        "soldiers": soldiers,
        **{k: out.get(k) for k in KEYS},
        "backlogs": [n.backlog.describe() for n in shards],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--soldiers", type=int, default=20000)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--cores", type=float, default=2.0)
    a = p.parse_args()
    clock = trio.testing.MockClock(autojump_threshold=0)
    charge(clock, a.cores)
    cpu = time.process_time()
    out = trio.run(run, a.soldiers, a.seconds, clock=clock)
    out |= {"cores": a.cores, "cpu_s": round(time.process_time() - cpu, 1)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
