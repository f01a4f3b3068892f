"""Benchmark: the CPU per tick of the pose boards of a cluster, in one process: the shards' sampling and
publish (quantise) and a front-end's merge and encodes, on N soldiers of the load mix (issue 21).

The soldiers tick at 30 Hz of simulated time with the load mix's requests (``client_stub.loadtest.mix``);
their codes go out as two shards' batches (even and odd indices, as ``Sharding.home`` splits them, through
``encode_batch``/``decode_batch``), which a front-end's board merges one at a time (``nodes.merge``), and
after each of them two clients, each subscribed to half the soldiers, encode what changed. Thread CPU
(``time.thread_time``), so a loaded machine disturbs it little; for an A/B run it on both trees, alternated.
``sha`` digests every client byte, ``codes`` the shards' codes and versions: equal on two trees, the
clients received the same. The shards' numbers are for all N soldiers (both shards' together). For an
A/B on another tree, copy this file and ``bench_answer_cost.py`` (its ``mix_world``) there.

    python bench/bench_board_cpu.py [--soldiers 20000] [--ticks 90] [--json]
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

from bench.bench_answer_cost import mix_world
from protocol.connection import CLIENT, NEED_DATA, PAUSED, Connection
from protocol.events import Hello, Subscribe
from server.app import TtesServer
from server.config import ServerConfig
from server.fabric.batch import Batch, decode_batch, encode_batch
from server.fabric.nodes import merge
from server.pose_board import BoardRef, PoseBoard
from server.session import Session

WARM = 30  # ticks not measured: the first full updates, the mix getting under way


def measure(soldiers: int, ticks: int) -> dict[str, object]:
    n = soldiers
    cfg = ServerConfig(port=0, throttle=0.0, max_soldiers=n + 64, max_soldiers_per_client=n + 64)
    server = TtesServer(cfg.with_overrides(max_requests_per_s=1e9))
    if hasattr(server, "codes_only"):
        server.codes_only()  # as a shard's (on a tree that has it)
    m, board, driver, clock = mix_world(server, n)
    world = server.world
    front = BoardRef()
    front.board = PoseBoard(board.ndofs, board.nfigs, n)
    sessions = [_client(server, front, range(k * n // 2, (k + 1) * n // 2), f"c{k}") for k in range(2)]
    alive = np.ones(n, bool)
    sha, codes = hashlib.sha256(), hashlib.sha256()
    ms: dict[str, float] = dict.fromkeys(("animate", "quantise", "merge", "encode"), 0.0)
    for k in range(1, ticks + WARM + 1):
        t = k / 30
        clock[0] = t
        cpu = [time.thread_time()]
        update = m.tick(t)
        cpu.append(time.thread_time())
        board.publish(update, world)
        cpu.append(time.thread_time())
        if k % 3 == 0:  # the mix's requests, between ticks (10 Hz)
            m.apply_requests(driver.step(t + 1 / 60).rows, t + 1 / 60)
        codes.update(board.codes[:n].tobytes())
        codes.update(board.version[:n].tobytes())
        rows = np.arange(n) if k % 30 == 1 else np.flatnonzero(board.version[:n] == board.serial)
        merged = encoded = 0.0
        for shard in (0, 1):
            r = rows[rows % 2 == shard]
            tables, quantised = board.table_of[r].astype(np.uint8), board.codes[r].astype(np.uint16)
            batch = decode_batch(encode_batch(Batch(shard, 2, k, k, 0.0, r, tables, quantised, k % 30 == 1)))
            a = time.thread_time()
            merge(front.board, [batch], k, alive)
            b = time.thread_time()
            written = [s.take_output() for s in sessions]
            encoded += time.thread_time() - b
            merged += b - a
            for data in written:
                sha.update(data)
        if k > WARM:
            for key, v in zip(ms, (cpu[1] - cpu[0], cpu[2] - cpu[1], merged, encoded), strict=True):
                ms[key] += v
    out: dict[str, object] = {"soldiers": n, "ticks": ticks}
    out.update({f"{key}_ms_per_tick": round(1000 * v / ticks, 3) for key, v in ms.items()})
    out.update(sha=sha.hexdigest()[:16], codes=codes.hexdigest()[:16])
    return out


def _client(server: TtesServer, ref: BoardRef, indices: range, name: str) -> Session:
    """A session on the front-end's board ``ref`` subscribed to ``indices`` (its client wired in memory)."""
    s = Session(server.world, ref, server.config, name)
    c = Connection(CLIENT, decode_updates=False)
    s.feed(c.send(Hello(name, "observer")))
    c.receive_data(s.take_output())
    while c.next_event() not in (NEED_DATA, PAUSED):
        pass
    s.feed(c.send(Subscribe(tuple(indices))))
    return s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=20000)
    ap.add_argument("--ticks", type=int, default=90, help="measured ticks (after 30 of warm-up)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = measure(args.soldiers, args.ticks)
    print(json.dumps(out) if args.json else json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
