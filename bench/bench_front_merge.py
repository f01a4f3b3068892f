"""Benchmark: a front-end's merge CPU per tick, every soldier merged into the board (before) or only those
its clients watch (after: ``server.fabric.watch``), on the same batches, alternating, in one process.

Per tick each of N shards sends a batch of its soldiers whose codes changed (``--moving`` of them, new
random codes; the update table's 64 fields) and every 30th tick a key batch of all of them, as
``ShardNode.publish`` does; the front-end decodes and merges them (``nodes.merge``) into its pose board.
Its clients watch ``--watched`` soldiers (e.g. 4 clients x 2,000 of 32,000). Thread CPU, so a loaded
machine disturbs it little. Also the cost of a subscription to ``--subscribe`` unwatched soldiers.

``blocks``: the same ticks as a shard sends them since blocktopic21, one batch per ``--block`` of indices
(on the block's topic), of which the front-end hears and decodes only the blocks its clients watch (the
watched soldiers are the lowest indices, as one front-end's share); with the bytes per tick it receives.

    python bench/bench_front_merge.py --soldiers 32000 48000 --shards 2 --watched 8000 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from server.fabric.batch import Batch, decode_batch, encode_batch
from server.fabric.nodes import KEY_EVERY, merge
from server.fabric.watch import Watch
from server.pose_board import PoseBoard

FIELDS = 64


def stream(
    soldiers: int, shards: int, moving: float, ticks: int, seed: int, block: int = 0, heard: int = 0
) -> list[list[bytes]]:
    """Each tick's batches (one per shard; with ``block``, one per shard and block of indices, of the
    blocks below index ``heard`` only: those a front-end hears), as the shards send them."""
    rng = np.random.default_rng(seed)
    out = []
    for t in range(ticks):
        tick = []
        for k in range(shards):
            idx = np.arange(k, soldiers, shards)
            key = t % KEY_EVERY == 0
            if not key:
                idx = idx[rng.random(len(idx)) < moving]
            codes = rng.integers(0, 4096, (len(idx), FIELDS), dtype=np.uint16)
            tables = np.ones(len(idx), np.uint8)
            if not block:
                tick.append(encode_batch(Batch(k, shards, t, t, 0.0, idx, tables, codes, key)))
                continue
            for b in range(-(-heard // block)):
                at = (idx >= b * block) & (idx < (b + 1) * block)
                if at.any():
                    part = Batch(k, shards, t, t, 0.0, idx[at], tables[at], codes[at], key, b)
                    tick.append(encode_batch(part))
        out.append(tick)
    return out


def run(batches: list[list[bytes]], soldiers: int, watched: int | None) -> tuple[float, int]:
    """Thread CPU ms per tick of decode + merge; and the rows published into the board."""
    board = PoseBoard(3, 2, soldiers)
    alive = np.ones(soldiers, bool)
    watch = None
    if watched is not None:
        watch = Watch(soldiers)
        watch.watch(np.arange(watched), board, alive)
    t0 = time.thread_time()
    for t, tick in enumerate(batches, 1):
        merge(board, [decode_batch(d) for d in tick], t, alive, watch)
    ms = (time.thread_time() - t0) * 1e3 / len(batches)
    return ms, board.rows_published


def subscribe_ms(batches: list[list[bytes]], soldiers: int, watched: int, count: int) -> float:
    board, alive, watch = PoseBoard(3, 2, soldiers), np.ones(soldiers, bool), Watch(soldiers)
    watch.watch(np.arange(watched), board, alive)
    for t, tick in enumerate(batches, 1):
        merge(board, [decode_batch(d) for d in tick], t, alive, watch)
    t0 = time.thread_time()
    watch.watch(np.arange(watched, watched + count), board, alive)
    return (time.thread_time() - t0) * 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, nargs="+", default=[32000, 48000])
    ap.add_argument("--shards", type=int, default=2)
    ap.add_argument("--watched", type=int, default=8000)
    ap.add_argument("--moving", type=float, default=0.6, help="share of soldiers whose codes change a tick")
    ap.add_argument("--ticks", type=int, default=60)
    ap.add_argument("--rounds", type=int, default=3, help="before/after pairs, alternated")
    ap.add_argument("--subscribe", type=int, default=2000)
    ap.add_argument("--block", type=int, default=4096, help="soldier indices per pose topic")
    args = ap.parse_args()
    results = []
    for n in args.soldiers:
        batches = stream(n, args.shards, args.moving, args.ticks, seed=n)
        blocked = stream(
            n, args.shards, args.moving, args.ticks, seed=n, block=args.block, heard=args.watched
        )
        row: dict[str, object] = {"soldiers": n, "shards": args.shards, "watched": args.watched}
        before, after, blocks = [], [], []
        for _ in range(args.rounds):
            ms, rows_all = run(batches, n, None)
            before.append(round(ms, 2))
            ms, rows_watched = run(batches, n, args.watched)
            after.append(round(ms, 2))
            ms, _ = run(blocked, n, args.watched)
            blocks.append(round(ms, 2))
        sub = subscribe_ms(batches, n, args.watched, args.subscribe)
        row |= {
            "merge_ms_per_tick_before": before,
            "merge_ms_per_tick_after": after,
            f"merge_ms_per_tick_blocks_{args.block}": blocks,
            "bytes_per_tick_whole_blocks": [
                sum(map(len, batches[1])),
                sum(map(len, blocked[1])),
            ],
            "rows_published_per_tick": [rows_all // args.ticks, rows_watched // args.ticks],
            f"subscribe_{args.subscribe}_ms": round(sub, 2),
            "load": round(os.getloadavg()[0], 1),
        }
        results.append(row)
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
