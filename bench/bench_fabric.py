"""Benchmark: the two candidate fabrics of issue 21 on one two-shard workload (docs/SCALING.md).

Per engine (Eclipse Zenoh, Eclipse Cyclone DDS; unicast on 127.0.0.1, no multicast) three processes: one
subscriber (the front-end's part: it takes every batch and merges its codes into one array, as the
front-end's pose board does) and two publishers (shards), each publishing one batch per tick at ``--hz`` of
its share of ``--soldiers`` soldiers' quantised codes (the shipped update table: 64 fields of at most 16
bits, uint16 per field, ``server.fabric.batch``). The codes change every tick. Reports per engine: publish →
receive latency p50/p99 (ms, one host's monotonic clock), CPU ms per tick of a publisher (encode + publish)
and of the subscriber (receive + decode + merge, per tick of both shards), batches lost (after a warm-up),
and the adapter's code size (lines of ``server/fabric/*_node.py``).

``--block N``: each tick as one batch per block of N soldier indices on the block's topic (what a shard
sends a front-end that hears its blocks), against one batch a tick (0, the default: a front-end that hears
the shard whole) — the per-message cost of the per-block batches.

    python bench/bench_fabric.py [--soldiers 10000] [--seconds 10] [--hz 30] [--engines zenoh,dds] [--json]
    python bench/bench_fabric.py --soldiers 20000 --engines zenoh --block 4096
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from server.fabric import FabricConfig, Kind, open_fabric, poses_topic  # noqa: E402
from server.fabric.batch import Batch, decode_batch, encode_batch  # noqa: E402

NFIELDS = 64  # the shipped soldier table (DI + weapon): 50 DOF fields + 2 figures x 7
WARM_TICKS = 45  # batches before measuring: discovery and connection set-up
ADAPTERS = {"zenoh": "server/fabric/zenoh_node.py", "dds": "server/fabric/dds_node.py"}


def _config(engine: str, port: int, listen: bool) -> FabricConfig:
    ep = f"127.0.0.1:{port}"
    return FabricConfig(
        engine, listen=ep if listen else "", connect=() if listen else (ep,), domain=port % 200
    )


def publisher(args: argparse.Namespace) -> dict[str, object]:
    fab = open_fabric(_config(args.engine, args.port, listen=False))
    n = args.soldiers // 2
    puts = [fab.publisher(poses_topic(args.shard, b), Kind.POSES) for b in range(_blocks(args))]
    rng = np.random.default_rng(args.shard)
    base = rng.integers(0, 4096, (n, NFIELDS), dtype=np.uint16)
    idx = np.arange(n, dtype=np.uint32) * 2 + args.shard
    tables = np.ones(n, np.uint8)
    period = 1.0 / args.hz
    total = int(args.seconds * args.hz) + WARM_TICKS
    cpu0 = 0.0
    next_t = time.monotonic() + 1.0  # let the subscriber's session see us first
    for seq in range(total):
        time.sleep(max(0.0, next_t - time.monotonic()))
        if seq == WARM_TICKS:
            cpu0 = time.process_time()
        codes = (base + np.uint16(seq)) & np.uint16(0x0FFF)
        part = idx // args.block if args.block else np.zeros(n, np.int64)
        for b, put in enumerate(puts):
            at = part == b
            put(
                encode_batch(Batch(args.shard, 2, seq, seq, time.monotonic(), idx[at], tables[at], codes[at]))
            )
        next_t += period
    cpu = time.process_time() - cpu0
    time.sleep(1.0)
    fab.close()
    published = (total - WARM_TICKS) * len(puts)  # messages
    return {"published": published, "cpu_ms_per_tick": 1000 * cpu / (total - WARM_TICKS)}


def subscriber(args: argparse.Namespace) -> dict[str, object]:
    fab = open_fabric(_config(args.engine, args.port, listen=True))
    merged = np.zeros((args.soldiers + 2, NFIELDS), np.uint16)
    lat: list[float] = []
    got = [0, 0]
    cpu = [0.0, 0.0]  # process time at the first and the last measured batch
    lock = threading.Lock()

    def on_batch(data: bytes) -> None:
        b = decode_batch(data)
        now = time.monotonic()
        merged[b.indices] = b.codes
        if b.seq < WARM_TICKS:
            return
        with lock:
            if not any(got):
                cpu[0] = time.process_time()
            lat.append(now - b.sent)
            got[b.shard] += 1
            cpu[1] = time.process_time()

    for k in (0, 1):
        for b in range(_blocks(args)):
            fab.subscribe(poses_topic(k, b), Kind.POSES, on_batch)
    print("ready", flush=True)
    sys.stdin.readline()  # the parent says when the publishers are done
    fab.close()
    ms = np.asarray(lat) * 1000
    ticks = max(1, sum(got)) / 2 / _blocks(args)
    return {
        "received": got,
        "latency_ms_p50": float(np.percentile(ms, 50)) if len(ms) else None,
        "latency_ms_p99": float(np.percentile(ms, 99)) if len(ms) else None,
        "latency_ms_max": float(ms.max()) if len(ms) else None,
        "cpu_ms_per_tick": 1000 * (cpu[1] - cpu[0]) / ticks,
    }


def _blocks(args: argparse.Namespace) -> int:
    """Pose topics a shard publishes a tick on: its blocks of ``--block`` indices, or one."""
    return -(-(args.soldiers + 2) // args.block) if args.block else 1


def _code_lines(path: str) -> int:
    lines = (ROOT / path).read_text().splitlines()
    return sum(1 for ln in lines if ln.strip() and not ln.strip().startswith("#"))


def run_engine(args: argparse.Namespace, engine: str, port: int) -> dict[str, object]:
    me = [sys.executable, __file__, "--engine", engine, "--port", str(port), "--soldiers", str(args.soldiers)]
    me += ["--seconds", str(args.seconds), "--hz", str(args.hz), "--block", str(args.block)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    sub = subprocess.Popen(
        [*me, "--role", "sub"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env
    )
    assert sub.stdout is not None and sub.stdin is not None
    sub.stdout.readline()
    pubs = [
        subprocess.Popen(
            [*me, "--role", "pub", "--shard", str(k)], stdout=subprocess.PIPE, text=True, env=env
        )
        for k in (0, 1)
    ]
    pub_results = [json.loads(p.communicate(timeout=args.seconds + 60)[0].splitlines()[-1]) for p in pubs]
    out = json.loads(sub.communicate("done\n", timeout=60)[0].splitlines()[-1])
    published = sum(int(r["published"]) for r in pub_results)
    received = sum(out.pop("received"))
    return {
        "batch_bytes": len(encode_batch(_probe(args.soldiers // 2))),
        "latency_ms_p50": out["latency_ms_p50"],
        "latency_ms_p99": out["latency_ms_p99"],
        "latency_ms_max": out["latency_ms_max"],
        "publisher_cpu_ms_per_tick": max(float(r["cpu_ms_per_tick"]) for r in pub_results),
        "subscriber_cpu_ms_per_tick": out["cpu_ms_per_tick"],
        "published": published,
        "lost": published - received,
        "adapter_lines": _code_lines(ADAPTERS[engine]),
    }


def _probe(n: int) -> Batch:
    return Batch(
        0, 2, 0, 0, 0.0, np.zeros(n, np.uint32), np.zeros(n, np.uint8), np.zeros((n, NFIELDS), np.uint16)
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=10000, help="over both shards")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--hz", type=float, default=30.0)
    ap.add_argument("--engines", default="zenoh,dds")
    ap.add_argument("--block", type=int, default=0, help="soldier indices a batch (0: one batch a tick)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--role", choices=("sub", "pub"), help=argparse.SUPPRESS)
    ap.add_argument("--engine", help=argparse.SUPPRESS)
    ap.add_argument("--port", type=int, default=17447, help=argparse.SUPPRESS)
    ap.add_argument("--shard", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role:
        print(json.dumps((publisher if args.role == "pub" else subscriber)(args)), flush=True)
        return 0
    results = {"soldiers": args.soldiers, "hz": args.hz, "seconds": args.seconds, "block": args.block}
    results["load"] = os.getloadavg()[0]
    for k, engine in enumerate(args.engines.split(",")):
        results[engine] = run_engine(args, engine, args.port + 10 * k)
        if not args.json:
            print(engine, json.dumps(results[engine]), flush=True)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
