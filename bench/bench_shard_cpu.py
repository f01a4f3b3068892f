"""Benchmark: one shard's CPU a tick, in-process, at N soldiers of the load mix (issue 21).

A shard of issue 21's bench (``bench_shards.py --soldiers 20000``: 2 shards) animates every other index,
10,000 soldiers, and takes the load mix's requests in batches of at most 256 rows (``server.fabric.backlog``)
between its ticks, each answered (``SoldierManager.answer``, then the board's publish). This runs that, the
soldiers on every ``--every``-th index as a shard's are, and measures thread CPU (``time.thread_time``) per
stage: ``tick_start``, ``advance`` (the clip ends), ``emit`` (sampling), ``quantise`` (the board's publish),
``apply`` (``apply_requests``), ``answer`` (its sampling and publish). ``codes`` digests every publish's codes
and versions and every apply's status: equal on two trees, the shard sent the same. For an A/B, copy this file
outside the trees and run it with ``PYTHONPATH=<tree>`` for each, both at the same time (on a loaded machine
two runs at once see the same load; alternated ones moved by ±15 %).

    python bench/bench_shard_cpu.py [--soldiers 10000] [--every 2] [--seconds 6] [--batch 256] [--json]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.loadtest.mix import MixDriver
from server.app import TtesServer
from server.config import ServerConfig

HZ = 30.0
STEP_EVERY = 3  # ticks per mix step (10 Hz)
BATCH = 256  # rows a shard takes as one batch at most (``server.fabric.backlog``)
WARM = 30  # ticks not measured


def measure(soldiers: int, every: int, seconds: float, batch: int = BATCH) -> dict[str, object]:
    n = soldiers
    top = n * every
    cfg = ServerConfig(
        port=0, tick_hz=HZ, throttle=0.0, max_soldiers=top + 64, max_soldiers_per_client=top + 64
    )
    server = TtesServer(cfg.with_overrides(max_requests_per_s=1e9))
    server.codes_only()
    server.start_world()
    world = server.world
    clock = [0.0]
    world.clock = lambda: clock[0]
    assert world.manager is not None
    for i in world.manager.table.live.tolist():  # the start-up script's soldiers: a shard has none
        world.remove_soldier(int(i), "bench")
    home = np.arange(n, dtype=np.int64) * every  # slot -> the shard's index
    for i in home.tolist():
        world.create_soldier("DI.fig", "AK_47.fig", int(i))
    m, board = world.manager, server.board_ref.board
    assert m is not None and board is not None
    driver = MixDriver(n)

    def rows_of(r: np.ndarray) -> np.ndarray:
        r = r.copy()
        r["index"] = home[r["index"].astype(np.int64)]
        return r

    m.apply_requests(rows_of(driver.initial()), 0.0)
    digest = hashlib.sha256()
    keys = ("tick_start", "advance", "emit", "quantise", "apply", "answer")
    ms = dict.fromkeys(keys, 0.0)
    batches = rows_total = 0

    def record() -> None:
        digest.update(board.codes[:top].tobytes())
        digest.update(board.version[:top].tobytes())

    ticks = int(seconds * HZ)
    for k in range(1, ticks + WARM + 1):
        on = k > WARM
        t = k / HZ
        clock[0] = t
        c0 = time.thread_time()
        ending = m.tick_start(t)
        c1 = time.thread_time()
        m.tick_advance_rows(ending)
        c2 = time.thread_time()
        update = m.tick_emit(t)
        c3 = time.thread_time()
        board.publish(update, world)
        c4 = time.thread_time()
        record()
        if on:
            for key, a, b in zip(keys, (c0, c1, c2, c3), (c1, c2, c3, c4), strict=False):
                ms[key] += b - a
        if k % STEP_EVERY:
            continue
        t_req = t + 0.5 / HZ
        clock[0] = t_req
        rows = rows_of(driver.step(t_req).rows)
        for a in range(0, len(rows), batch):
            part = rows[a : a + batch]
            c0 = time.thread_time()
            status = m.apply_requests(part, t_req)
            c1 = time.thread_time()
            answer = m.answer(t_req, t + 1 / HZ)
            board.publish(answer, world, between=True)
            c2 = time.thread_time()
            digest.update(np.asarray(status).tobytes())
            record()
            if on:
                ms["apply"] += c1 - c0
                ms["answer"] += c2 - c1
                batches += 1
                rows_total += len(part)
    out: dict[str, object] = {"soldiers": n, "every": every, "ticks": ticks, "batch": batch}
    out.update({f"{key}_ms_per_tick": round(1000 * v / ticks, 3) for key, v in ms.items()})
    out["total_ms_per_tick"] = round(1000 * sum(ms.values()) / ticks, 3)
    out.update(batches=batches, rows=rows_total, codes=digest.hexdigest()[:16])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=10000)
    ap.add_argument("--every", type=int, default=2, help="the shard's soldiers are every N-th index")
    ap.add_argument("--seconds", type=float, default=6.0, help="measured simulated seconds (after 1 s)")
    ap.add_argument("--batch", type=int, default=BATCH, help="rows of a batch at most")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = measure(args.soldiers, args.every, args.seconds, args.batch)
    print(json.dumps(out) if args.json else json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
