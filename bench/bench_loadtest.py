"""Benchmark: the largest number of soldiers one server sustains at 30 Hz, server and load generator on this
machine (`ttes loadtest --ramp --spawn-server`).

Stages grow N (×``--factor``) until one misses the criteria: steady-mover updates delivered ≥ 99 % of
expected and p99 latency ≤ 33 ms. The latency criterion is the *tick → arrival* p99 (how long after its
server tick an update arrives); the request → update p99 is reported too, but it cannot meet 33 ms at any
N: a request waits for the next 30 Hz tick (0 – 33.3 ms) and the first pose change visible at the wire's
12-bit resolution may come a tick later still. Prints each stage, the largest N sustained and the bytes
per soldier update.

    python bench/bench_loadtest.py [--start 400] [--factor 1.4] [--clients 2] [--seconds 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.machine import Machine


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--start", type=int, default=400)
    ap.add_argument("--factor", type=float, default=1.4)
    ap.add_argument("--clients", type=int, default=2)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--seconds", type=float, default=3.0, help="measured seconds per stage")
    ap.add_argument("--warmup", type=float, default=1.5, help="seconds before measuring, per stage")
    ap.add_argument("--max-wall", type=float, default=38.0, help="no new stage after this many seconds")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from client_stub.loadtest.session import LoadTestConfig, run_loadtest

    machine = Machine()
    cfg = LoadTestConfig(
        soldiers=args.start,
        clients=args.clients,
        rate_hz=args.rate,
        seconds=args.seconds,
        warmup_s=args.warmup,
        spawn_server=True,
        ramp=True,
        ramp_factor=args.factor,
        ramp_max_s=args.max_wall,
        min_delivered_pct=99.0,
        max_p99_ms=33.0,
        latency_metric="delivery",
    )
    r = run_loadtest(cfg)
    stages = [
        {k: s.get(k) for k in ("soldiers", "updates_per_s", "expected_updates_per_s", "delivered_pct",
                               "latency_ms_p50", "latency_ms_p99", "delivery_ms_p99", "bytes_per_update",
                               "server_cpu_pct", "client_cpu_pct", "passed")}
        for s in r["stages"]
    ]  # fmt: skip
    e2e = [s["soldiers"] for s in r["stages"] if s["passed"] and (s["latency_ms_p99"] or 1e9) <= 33.0]
    best = r["largest_sustained_soldiers"]
    best_stage = next((s for s in stages if s["soldiers"] == best), stages[0])
    out = {
        "largest_sustained_soldiers": best,
        "first_failed_soldiers": r["first_failed_soldiers"],
        "criteria": "delivered >= 99% of expected and tick->arrival p99 <= 33 ms, 30 Hz",
        "largest_with_request_p99_le_33ms": max(e2e) if e2e else None,
        "bytes_per_update": best_stage["bytes_per_update"],
        "rate_hz": args.rate,
        "clients": args.clients,
        "server_synthetic_library": r["server"]["synthetic"],
        "stages": stages,
        **machine.facts(),
    }
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"bench_loadtest: {args.clients} clients at {args.rate:g} Hz, {os.cpu_count()} CPUs, "
          f"load average before {out['loadavg_before']}")  # fmt: skip
    for s in stages:
        print(
            f"  N={s['soldiers']:>5}  delivered {s['delivered_pct']}% ({s['updates_per_s']} of "
            f"{s['expected_updates_per_s']} /s)  request->update p50/p99 {s['latency_ms_p50']}/"
            f"{s['latency_ms_p99']} ms  tick->arrival p99 {s['delivery_ms_p99']} ms  "
            f"{s['bytes_per_update']} B/update  server CPU {s['server_cpu_pct']}%  "
            f"{'ok' if s['passed'] else 'FAIL'}"
        )
    print(f"  largest sustained N = {best} (first failed {out['first_failed_soldiers']}); "
          f"{out['bytes_per_update']} bytes per soldier update; {out['wall_s']} s")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
