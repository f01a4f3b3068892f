"""Benchmark: N shards, M front-ends and C clients in P load-generator processes, all real processes on this
machine (issue 21's scale-out: what a 16-core machine carries).

Spawns ``ttes front --shards N --front K/M`` (front-end K listens on its fabric endpoint and connects to the
front-ends before it) and ``ttes server --shard K/N`` (connected to every front-end) on the shipped library
over Zenoh (loopback), every soldier updated every tick (``--throttle 0``), then P load generators
(``client_stub.loadtest`` in processes of their own, so that they are not the bottleneck: process j drives
front-end j % M with its share of the clients and soldiers). Reports, over the window in which every
generator measured: delivered % of steady-mover updates (all generators' together), request -> update
p50/p99 (all their samples), each process's CPU (% of a core: front-ends, shards, generators), each
server's CPU per tick by stage (its status lines), and the bytes the processes moved through system calls
and the fabric's bytes per second (each shard's batches, one copy: Zenoh sends one to each front-end; and
what each front-end received: ``fabric_in_bytes_per_s``, only the index blocks its clients watch, and
``fabric_blocks``, the (shard, block) topics it heard at the end), from the servers' status lines. A
progress line on stderr every 2 s. ``--fabric dds`` runs it on Cyclone DDS; ``--fabric-block`` sets the
soldier indices per pose topic (``ttes server --fabric-block``).

A soldier index is 16 bits on the client protocol (docs/PROTOCOL.md: ``max_soldiers`` <= 65,536), so one
cluster serves at most 65,536 soldiers, the start-up script's included.

    python bench/bench_scaleout.py --soldiers 20000 --shards 2 --fronts 2 --clients 4 --procs 2 \\
        [--seconds 10] [--warmup 5] [--out result.json]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import random
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client_stub.link.spawn import ServerProcess, SpawnError, cpu_seconds, free_port
from server.config import MAX_SOLDIERS_LIMIT
from server.fabric import BLOCK, engine_flags

HEADROOM = (
    512  # indices beyond the load's: the start-up script's soldiers and the front-ends' shares' rounding
)
PORT_TRIES = 3  # cluster starts when a front-end's fabric port was taken meanwhile


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=20000)
    ap.add_argument("--shards", type=int, default=2)
    ap.add_argument("--fronts", type=int, default=2)
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument(
        "--procs", type=int, help="load-generator processes (default: max(fronts, min(clients, 4)))"
    )
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--warmup", type=float, default=5.0)
    ap.add_argument("--timeout", type=float, default=300.0, help="a generator's limit to create its soldiers")
    ap.add_argument("--out", type=Path, help="write the JSON here too")
    ap.add_argument("--fabric", choices=("zenoh", "dds"), default="zenoh", help="fabric engine")
    ap.add_argument("--fabric-block", type=int, help="soldier indices per pose topic (default: the server's)")
    ap.add_argument("--worker", nargs=2, metavar=("PORT", "OUT"), help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--gate", default="", help=argparse.SUPPRESS)
    ap.add_argument("--ready-file", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        return worker(args, int(args.worker[0]), Path(args.worker[1]))
    out = run(args)
    text = json.dumps(out)
    print(text, flush=True)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


def run(args: argparse.Namespace) -> dict[str, Any]:
    m, n = args.fronts, args.shards
    procs_n = args.procs or max(m, min(args.clients, 4))
    if not 1 <= m <= procs_n <= args.clients <= args.soldiers:
        raise SystemExit("need 1 <= fronts <= procs <= clients <= soldiers")
    # each front-end allots from its share (every M-th block of indices): room for its generators' soldiers
    per_front = np.bincount(np.arange(procs_n) % m, _split(args.soldiers, procs_n), m)
    cap = max_soldiers(args.soldiers, per_front, args.fabric_block or BLOCK)
    with tempfile.TemporaryDirectory(prefix="ttes-scaleout-") as tmp:
        config = Path(tmp) / "scale.toml"
        config.write_text(f"max_soldiers = {cap}\nmax_soldiers_per_client = {cap}\nreport_interval = 1.0\n")
        flags = ["--config", str(config), "--throttle", "0", *engine_flags(args.fabric)]
        flags += ["--fabric-block", str(args.fabric_block)] if args.fabric_block else []
        started = time.monotonic()
        with cluster(flags, n, m) as servers:
            ready_s = time.monotonic() - started
            print(f"{n} shards + {m} front-ends ready in {ready_s:.1f} s", file=sys.stderr, flush=True)
            load0 = os.getloadavg()[0]
            gens = generators(args, servers, procs_n, Path(tmp))
            try:
                samples = watch(servers, gens, Path(tmp) / "gate")
            finally:  # (interrupted: timeout -s INT)
                for g in gens:
                    if g.poll() is None:
                        g.kill()
            reports = [_report(Path(tmp), j) for j in range(procs_n)]
            logs = {k: p.log_tail(1 << 26) for k, p in servers.items()}
    books = {k: log.count("fabric_books_failed") for k, log in logs.items() if k.startswith("front")}
    # books answers a shard sent (each a list of every soldier it animates, heard by every front-end)
    answered = {k: log.count("fabric_books_answered") for k, log in logs.items() if k.startswith("shard")}
    failed = [r for r in reports if "error" in r]
    reports = [r for r in reports if "error" not in r]
    if not reports:
        return {"soldiers": args.soldiers, "shards": n, "fronts": m, "failed": failed}
    window = (max(r["window_abs"][0] for r in reports), min(r["window_abs"][1] for r in reports))
    rows = {k: status_lines(log, window) for k, log in logs.items()}
    fabric = {k: fabric_rate(r) for k, r in rows.items()}
    lat = np.concatenate([np.asarray(r["latency_s"]) for r in reports]) * 1000.0
    got = sum(r["updates_per_s"] or 0.0 for r in reports)
    want = sum(r["expected_updates_per_s"] or 0.0 for r in reports)
    return {
        "soldiers": args.soldiers,
        "shards": n,
        "fronts": m,
        "clients": args.clients,
        "generators": procs_n,
        "nproc": os.cpu_count(),
        "load_start": round(load0, 2),
        "load_end": round(os.getloadavg()[0], 2),
        "cluster_ready_s": round(ready_s, 1),
        "soldiers_made_s": next((s["gate"] for s in samples if "gate" in s), None),
        "common_window_s": round(window[1] - window[0], 2),
        "delivered_pct": round(100.0 * got / want, 2) if want else None,
        "latency_ms_p50": round(float(np.percentile(lat, 50)), 1) if len(lat) else None,
        "latency_ms_p99": round(float(np.percentile(lat, 99)), 1) if len(lat) else None,
        "latency_samples": len(lat),
        **cpu_rates(samples, window),
        "fabric_out_bytes_per_s": sum(v for k, v in fabric.items() if k.startswith("shard")),
        "fabric_bytes_per_s": fabric,
        "fabric_in_bytes_per_s": {k: v for k, v in fabric.items() if k.startswith("front")},
        "fabric_blocks": {
            k: int(r[-1]["fabric_blocks"]) for k, r in rows.items() if r and "fabric_blocks" in r[-1]
        },
        "cpu_ms_per_tick": {k: stages(r) for k, r in rows.items()},
        "books_failed": books,
        "books_answered": answered,
        # at the window's end: every front-end should know every soldier, each shard its own; mirrored:
        # the soldiers a front-end knows from the others (ttes/fronts)
        "soldiers_known": {k: int(r[-1].get("soldiers", -1)) for k, r in rows.items() if r},
        "mirrored": {k: int(r[-1]["mirrored"]) for k, r in rows.items() if r and "mirrored" in r[-1]},
        "per_generator": [{k: v for k, v in r.items() if k != "latency_s"} for r in reports],
        "failed": failed,
    }


def max_soldiers(soldiers: int, per_front: np.ndarray, block: int) -> int:
    """The cluster's ``max_soldiers``: room for the soldiers, the start-up script's and, in each front-end's
    share of the index blocks, its generators' (a share is the blocks ``k, k + M, ...`` below it; the
    start-up script's soldiers are in block 0, front-end 0's)."""
    m = len(per_front)
    cap = min(soldiers + soldiers // 16 + HEADROOM, MAX_SOLDIERS_LIMIT)
    need = per_front + np.eye(1, m, dtype=int)[0] * HEADROOM
    while True:
        shares = np.bincount((np.arange(cap) // block) % m, minlength=m)
        if soldiers + HEADROOM <= cap and (need <= shares).all():
            return cap
        if cap == MAX_SOLDIERS_LIMIT:
            raise SystemExit(f"{soldiers} soldiers: the client protocol's index is 16 bits ({cap} at most)")
        cap = min(cap + block // 4, MAX_SOLDIERS_LIMIT)


def _report(tmp: Path, j: int) -> dict[str, Any]:
    """Generator j's report, or what it said on stderr if it wrote none."""
    try:
        return dict(json.loads((tmp / f"gen{j}.json").read_text()))
    except (OSError, ValueError):
        return {"generator": j, "error": (tmp / f"gen{j}.err").read_text()[-2000:]}


@contextlib.contextmanager
def cluster(flags: list[str], shards: int, fronts: int) -> Iterator[dict[str, ServerProcess]]:
    """``fronts`` front-ends (each connects to those before it) and ``shards`` shards connected to all.
    A front-end whose fabric port was taken meanwhile (the port is picked free, then released, and another
    process's connection may get it: "Address already in use") is started again on a new port, all of
    them with it (the later ones and the shards connect to it)."""
    for attempt in range(PORT_TRIES):
        procs: dict[str, ServerProcess] = {}
        try:
            _start(procs, flags, shards, [f"127.0.0.1:{fabric_port()}" for _ in range(fronts)])
        except SpawnError as exc:
            for p in procs.values():
                p.stop()
            if "Address already in use" not in str(exc) or attempt + 1 == PORT_TRIES:
                raise
            print(f"a fabric port was taken meanwhile: starting again ({exc!s:.200})", file=sys.stderr)
            continue
        try:
            yield procs
        finally:
            for p in procs.values():
                p.stop()
        return


def _start(procs: dict[str, ServerProcess], flags: list[str], shards: int, ends: list[str]) -> None:
    for k, end in enumerate(ends):
        joins = [a for e in ends[:k] for a in ("--fabric-connect", e)]
        args = [
            *flags,
            "--shards",
            str(shards),
            "--front",
            f"{k}/{len(ends)}",
            "--fabric-listen",
            end,
            *joins,
        ]
        procs[f"front{k}"] = ServerProcess(args, command="front", timeout=300.0)
    joins = [a for e in ends for a in ("--fabric-connect", e)]
    for k in range(shards):
        procs[f"shard{k}"] = ServerProcess([*flags, "--shard", f"{k}/{shards}", *joins], timeout=300.0)
    for p in procs.values():
        p.wait_ready()


def fabric_port() -> int:
    """A free port below the kernel's range of ephemeral ports where it can tell (outgoing connections of
    the servers then never take it between its pick and the front-end's listen), else any free port."""
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return free_port()
    rng = random.Random()
    for _ in range(100):
        port = rng.randrange(max(1024, low // 2), low)
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    return free_port()


def generators(
    args: argparse.Namespace, servers: dict[str, ServerProcess], procs_n: int, tmp: Path
) -> list[subprocess.Popen[bytes]]:
    """The load-generator processes: j drives front-end j % M with its share of clients and soldiers."""
    clients, soldiers = _split(args.clients, procs_n), _split(args.soldiers, procs_n)
    gens = []
    for j in range(procs_n):
        port = servers[f"front{j % args.fronts}"].port
        cmd = [sys.executable, __file__, "--soldiers", str(soldiers[j]), "--clients", str(clients[j])]
        cmd += ["--seconds", str(args.seconds), "--warmup", str(args.warmup), "--timeout", str(args.timeout)]
        cmd += [
            "--seed",
            str(j + 1),
            "--gate",
            str(tmp / "gate"),
            "--worker",
            str(port),
            str(tmp / f"gen{j}.json"),
        ]
        cmd += ["--ready-file", str(tmp / f"gen{j}.ready")]
        err = (tmp / f"gen{j}.err").open("wb")
        gens.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err))
    return gens


def _split(total: int, parts: int) -> np.ndarray:
    return np.diff(np.linspace(0, total, parts + 1).round().astype(int))


def status_lines(log: str, window: tuple[float, float]) -> list[dict[str, str]]:
    """A server's status lines (their ``key=value`` fields) stamped (``mono``: host monotonic time) within
    ``window``, and the one before (the start of the first one's interval); the last two if fewer."""
    rows = [
        dict(f.split("=", 1) for f in line.split() if "=" in f)
        for line in log.splitlines()
        if "event=status" in line and " mono=" in line
    ]
    first = next((i for i, r in enumerate(rows) if float(r["mono"]) >= window[0]), len(rows))
    inside = [r for r in rows[max(0, first - 1) :] if float(r["mono"]) <= window[1]]
    return inside if len(inside) >= 2 else rows[-2:]


def fabric_rate(rows: list[dict[str, str]]) -> int:
    """Fabric bytes per second between the first and the last of a server's status lines."""
    if len(rows) < 2 or float(rows[-1]["mono"]) <= float(rows[0]["mono"]):
        return 0
    moved = int(rows[-1]["fabric_bytes"]) - int(rows[0]["fabric_bytes"])
    return round(moved / (float(rows[-1]["mono"]) - float(rows[0]["mono"])))


def stages(rows: list[dict[str, str]]) -> dict[str, float]:
    """The mean CPU per tick by stage (``cpu_ms_per_tick``) of the status lines after the first."""
    ticks = [
        {k: float(v) for k, v in (kv.split(":") for kv in r["cpu_ms_per_tick"].split(","))}
        for r in rows[1:]
        if r.get("cpu_ms_per_tick")
    ]
    keys = sorted({k for t in ticks for k in t})
    return {k: round(float(np.mean([t.get(k, 0.0) for t in ticks])), 2) for k in keys} | {
        "reports": len(ticks)
    }


def watch(
    servers: dict[str, ServerProcess], gens: list[subprocess.Popen[bytes]], gate: Path
) -> list[dict[str, Any]]:
    """Sample every process's CPU seconds each second until the generators exit, a progress line on stderr
    every 2 s; open ``gate`` once every generator's soldiers exist (or one generator ended early)."""
    pids = {k: p.pid for k, p in servers.items()} | {f"gen{j}": g.pid for j, g in enumerate(gens)}
    samples: list[dict[str, Any]] = []
    t0 = time.monotonic()
    while True:
        now = time.monotonic()
        samples.append({"t": now, "cpu": {k: cpu_seconds(p) for k, p in pids.items()}})
        ready = len(list(gate.parent.glob("gen*.ready")))
        if not gate.exists() and (ready == len(gens) or any(g.poll() is not None for g in gens)):
            gate.touch()
            samples[-1]["gate"] = round(now - t0, 1)
        if len(samples) % 2 == 1 and len(samples) > 2:
            line = progress_line(samples[-3], samples[-1], now - t0, gens)
            print(
                line + ("" if gate.exists() else f", soldiers made by {ready}"), file=sys.stderr, flush=True
            )
        if all(g.poll() is not None for g in gens):
            return samples
        time.sleep(max(0.0, now + 1.0 - time.monotonic()))


def progress_line(a: dict[str, Any], b: dict[str, Any], elapsed: float, gens: list[Any]) -> str:
    dt = b["t"] - a["t"]
    pct = {k: 100.0 * (b["cpu"][k] - a["cpu"][k]) / dt for k in b["cpu"]}
    fronts = " ".join(f"{v:.0f}" for k, v in pct.items() if k.startswith("front"))
    shards = " ".join(f"{v:.0f}" for k, v in pct.items() if k.startswith("shard"))
    gen = " ".join(f"{v:.0f}" for k, v in pct.items() if k.startswith("gen"))
    running = sum(g.poll() is None for g in gens)
    return (
        f"[{elapsed:5.0f} s] load {os.getloadavg()[0]:.1f}  CPU %: fronts {fronts} | shards {shards} | "
        f"generators {gen}  (generators running: {running})"
    )


def cpu_rates(samples: list[dict[str, Any]], window: tuple[float, float]) -> dict[str, Any]:
    """Each process's CPU % over ``window`` (the samples inside it)."""
    inside = [s for s in samples if window[0] <= s["t"] <= window[1]]
    if len(inside) < 2:
        inside = samples[-2:]
    a, b = inside[0], inside[-1]
    dt = max(b["t"] - a["t"], 1e-9)
    return {
        "cpu_measured_s": round(dt, 2),
        "cpu_pct": {k: _pct(b["cpu"][k] - a["cpu"][k], dt) for k in b["cpu"]},  # None: it ended in the window
    }


def _pct(cpu_s: float, dt: float) -> float | None:
    return round(100.0 * cpu_s / dt, 1) if math.isfinite(cpu_s) else None


def worker(args: argparse.Namespace, port: int, out: Path) -> int:
    """One load generator: ``run_loadtest`` against a front-end; writes its report with its request ->
    update samples of the window and the window in this host's monotonic time."""
    from client_stub.loadtest.session import LoadTestConfig, run_loadtest

    first: list[float] = []

    def progress(done: float, total: float | None, stage: str) -> None:
        if not first:
            first.append(time.monotonic() - done)  # the drive began: warm-up, then the window

    cfg = LoadTestConfig(
        soldiers=args.soldiers,
        clients=args.clients,
        seconds=args.seconds,
        warmup_s=args.warmup,
        port=port,
        throttle=None,
        seed=args.seed,
        timeout_s=args.timeout,
        keep_recording=True,
        ready_file=args.ready_file,
        gate=args.gate,
    )
    report = run_loadtest(cfg, progress)
    rec = report.pop("_recording")
    t0, t1 = report["window"]
    sel = (rec["latency_time"] >= t0) & (rec["latency_time"] < t1)
    begin = first[0] if first else time.monotonic()
    keys: tuple[str, ...] = (
        "delivered_pct",
        "updates_per_s",
        "expected_updates_per_s",
        "latency_ms_p50",
        "latency_ms_p99",
    )
    keys += ("server_ticks_seen", "soldiers_seen_min", "client_cpu_pct", "server")
    result = {k: report.get(k) for k in keys}
    result |= {"soldiers": args.soldiers, "clients": args.clients, "port": port}
    result["window_abs"] = [begin + args.warmup, begin + args.warmup + args.seconds]
    result["latency_s"] = [round(float(x), 5) for x in rec["latency"][sel]]
    out.write_text(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
