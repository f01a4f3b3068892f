"""Benchmark: the CPU of batches whose requests change what many soldiers play (issues 16 and 21).

A shard's request path is mostly its soldiers' events (a start, a stop, a snap into a posture): the manager
decides each one's next clip. This measures, with ``time.thread_time``, one in-process ``SoldierManager`` of
N soldiers (the shipped library, DI.fig) through:

* ``initial``: every soldier's first request, ``immediate`` (the load mix's: snaps into its starting
  posture, the walkers and crawlers starting at once) — a shard's creation burst;
* ``start``: every soldier (standing) asked to walk in one batch;
* ``stop``: every walking soldier asked to stand in one batch, then the ticks that take its end steps' ends
  (the stops decided at clip ends);
* ``turn``: every soldier, standing with the rifle stowed, turned 90° in one batch (turns in place);
* ``mix``: the load mix's 10 Hz steps for a few seconds, one batch each (``bench_answer_cost --together``).

    python bench/bench_decide.py [--soldiers 10000] [--json]
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

from client_stub.loadtest.mix import MixDriver
from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.app import TtesServer
from server.config import ServerConfig
from server.soldier.manager import SoldierManager

HZ = 30.0


def _manager(n: int) -> SoldierManager:
    server = TtesServer(ServerConfig(host="127.0.0.1", port=0, tick_hz=HZ, throttle=0.0))
    server.start_world()
    for _ in range(n):
        server.world.create_soldier("DI.fig", "AK_47.fig")
    assert server.world.manager is not None
    return server.world.manager


def _cpu_ms(func: Any, *args: Any) -> float:
    t = time.thread_time()
    func(*args)
    return 1000.0 * (time.thread_time() - t)


def _standing(
    n: int, speed: float, immediate: bool = False, weapon: int = WeaponState.DEPLOYED, heading: float = 0.0
) -> np.ndarray:
    h = np.radians(heading)
    velocity = (speed * np.sin(h), speed * np.cos(h), 0.0)
    return make_entity_requests(
        np.arange(n), Appearance.UPRIGHT, weapon, velocity, heading, (0.0, 0.0, 0.0), immediate
    )


def measure(n: int, mix_seconds: float = 3.0) -> dict[str, Any]:
    out: dict[str, Any] = {"soldiers": n}
    m = _manager(n)
    driver = MixDriver(n)
    out["initial_ms"] = round(_cpu_ms(m.apply_requests, driver.initial(), 0.0), 2)
    period = 1.0 / HZ
    mix = []
    for k in range(1, int(mix_seconds * HZ) + 1):
        m.tick(k * period)
        if k % 3 == 0:
            t = (k + 0.5) * period
            mix.append(_cpu_ms(m.apply_requests, driver.step(t).rows, t))
    out["mix_batch_ms_p50"] = round(float(np.median(mix)), 3)

    m = _manager(n)
    m.apply_requests(_standing(n, 0.0, True), 0.0)
    out["start_ms"] = round(_cpu_ms(m.apply_requests, _standing(n, 1.4), 0.05), 2)
    tick = 2
    for tick in range(2, 60):  # a couple of strides
        m.tick(tick * period)
    t_stop = (tick + 0.5) * period
    out["stop_ms"] = round(_cpu_ms(m.apply_requests, _standing(n, 0.0), t_stop), 2)
    ticks = [_cpu_ms(m.tick, k * period) for k in range(tick + 1, tick + 90)]
    out["stop_ticks_ms"] = round(float(np.sum(ticks)), 1)  # the end steps and their ends, 3 s
    out["still_walking"] = int((m.table.speed[:n] > 0).sum() + (m.table.mode[:n] != 0).sum())

    m = _manager(n)
    m.apply_requests(_standing(n, 0.0, True, WeaponState.STOWED), 0.0)
    m.apply_requests(_standing(n, 0.0, False, WeaponState.STOWED), 0.01)
    out["turn_ms"] = round(
        _cpu_ms(m.apply_requests, _standing(n, 0.0, False, WeaponState.STOWED, 90.0), 0.05), 2
    )
    out["turning"] = int((m.table.mode[:n] == 1).sum())  # Mode.TRANSITION: the turn clip
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=10000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = measure(args.soldiers)
    print(json.dumps(out, indent=None if args.json else 1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
