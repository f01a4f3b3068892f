"""Benchmark: the part of request -> reflecting-update latency the motion itself sets (no sockets, no CPU).

`ttes loadtest` measures request -> first reflecting update over TCP on a loaded machine. This takes the
scheduling away: one soldier on the shipped library, resting in each of the load mix's resting activities,
gets a request for every other activity at uniformly spread phases of the 30 Hz tick; the server's answer
(``SoldierManager.answer``, published between ticks) and then its ticks go through the pose board exactly as
in ``ttes server``. The delay is the time from the request to the first publish whose codes changed on the
wire: 0 when the answer already shows the request, else the time to the tick that first does (a posture
change eases in: a request just before a tick may show nothing new at that tick's time).

    python bench/bench_answer_latency.py [--phases 8] [--json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.loadtest.mix import MOVING, SPECS, Activity
from protocol.entity import make_entity_requests
from server.pose_board import PoseBoard
from server.startup import ServerWorld

HZ = 30.0
SETTLE_TICKS = 300  # 10 s at rest first
LIMIT_TICKS = 90  # give up after 3 s


def first_visible(world: ServerWorld, rest: Activity, goal: Activity, phase: float) -> float | None:
    """Seconds from the request to the first wire change (None: none within LIMIT_TICKS)."""
    m = world.manager
    assert m is not None
    table = world.sets[0].table
    board = PoseBoard(table.ndofs, table.nfigures)
    i = m.create_soldier(figure="DI.fig", weapon="AK_47.fig", now=0.0)
    board.add(i, world.table_of(i))
    a, b = SPECS[rest], SPECS[goal]
    m.apply_requests(make_entity_requests(i, a.appearance, a.weapon), 0.0)
    for k in range(SETTLE_TICKS):
        board.publish(m.tick(k / HZ), world)
    k = SETTLE_TICKS
    t_req = (k - 1 + phase) / HZ
    m.apply_requests(make_entity_requests(i, b.appearance, b.weapon, (0.0, b.speed, 0.0)), t_req)
    got = 0.0 if board.publish(m.answer(t_req, k / HZ), world, between=True) else None
    while got is None and k < SETTLE_TICKS + LIMIT_TICKS:
        if board.publish(m.tick(k / HZ), world):
            got = k / HZ - t_req
        k += 1
    m.remove_soldier(i)
    return got


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--phases", type=int, default=8, help="request phases per tick period")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    world = ServerWorld(Path(__file__).resolve().parents[1])
    world.run_startup("jack-ttes-soldier_low.jcl")
    phases = (np.arange(args.phases) + 0.5) / args.phases
    rows = []
    for rest, goal in itertools.product([a for a in Activity if not MOVING[a]], list(Activity)):
        if rest == goal:
            continue
        delays = [first_visible(world, rest, goal, float(p)) for p in phases]
        ms = [None if d is None else round(d * 1000.0, 1) for d in delays]
        rows.append({"from": rest.name, "to": goal.name, "ms": ms})
    flat = np.array([d for r in rows for d in r["ms"] if d is not None])
    out = {
        "pairs": len(rows),
        "answered_at_once_pct": round(100.0 * float((flat == 0).mean()), 1),
        "delay_ms_p50": float(np.percentile(flat, 50)),
        "delay_ms_p90": float(np.percentile(flat, 90)),
        "delay_ms_p99": float(np.percentile(flat, 99)),
        "never_within_3s": sum(d is None for r in rows for d in r["ms"]),
        "late_pairs": [r for r in rows if any(d is None or d > 0 for d in r["ms"])],
    }
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{out['pairs']} transitions x {args.phases} phases: {out['answered_at_once_pct']} % at once;")
        p50, p90, p99 = (out[f"delay_ms_p{q}"] for q in (50, 90, 99))
        print(f"delay p50 {p50:.1f}, p90 {p90:.1f}, p99 {p99:.1f} ms")
        for r in out["late_pairs"]:
            print(f"  {r['from']:>14} -> {r['to']:<14} {r['ms']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
