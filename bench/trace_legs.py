"""Where a request's time goes through a front-end and its shards, under load (issue 21; ``server/trace.py``).

``bench_shards.py --trace N`` starts the cluster with ``TTES_TRACE`` set, and a probe client (its own
process: :func:`probe_client`) creates N soldiers (indices 0..N-1, traced) before the load generator
creates the rest; it then sends one kneel or stand request at a time and writes ``index sent received``
per request. :func:`legs` joins those with the servers' stamps: for each request the first stamp of each
stage, in path order, at or after the previous one's; a leg is the time between two stages.
"""

from __future__ import annotations

import collections
import sys
import time
from bisect import bisect_left
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trio

# the path of a request and its answer, in order (server/trace.py's stages, the probe's at both ends)
STAGES = (
    "client_send",  # the probe sends ENTITY_REQUESTS
    "fe_request",  # the front-end's reader handled it (checked, queued for the shard)
    "fe_publish",  # the front-end put it on the fabric
    "shard_arrive",  # the shard's fabric thread received it
    "shard_take",  # the shard's loop takes it (applies it, answers)
    "shard_publish",  # the shard's first batch with the soldier after that (note: answer or tick)
    "fe_arrive",  # the front-end's fabric thread received that batch
    "fe_merge",  # the front-end's loop merged it into its board (note: fed, tick, or first: ahead of ticks)
    "encode",  # the probe's writer encoded the soldier's update
    "sent",  # ... and wrote it to the socket
    "client_recv",  # the probe read it
)
NOTED = ("shard_publish", "fe_merge")


def read_stamps(paths: list[Path]) -> dict[tuple[str, int], tuple[list[float], list[str]]]:
    """(stage, index) -> (sorted times, their notes) from the servers' trace files."""
    rows: dict[tuple[str, int], list[tuple[float, str]]] = collections.defaultdict(list)
    for path in paths:
        for line in path.read_text().splitlines():
            t, stage, idx, *note = line.split()
            for i in idx.split(","):
                rows[(stage, int(i))].append((float(t), note[0] if note else ""))
    out = {}
    for key, stamps in rows.items():
        stamps.sort()
        out[key] = ([t for t, _ in stamps], [n for _, n in stamps])
    return out


def legs(probes: list[tuple[int, float, float]], stamps: dict) -> dict[str, object]:
    """Per leg (``a→b``) p50/p90/p99 ms over the probe requests, and how often each noted stage's note."""
    per_leg: dict[str, list[float]] = collections.defaultdict(list)
    notes: dict[str, collections.Counter[str]] = {s: collections.Counter() for s in NOTED}
    for index, sent, received in probes:
        prev_stage, prev = "client_send", sent
        for stage in STAGES[1:-1]:
            times, tags = stamps.get((stage, index), ([], []))
            k = bisect_left(times, prev - 1e-6)
            if k == len(times) or times[k] > received + 1e-3:
                continue  # not seen on this request's path (e.g. no answer batch: the tick's carried it)
            per_leg[f"{prev_stage}→{stage}"].append(times[k] - prev)
            if stage in notes:
                notes[stage][tags[k]] += 1
            prev_stage, prev = stage, times[k]
        per_leg[f"{prev_stage}→client_recv"].append(received - prev)
        per_leg["total"].append(received - sent)
    order = {f"{a}→{b}": i for i, (a, b) in enumerate(_pairs())}
    table = {}
    for leg in sorted(per_leg, key=lambda name: order.get(name, len(order))):
        ms = 1000 * np.asarray(per_leg[leg])
        table[leg] = {
            "n": len(ms),
            **{f"p{q}": round(float(np.percentile(ms, q)), 2) for q in (50, 90, 99)},
            "mean": round(float(ms.mean()), 2),
        }
    return {"requests": len(probes), "legs_ms": table, "notes": {s: dict(c) for s, c in notes.items()}}


def _pairs() -> list[tuple[str, str]]:
    return [(a, b) for i, a in enumerate(STAGES) for b in STAGES[i + 1 :]]


def probe_client(port: int, n: int, out: Path) -> None:
    """The probe's process: N soldiers, then one request at a time until killed (one line each)."""
    with out.open("w", buffering=1) as f:
        trio.run(
            probe_requests,
            port,
            n,
            10**9,
            lambda i, sent, received: f.write(f"{i} {sent:.6f} {received:.6f}\n"),
            lambda idx: print("ready", max(idx), flush=True),
        )


async def probe_requests(
    port: int,
    n: int,
    requests: int,
    answered: Callable[[int, float, float], object],
    ready: Callable[[list[int]], object] = lambda idx: None,
) -> None:
    """A client of N soldiers (``ready`` with their indices once made) sends ``requests`` posture requests
    one at a time (kneel, then stand, soldier after soldier) and calls ``answered(index, sent, received)``
    at each soldier's first update after its request (monotonic clock; none within 5 s: not called)."""
    from client_stub.link.client import Client
    from protocol.entity import Appearance, make_entity_requests

    arrived: dict[int, float] = {}

    def updates(when: float, tick: int, indices: np.ndarray, size: int, event: object) -> None:
        now = time.monotonic()
        for i in indices.tolist():
            arrived.setdefault(i, now)

    async with trio.open_nursery() as nursery:
        c = Client("probe", on_updates=updates)
        await c.open(nursery, "127.0.0.1", port, soldierprefix=None)
        idx = [(await c.create_soldier("DI.fig", "AK_47.fig")).index for _ in range(n)]
        c.subscribe(idx)
        ready(idx)
        await trio.sleep(2.0)  # every soldier's first update, and settled
        for rep in range(requests):
            i = idx[rep % n]
            posture = Appearance.KNEEL if (rep // n) % 2 == 0 else Appearance.UPRIGHT
            arrived.pop(i, None)
            sent = time.monotonic()
            c.send_requests(make_entity_requests([i], appearance=posture))
            with trio.move_on_after(5.0):
                while i not in arrived:
                    await trio.sleep(0.001)
            if i in arrived:
                answered(i, sent, arrived[i])
            await trio.sleep(0.05)
        await c.aclose()
        nursery.cancel_scope.cancel()


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    probe_client(int(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3]))
