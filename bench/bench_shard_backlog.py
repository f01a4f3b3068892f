"""Benchmark: what a shard's backlog of fabric requests costs to take after it fell behind (issue 21).

In one process, no sockets: a shard (one of one) with N soldiers of the load mix gets ``--messages``
front-end messages at once (each a 10 Hz step of the load tester's mix: the rows that changed), as when it
fell that many messages behind, then takes turns (``ShardNode.take_turn``) until none is left. Reported:
the thread CPU of all the turns, how many turns and batches applied, the rows queued at the peak. Runs
against whichever ``server`` is on the path, so the same command measures a checkout before the change
(``take_turn(deque)``: every message applied, in order) and after (``ShardNode.backlog``: each soldier's
newest request, consecutive rows in one batch)::

    PYTHONPATH=/path/to/checkout python bench/bench_shard_backlog.py [--soldiers 5000] [--messages 300]
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.loadtest.mix import MixDriver
from server.app import TtesServer
from server.config import ServerConfig
from server.fabric import requests as req
from server.fabric.nodes import Sharding, ShardNode


class _NoFabric:
    engine = "none"

    def publisher(self, topic: str, kind: object, on_match: object = None) -> Any:
        return lambda data: None

    def subscribe(self, *args: object) -> None: ...
    def announce(self, key: str) -> None: ...
    def watch(self, *args: object) -> None: ...
    def close(self) -> None: ...


def measure(soldiers: int, messages: int, merge_rows: int | None = None) -> dict[str, Any]:
    server = TtesServer(ServerConfig(host="127.0.0.1", port=0, tick_hz=30.0, throttle=0.0))
    server.start_world()
    world = server.world
    clock = [0.0]
    world.clock = lambda: clock[0]
    for _ in range(soldiers):
        world.create_soldier("DI.fig", "AK_47.fig")
    m = world.manager
    assert m is not None
    driver = MixDriver(soldiers)
    m.apply_requests(driver.initial(), 0.0)
    node = ShardNode(server, _NoFabric(), Sharding(0, 1))
    data = [req.pack([req.requests(driver.step(0.1 * (k + 1)).rows)]) for k in range(messages)]
    sent_rows = sum(len(req.decode(d)[0]["rows"]) for d in data)
    clock[0] = 0.1 * messages
    batches = [0]
    apply = world.apply_requests

    def counted(rows: np.ndarray) -> np.ndarray:
        batches[0] += 1
        return apply(rows)

    world.apply_requests = counted  # type: ignore[method-assign]
    backlog = getattr(node, "backlog", None)
    if backlog is not None and merge_rows is not None:
        backlog.merge_rows = merge_rows
    ops: collections.deque[req.Op] = collections.deque()
    for d in data:  # what the fabric's thread queues (decoding included)
        if backlog is not None:
            backlog.put(req.decode(d))
        else:
            ops.extend(req.decode(d))
    peak = len(backlog) if backlog is not None else sum(len(op["rows"]) for op in ops)
    turn_ms = []
    while backlog if backlog is not None else ops:
        t = time.thread_time()
        node.take_turn() if backlog is not None else node.take_turn(ops)  # type: ignore[call-arg]
        turn_ms.append(1000.0 * (time.thread_time() - t))
    cpu = sum(turn_ms) / 1000.0
    turns = len(turn_ms)
    return {
        "soldiers": soldiers,
        "messages": messages,
        "rows_sent": sent_rows,
        "rows_queued_peak": peak,
        "turns": turns,
        "batches": batches[0],
        "cpu_ms": round(1000.0 * cpu, 1),
        "cpu_ms_per_message": round(1000.0 * cpu / messages, 3),
        "turn_ms_p50_max": [round(float(np.median(turn_ms)), 1), round(max(turn_ms), 1)],
        "backlog": backlog.describe() if backlog is not None else "unbounded deque",
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--soldiers", type=int, default=5000)
    p.add_argument("--messages", type=int, default=300)
    p.add_argument("--merge-rows", type=int, help="the backlog's MERGE_ROWS (after the change only)")
    p.add_argument("--json", action="store_true")
    a = p.parse_args()
    out = measure(a.soldiers, a.messages, a.merge_rows)
    print(json.dumps(out) if a.json else "\n".join(f"{k}: {v}" for k, v in out.items()))


if __name__ == "__main__":
    main()
