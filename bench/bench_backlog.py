"""Benchmark: request frames that queued up while the server could not run, applied one by one or as one.

On a loaded machine a starved server's sockets fill with its clients' request frames (the load mix: one
frame per client every 0.1 s). Applying a frame first brings its soldiers up to the request's time. After a
spell with no tick, that means rounds of clip and step ends over the whole spell, and those rounds cost
mostly a fixed amount per call. So frames applied one by one cost many times one batch of the same rows
(``server.pending_requests``: a client's queued frames now join one batch). This measures it in process on
the shipped library: N soldiers of the load mix, 10 s of ticks, then ``--gap`` seconds of one client's
frames with no tick, applied both ways (thread CPU)::

    python bench/bench_backlog.py [--soldiers 5000] [--gap 4]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from client_stub.loadtest.mix import MixDriver  # noqa: E402
from server.startup import ServerWorld  # noqa: E402

HZ = 30.0
STEP_S = 0.1  # the load mix's step: one request frame per client


def backlog(soldiers: int, gap: float) -> tuple[ServerWorld, list[np.ndarray], float]:
    """A world after 10 s of the load mix, and one client's frames (every other soldier) of ``gap`` s that
    queued up with no tick; the time they are applied at."""
    world = ServerWorld(ROOT, max_soldiers=soldiers + 64)
    world.run_startup("jack-ttes-soldier_low.jcl")
    world.owners.per_owner = soldiers + 64
    m = world.manager
    assert m is not None
    idx = np.array([world.create_soldier("DI.fig", "AK_47.fig", None, owner="load") for _ in range(soldiers)])
    mix = MixDriver(soldiers, seed=1)

    def rows(r: np.ndarray) -> np.ndarray:
        r = r.copy()
        r["index"] = idx[r["index"]]
        return r

    m.apply_requests(rows(mix.initial()), 0.0)
    t = 0.0
    for k in range(int(10 * HZ)):
        t = k / HZ
        m.tick(t)
        if k % 3 == 0:
            m.apply_requests(rows(mix.step(t).rows), t)
    frames = []
    for j in range(1, round(gap / STEP_S) + 1):
        r = rows(mix.step(t + j * STEP_S).rows)
        frames.append(r[r["index"] % 2 == 0])
    return world, frames, t + gap + 0.05


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--soldiers", type=int, default=5000)
    p.add_argument("--gap", type=float, default=4.0, help="seconds the server could not run")
    a = p.parse_args()
    out: dict[str, object] = {"soldiers": a.soldiers, "gap_s": a.gap}
    for mode in ("one_by_one", "one_batch"):
        world, frames, now = backlog(a.soldiers, a.gap)
        m = world.manager
        assert m is not None
        c0 = time.thread_time()
        if mode == "one_by_one":
            for f in frames:
                m.apply_requests(f, now)
        else:
            m.apply_requests(np.concatenate(frames), now)
        c1 = time.thread_time()
        m.tick(now + 1 / HZ)
        c2 = time.thread_time()
        out |= {"frames": len(frames), "rows": sum(len(f) for f in frames)}
        out[f"{mode}_apply_ms"] = round(1000 * (c1 - c0), 1)
        out[f"{mode}_next_tick_ms"] = round(1000 * (c2 - c1), 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
