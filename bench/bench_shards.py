"""Benchmark: soldiers over 2 shards and a front-end at 30 Hz to C clients, all real processes on this machine
(issue 21's: 20,000 soldiers, 2 clients, ≥ 99 % delivered, p99 request → update ≤ 50 ms).

Spawns ``ttes front --shards 2`` and two ``ttes server --shard K/2`` on the shipped library over the Zenoh
fabric (loopback), every soldier updated every tick (``--throttle 0``), then drives the front-end with the
load generator (``client_stub.loadtest``, as ``ttes loadtest --host --port``): delivered % of steady-mover
updates, request → first reflecting update p50/p99, bytes per update; and each process's CPU (% of a core)
over the run. On this 2-core machine the four processes share two cores with everything else: quote the
load average.

    python bench/bench_shards.py [--soldiers 20000] [--clients 2] [--seconds 10] [--fabric zenoh] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.link.spawn import ServerProcess, cpu_seconds, free_port
from client_stub.loadtest.session import LoadTestConfig, run_loadtest


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=20000)
    ap.add_argument("--clients", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--warmup", type=float, default=3.0)
    ap.add_argument("--fabric", choices=("zenoh", "dds"), default="zenoh")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="ttes-shards-") as tmp:
        config = Path(tmp) / "scale.toml"  # room for every soldier, one client id may own them all
        n = args.soldiers + 64
        config.write_text(f"max_soldiers = {n}\nmax_soldiers_per_client = {n}\n")
        common = ["--config", str(config), "--throttle", "0", "--fabric", args.fabric]
        endpoint = f"127.0.0.1:{free_port()}"
        procs = {
            "front": ServerProcess([*common, "--shards", "2", "--fabric-listen", endpoint], command="front")
        }
        for k in (0, 1):
            procs[f"shard{k}"] = ServerProcess([*common, "--shard", f"{k}/2", "--fabric-connect", endpoint])
        try:
            for p in procs.values():
                p.wait_ready()
            cpu0, t0 = {k: p.cpu_seconds() for k, p in procs.items()}, time.monotonic()
            load = os.getloadavg()[0]
            report = run_loadtest(
                LoadTestConfig(
                    soldiers=args.soldiers,
                    clients=args.clients,
                    seconds=args.seconds,
                    warmup_s=args.warmup,
                    port=procs["front"].port,
                    throttle=None,
                    timeout_s=120.0,
                )
            )
            wall = time.monotonic() - t0
            cpu = {k: round(100 * (cpu_seconds(p.pid) - cpu0[k]) / wall, 1) for k, p in procs.items()}
        finally:
            for p in procs.values():
                p.stop()
    keys = ("delivered_pct", "latency_ms_p50", "latency_ms_p99", "delivery_ms_p99", "bytes_per_update")
    keys += ("all_updates_per_s", "soldiers_seen_min", "server_ticks_seen")
    out = {
        "soldiers": args.soldiers,
        "clients": args.clients,
        "fabric": args.fabric,
        "load": round(load, 2),
        **{k: report.get(k) for k in keys},
        "cpu_pct": cpu,
    }
    print(json.dumps(out) if args.json else json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
