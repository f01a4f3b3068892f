"""Benchmark: are a load test's probes answered when a shard's backlog holds several messages (issue 21)?

In one process, no sockets, on a simulated clock: a shard (one of one) with N soldiers of the load mix
(``client_stub.loadtest.mix``) ticks at 30 Hz; every 0.1 s the mix's step goes into its backlog as one
front-end message, and the shard takes its backlog only every ``--depth`` steps (a shard that is that many
messages behind: its backlog coalesces them). The load tester's own bookkeeping
(``client_stub.loadtest.stats.Tracker``) marks the probes (a soldier at rest asked to do something else)
and takes a soldier's board change as the update a client would get. Reported: probes, how many were
answered in time (within the backlog's wait and 0.5 s), later, and how many never were. The CPU does not
matter here (the clock is simulated), so on a loaded machine it measures what it does on a quiet one::

    python bench/bench_shard_probes.py [--soldiers 3000] [--seconds 20] [--depth 1 2 4]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.bench_shard_backlog import _NoFabric
from client_stub.loadtest.mix import MOVING, MixDriver
from client_stub.loadtest.stats import Tracker
from server.app import TtesServer
from server.config import ServerConfig
from server.fabric import requests as req
from server.fabric.nodes import Sharding, ShardNode

TICK_HZ = 30.0
STEP_S = 0.1  # the load tester's step (10 Hz)


def measure(soldiers: int, seconds: float, depth: int, seed: int = 1) -> dict[str, Any]:
    server = TtesServer(ServerConfig(host="127.0.0.1", port=0, tick_hz=TICK_HZ, throttle=0.0))
    server.start_world()
    world = server.world
    clock = [0.0]
    world.clock = lambda: clock[0]
    server.now = lambda: clock[0]  # type: ignore[method-assign]
    first = [world.create_soldier("DI.fig", "AK_47.fig") for _ in range(soldiers)]
    index = np.asarray(first, np.int64)  # slot -> soldier
    node = ShardNode(server, _NoFabric(), Sharding(0, 1))
    driver = MixDriver(soldiers, seed=seed)
    tracker = Tracker(TICK_HZ, 1)
    tracker.grow(soldiers, np.zeros(soldiers, np.int64))
    slot_of = np.full(int(index.max()) + 1, -1, np.int64)
    slot_of[index] = np.arange(soldiers)
    board_serial = [0]

    def put(rows: np.ndarray) -> None:
        rows = rows.copy()
        rows["index"] = index[rows["index"].astype(np.int64)]
        node.backlog.put(req.decode(req.pack([req.requests(rows)])))

    def seen(t: float) -> None:
        """What a client would get now: the soldiers whose codes changed since the last look."""
        board = server.board_ref.board
        if board is None:
            return
        changed = np.flatnonzero(board.valid & (board.version > board_serial[0]))
        board_serial[0] = board.serial
        slots = slot_of[changed[changed < len(slot_of)]]
        tracker.batch(t, 0, board.tick, slots[slots >= 0], 0)

    put(driver.initial())
    node.take_turn()
    steps, next_step, tick = 0, STEP_S, 0
    cpu0 = time.process_time()
    while clock[0] < seconds:
        tick += 1
        t = tick / TICK_HZ
        while next_step <= t:  # the mix's steps due before this tick (each at its own time)
            clock[0] = next_step
            step = driver.step(next_step)
            ch = step.changed
            if len(ch):
                was_static = ~MOVING[step.previous]
                probe = was_static & tracker.settled(next_step, ch) & (next_step > 2.0)
                tracker.activity(next_step, ch, MOVING[driver.activity[ch]], probe)
            put(step.rows)
            steps += 1
            if steps % depth == 0:
                while node.backlog:
                    node.take_turn()
                seen(next_step)
            next_step += STEP_S
        clock[0] = t
        server.tick(t)
        seen(t)
    cpu = time.process_time() - cpu0
    rec = tracker.rec.arrays()
    lat = rec["latency"]
    sent = rec["probe_sent"]
    sent = sent[sent < seconds - 2.0]  # those that had two seconds to be answered
    answered = lat[rec["latency_time"] - lat < seconds - 2.0]
    due = depth * STEP_S + 0.5  # the backlog's wait, and a tick and a half to spare
    return {
        "soldiers": soldiers,
        "seconds": seconds,
        "depth": depth,
        "probes": len(sent),
        "answered_in_time": int((answered <= due).sum()),
        "answered_late": int((answered > due).sum()),
        "never": len(sent) - len(answered),
        "late_ms": sorted(round(1000 * float(x)) for x in answered[answered > due])[:12],
        "coalesced": node.backlog.coalesced,
        "cpu_s": round(cpu, 1),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--soldiers", type=int, default=3000)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--depth", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args()
    for d in a.depth:
        print(json.dumps(measure(a.soldiers, a.seconds, d, a.seed)), flush=True)


if __name__ == "__main__":
    main()
