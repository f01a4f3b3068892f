"""Benchmark: soldiers over 2 shards and a front-end at 30 Hz to C clients, all real processes on this machine
(issue 21's: 20,000 soldiers, 2 clients, ≥ 99 % delivered, p99 request → update ≤ 50 ms).

Spawns ``ttes front --shards 2`` and two ``ttes server --shard K/2`` on the shipped library over the Zenoh
fabric (loopback), every soldier updated every tick (``--throttle 0``), then drives the front-end with the
load generator (``client_stub.loadtest``, as ``ttes loadtest --host --port``): delivered % of steady-mover
updates, request → first reflecting update p50/p99, bytes per update; and each process's CPU (% of a core)
over the run (``server_cpu_pct``: the front-end's in the steady window). The load generator only taps the
update frames (header and indices), so it stays cheap beside the servers (``client_cpu_pct``: 2–5 % of a
core at 10,000–20,000). On this 2-core machine the four processes share two cores with everything else:
quote the load average. Each server's status line has its CPU per tick by stage (``cpu_ms_per_tick``).

``--probe N`` measures instead the path a request takes alone: N soldiers, one posture request at a time
(kneel, then stand), the time until that soldier's next update reaches the client (client → front-end →
shard → front-end → client), on the synthetic library, ``--throttle 0`` as the load.

    python bench/bench_shards.py [--soldiers 20000] [--clients 2] [--seconds 10] [--fabric zenoh] [--json]
    python bench/bench_shards.py --probe 40 [--fabric dds]

``--trace N`` runs the load with a probe of N soldiers beside it and says where each probe request's time
went (``bench/trace_legs.py``: the legs client → front-end → fabric → shard → fabric → front-end →
client, stamped by each process under ``TTES_TRACE``) with each process's CPU per tick by stage.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path

import numpy as np
import trio

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import trace_legs
from client_stub.link.spawn import ServerProcess, cpu_seconds, free_port
from client_stub.loadtest.session import LoadTestConfig, run_loadtest
from server.fabric import engine_flags
from server.gc_freeze import freeze_loaded

REPORT_S = 2.0  # the servers' status period (their CPU per tick by stage)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=20000)
    ap.add_argument("--clients", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--warmup", type=float, default=3.0)
    ap.add_argument("--fabric", choices=("zenoh", "dds"), default="zenoh")
    ap.add_argument(
        "--fabric-block",
        type=int,
        help="soldier indices per pose topic (default: the servers'; the one front-end watches every "
        "block, so it hears each shard whole, one batch a tick, whatever the block: docs/SCALING.md)",
    )
    ap.add_argument("--probe", type=int, metavar="N", help="request -> update latency of N soldiers")
    ap.add_argument("--trace", type=int, metavar="N", help="trace N probe soldiers' requests under the load")
    ap.add_argument(
        "--subscribe-all",
        action="store_true",
        help="the load's connections share one client id and each watches every soldier (their encodes may "
        "then be shared: front_encodes' hits; by default each watches its own and none can be)",
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.probe:
        out = probe(args.probe, args.fabric)
        print(json.dumps(out) if args.json else json.dumps(out, indent=1))
        return 0
    with tempfile.TemporaryDirectory(prefix="ttes-shards-") as tmp:
        config = Path(tmp) / "scale.toml"  # room for every soldier, one client id may own them all
        n = args.soldiers + 64
        config.write_text(
            f"max_soldiers = {n}\nmax_soldiers_per_client = {n}\nreport_interval = {REPORT_S}\n"
        )
        common = ["--config", str(config), "--throttle", "0", *engine_flags(args.fabric)]
        common += ["--fabric-block", str(args.fabric_block)] if args.fabric_block else []
        if args.trace:
            os.environ["TTES_TRACE"], os.environ["TTES_TRACE_BELOW"] = f"{tmp}/trace", str(args.trace + EXTRA)
        with cluster(common) as procs, probing(procs["front"].port, args.trace, Path(tmp)) as probed:
            freeze_loaded()  # the load generator's imports out of its GC's full collections (24 ms each)
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
                    subscribe_all=args.subscribe_all,
                    server_pid=procs["front"].pid,
                )
            )
            wall = time.monotonic() - t0
            end = time.time()
            window = (end - args.seconds, end)  # the load generator's measured seconds, just ended
            cpu = {k: round(100 * (cpu_seconds(p.pid) - cpu0[k]) / wall, 1) for k, p in procs.items()}
            stages = {k: stage_cpu(p.log_tail(1 << 24)) for k, p in procs.items()}
            steady = {k: stage_cpu(p.log_tail(1 << 24), window=window) for k, p in procs.items()}
            deaf = {k: stage_cpu(p.log_tail(1 << 24), "loop_deaf_ms") for k, p in procs.items()}
            streams = last_field(procs["front"].log_tail(1 << 24), "fabric_blocks")
            memo = memo_counts(procs["front"].log_tail(1 << 24))
            traced = probed(time.monotonic() - args.seconds) if args.trace else {}
    keys: tuple[str, ...] = (
        "delivered_pct",
        "latency_ms_p50",
        "latency_ms_p99",
        "delivery_ms_p99",
        "bytes_per_update",
    )
    keys += ("all_updates_per_s", "soldiers_seen_min", "server_ticks_seen")
    keys += (
        "latency_samples",
        "latency_ms_max",
        "probes_over_1s",
        "probes_superseded",
        "probes_over_1s_superseded",
        "probes_over_1s_sent_s",
    )
    keys += ("server_cpu_pct", "client_cpu_pct")  # the front-end's and the load generator's, steady window
    out = {
        "soldiers": args.soldiers,
        "clients": args.clients,
        "fabric": args.fabric,
        "load": round(load, 2),
        **{k: report.get(k) for k in keys},
        "cpu_pct": cpu,
        "cpu_ms_per_tick": stages,
        "cpu_ms_per_tick_window": steady,  # the status lines within the measured window only
        "front_streams_heard": streams,  # (shard, block or whole) pose topics: 2 = each shard whole
        "front_encodes": memo,  # per tick between its status lines (the first left out): shared or own
        **({"loop_deaf_ms": deaf} if os.environ.get("TTES_DEAF") == "1" else {}),
        **traced,
    }
    print(json.dumps(out) if args.json else json.dumps(out, indent=1))
    return 0


@contextlib.contextmanager
def cluster(flags: list[str]) -> Iterator[dict[str, ServerProcess]]:
    """A front-end and two shards with ``flags`` each, ready; stopped on exit."""
    endpoint = f"127.0.0.1:{free_port()}"
    procs = {"front": ServerProcess([*flags, "--shards", "2", "--fabric-listen", endpoint], command="front")}
    for k in (0, 1):
        procs[f"shard{k}"] = ServerProcess([*flags, "--shard", f"{k}/2", "--fabric-connect", endpoint])
    try:
        for p in procs.values():
            p.wait_ready()
        yield procs
    finally:
        for p in procs.values():
            p.stop()


EXTRA = 16  # the start-up script's soldiers come first: the probe's are traced below N + EXTRA


@contextlib.contextmanager
def probing(port: int, n: int | None, tmp: Path) -> Iterator[Callable[[float], dict[str, object]]]:
    """With ``n``: a probe client of n traced soldiers (made first: indices 0..n-1) in its own process,
    and a function that joins its requests sent since a time with the servers' trace stamps."""
    if not n:
        yield lambda since: {}
        return
    out = tmp / "probe.txt"
    cmd = [sys.executable, str(Path(__file__).with_name("trace_legs.py")), str(port), str(n), str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        ready = proc.stdout.readline().split()
        if ready[:1] != ["ready"] or int(ready[1]) >= n + EXTRA:
            raise RuntimeError(f"probe client not ready: {ready}")

        def joined(since: float) -> dict[str, object]:
            lines = out.read_text().splitlines() if out.exists() else []
            probes = [(int(i), float(a), float(b)) for i, a, b in (ln.split() for ln in lines)]
            window = [p for p in probes if p[1] >= since]
            stamps = trace_legs.read_stamps(sorted(tmp.glob("trace.*")))
            return {"probes_all": len(probes), **trace_legs.legs(window, stamps)}

        yield joined
    finally:
        proc.terminate()
        proc.wait(10)


def last_field(log: str, name: str) -> str | None:
    """The value of ``name=`` in a server's last status line (None without one)."""
    for line in reversed(log.splitlines()):
        field = next((f for f in line.split() if f.startswith(name + "=")), None)
        if "event=status" in line and field:
            return field.split("=", 1)[1]
    return None


def memo_counts(log: str) -> dict[str, float]:
    """A front-end's encodes per tick between its first and last status lines (``shared_encodes``:
    ``hits`` taken from a client in the same delta state, ``own`` a writer's own diff-and-pack), and the rows
    of an own encode: whether its clients share encodes (issue 21's two clients watch their own soldiers)."""
    rows = []
    for line in log.splitlines():
        fields = dict(f.split("=", 1) for f in line.split() if "=" in f)
        if fields.get("event") == "status" and "shared_encodes" in fields:
            counts = {k: int(v) for k, v in (kv.split(":") for kv in fields["shared_encodes"].split(","))}
            rows.append((int(fields["ticks"]), counts))
    if len(rows) < 3:
        return {}
    (t0, a), (t1, b) = rows[1], rows[-1]
    ticks = max(1, t1 - t0)
    own = b["own"] - a["own"]
    return {
        "hits_per_tick": round((b["hits"] - a["hits"]) / ticks, 2),
        "own_per_tick": round(own / ticks, 2),
        "caught_up_per_tick": round((b["caught_up"] - a["caught_up"]) / ticks, 2),
        "rows_per_own": round((b["rows"] - a["rows"]) / max(1, own)),
    }


def stage_cpu(
    log: str, name: str = "cpu_ms_per_tick", window: tuple[float, float] | None = None
) -> dict[str, float]:
    """The mean of a server's ``cpu_ms_per_tick`` (``animate:3.2,merge:1.1,...``) over its status lines,
    the first (start-up, creations) left out; ``name``: another such field (``loop_deaf_ms``: with
    ``TTES_DEAF=1`` in the environment, ``server.stage_cpu.DeafSpans``). With ``window`` (epoch seconds),
    only the lines whose span lies in it: the whole run's mean has the creation burst in it (a front-end's
    ``requests`` 10-19 ms a tick while the clients create their soldiers, 0.5-0.7 in the steady window)."""
    rows = []
    for line in log.splitlines():
        field = next((f for f in line.split() if f.startswith(name + "=")), None)
        if "event=status" in line and field:
            if window is not None:
                at = datetime.fromisoformat(line.split()[0]).timestamp()
                if not window[0] <= at - REPORT_S <= at <= window[1]:
                    continue
            rows.append({k: float(v) for k, v in (kv.split(":") for kv in field.split("=", 1)[1].split(","))})
    rows = (rows if window is not None else rows[1:]) or [{}]
    keys = sorted({k for r in rows for k in r})
    return {k: round(float(np.mean([r.get(k, 0.0) for r in rows])), 2) for k in keys} | {"reports": len(rows)}


def probe(n: int, fabric: str) -> dict[str, object]:
    # --throttle 0 as the load's: the synthetic start-up script's 0.04 s held an answer until 23 ms after the
    # client's last write (16 ms p50 of the path's 9 at load 11, measured alone)
    with cluster(["--synthetic", "--throttle", "0", *engine_flags(fabric)]) as procs:
        lat = trio.run(_probe, procs["front"].port, n)
    ms = np.asarray(lat) * 1000
    return {
        "soldiers": n,
        "fabric": fabric,
        "load": round(os.getloadavg()[0], 2),
        "requests": len(ms),
        **{f"request_to_update_ms_p{q}": round(float(np.percentile(ms, q)), 1) for q in (50, 90, 99)},
        "max_ms": round(float(ms.max()), 1),
    }


async def _probe(port: int, n: int) -> list[float]:
    lat: list[float] = []
    await trace_legs.probe_requests(port, n, 3 * n, lambda i, sent, received: lat.append(received - sent))
    return lat


if __name__ == "__main__":
    raise SystemExit(main())
