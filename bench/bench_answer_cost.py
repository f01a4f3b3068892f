"""Benchmark: the CPU of a tick and of one answer, in-process (no sockets), at N soldiers of the load mix.

What a request waits behind on the server is CPU: the tick's sampling and publish, then the requests applied
and answered (issue 16). A batch costs about 2 ms whatever its size, so the server applies the requests of
all clients that sent at one moment as one batch (``server.pending_requests``); ``--together`` measures that
(one batch per mix step), the default each client's batch on its own (requests that land apart).
``bench_request_latency.py`` measures the latency those costs make, but one run on a shared machine varies
by more than a millisecond; this measures the costs themselves with ``time.thread_time``: per tick
``SoldierManager.tick`` and ``PoseBoard.publish``; per batch of a 10 Hz mix step (the load tester's, split
over the clients as it splits them, unless ``--together``) ``apply_requests``, the answer
(``SoldierManager.answer`` at the next tick's time) and its publish.

    python bench/bench_answer_cost.py [--soldiers 5000] [--clients 2] [--seconds 10] [--together] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.loadtest.mix import MixDriver
from server.app import TtesServer
from server.config import ServerConfig
from server.pose_board import PoseBoard
from server.soldier.manager import SoldierManager

TICK_HZ = 30.0
STEP_EVERY = 3  # ticks per mix step (10 Hz)
WARM_S = 1.0  # the first second (the initial requests settling) is not measured


def mix_world(server: TtesServer, soldiers: int) -> tuple[SoldierManager, PoseBoard, MixDriver, list[float]]:
    """``server``'s world started with ``soldiers`` of the load mix, their first requests applied at 0, on
    a clock the caller sets (``clock[0]``, simulated seconds): ``(manager, board, mix, clock)``."""
    server.start_world()
    world = server.world
    clock = [0.0]
    world.clock = lambda: clock[0]
    for _ in range(soldiers):
        world.create_soldier("DI.fig", "AK_47.fig")
    m, board = world.manager, server.board_ref.board
    assert m is not None and board is not None
    driver = MixDriver(soldiers)
    m.apply_requests(driver.initial(), 0.0)
    return m, board, driver, clock


def measure(soldiers: int, clients: int, seconds: float, together: bool = False) -> dict[str, Any]:
    cfg = ServerConfig(host="127.0.0.1", port=0, tick_hz=TICK_HZ, throttle=0.0)
    server = TtesServer(cfg)
    m, board, driver, clock = mix_world(server, soldiers)
    world = server.world
    owner = np.arange(soldiers) * clients // soldiers  # each client created a contiguous share
    ms: dict[str, list[float]] = {}
    rows: dict[str, list[int]] = {"rows": [], "answered": []}

    def timed(key: str, measured: bool, func: Callable[..., Any], *args: Any, **kw: Any) -> Any:
        t = time.thread_time()
        out = func(*args, **kw)
        if measured:
            ms.setdefault(key, []).append(1000.0 * (time.thread_time() - t))
        return out

    period = 1.0 / TICK_HZ
    for k in range(1, int(seconds * TICK_HZ) + 1):
        t = k * period
        on = t >= WARM_S
        clock[0] = t
        update = timed("tick_sample", on, m.tick, t)
        timed("tick_publish", on, board.publish, update, world)
        if k % STEP_EVERY:
            continue
        t_req = t + 0.5 * period  # between ticks
        clock[0] = t_req
        step = driver.step(t_req)
        own = owner[step.rows["index"].astype(np.int64)]
        parts = [step.rows] if together else [step.rows[own == c] for c in range(clients)]
        for part in parts:
            timed("answer_apply", on, m.apply_requests, part, t_req)
            answer = timed("answer_sample", on, m.answer, t_req, t + period)
            timed("answer_publish", on, board.publish, answer, world, between=True)
            if on:
                rows["rows"].append(len(part))
                rows["answered"].append(len(answer))
    out: dict[str, Any] = {"soldiers": soldiers, "clients": clients, "together": together}
    for key, v in ms.items():
        a = np.asarray(v)
        out[key] = {"mean": round(float(a.mean()), 3), "p50": round(float(np.median(a)), 3)}
        out[key]["p90"] = round(float(np.percentile(a, 90)), 3)
    out["answer_total_ms_p50"] = round(
        sum(out[f"answer_{s}"]["p50"] for s in ("apply", "sample", "publish")), 3
    )
    out["request_rows_p50"] = float(np.median(rows["rows"]))
    out["answered_soldiers_p50"] = float(np.median(rows["answered"]))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=5000)
    ap.add_argument("--clients", type=int, default=2)
    ap.add_argument(
        "--seconds", type=float, default=10.0, help="simulated seconds (the first is not measured)"
    )
    ap.add_argument(
        "--together",
        action="store_true",
        help="all clients' requests of a step as one batch (they landed together)",
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = measure(args.soldiers, args.clients, args.seconds, args.together)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    how = " (their requests together)" if args.together else ""
    print(f"{args.soldiers} soldiers, {args.clients} clients{how}: CPU ms (mean / p50 / p90)")
    for key in ("tick_sample", "tick_publish", "answer_apply", "answer_sample", "answer_publish"):
        r = out[key]
        print(f"  {key:15s} {r['mean']:7.3f} {r['p50']:7.3f} {r['p90']:7.3f}")
    print(
        f"  one answer: {out['answer_total_ms_p50']} ms (p50) for {out['request_rows_p50']:g} request rows, "
        f"{out['answered_soldiers_p50']:g} soldiers answered"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
