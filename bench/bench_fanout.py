"""Benchmark: fan-out of joint updates — one server, N soldiers, 1, 2, 4 and 8 clients subscribed to all.

By default, per client count: a spawned server (its own process, every tick due), one controller that makes
N soldiers walk, run or crawl, and C *counting observers* (client_stub/loadtest/observe.py: each JOINT_UPDATES
frame counted from its 8-byte head, never decoded; ``--procs`` processes, not this one) subscribed to all.
Reports per count: delivered % (updates received / N x tick rate x window, the worst client), the server's
CPU (% of a core, ms per server tick run), how long it waited for a CPU (run queue: a loaded machine, not its
own work), bytes/s and bytes per soldier-update per client, the observers' CPU. With encode-once-send-to-many
(issue 18) the server's CPU should stay nearly flat as clients are added. ``--per-client`` sets
``TTES_SHARED_ENCODES=0`` for the spawned server: every client encodes on its own (the behaviour before).
``--loadtest``: the full load generator instead (``ttes loadtest --spawn-server --subscribe-all``, one
process, its own tracker per soldier: on a small machine it, not the server, bounds what is delivered).

    python bench/bench_fanout.py [--soldiers 10000] [--clients 1,2,4,8] [--seconds 5] [--protocol 1|2]
        [--procs 1] [--per-client] [--loadtest] [--json]

``--in-process`` measures the server's side alone, without sockets or a load generator competing for the
CPU (for a loaded or small machine): the server's tick and C sessions (observers subscribed to every soldier,
each reading every tick) in this process, simulated time; reports CPU milliseconds per tick of the tick and
of the sessions' joint-update encoding, and bytes per soldier-update (every soldier-update after the warm-up
is of a soldier that moved). ``--protocol 1`` makes the observers speak version 1 (the joint-update format
before per-entry widths and predicted deltas, docs/PROTOCOL.md §8.5); ``--data shipped`` runs the shipped
library (channelsets/, posture_graphs/) instead of the synthetic one, for the bytes that real clips give;
``--mix moving`` the TCP measurement's soldiers (every one walking, running or crawling).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=10000)
    ap.add_argument("--clients", default="1,2,4,8")
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--warmup", type=float, default=5.0)
    ap.add_argument("--mix", default="realistic")
    ap.add_argument("--per-client", action="store_true", help="no shared encodes (TTES_SHARED_ENCODES=0)")
    ap.add_argument("--in-process", action="store_true", help="the server's CPU alone (see above)")
    ap.add_argument("--loadtest", action="store_true", help="the full load generator (see above)")
    ap.add_argument("--procs", type=int, default=1, help="observer processes (default 1)")
    ap.add_argument("--ticks", type=int, default=60, help="--in-process: measured ticks")
    ap.add_argument("--late", type=float, default=0.0,
                    help="--in-process: chance that a session misses a publish (a late writer)")  # fmt: skip
    ap.add_argument("--protocol", type=int, default=2, choices=(1, 2), help="the observers' protocol version")
    ap.add_argument(
        "--data", choices=("synthetic", "shipped"), default=None,
        help="motion library (default: synthetic --in-process, shipped over TCP)",
    )  # fmt: skip
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.per_client:
        os.environ["TTES_SHARED_ENCODES"] = "0"

    if args.in_process:
        shipped = args.data == "shipped"
        runs = [in_process(args.soldiers, int(c), args.ticks, args.protocol, shipped, args.late, args.mix)
                for c in args.clients.split(",")]  # fmt: skip
        out = {"soldiers": args.soldiers, "shared_encodes": not args.per_client, "cpus": os.cpu_count(),
               "protocol": args.protocol, "data": args.data, "late": args.late, "mix": args.mix,
               "loadavg": [round(x, 2) for x in os.getloadavg()], "runs": runs}  # fmt: skip
        print(json.dumps(out) if args.json else "\n".join(map(str, [out.pop("runs"), out])))
        return 0
    if not args.loadtest:
        return counted(args)
    from client_stub.loadtest.session import LoadTestConfig, run_loadtest

    rows = []
    for c in (int(x) for x in args.clients.split(",")):
        load = os.getloadavg()
        t0 = time.perf_counter()
        cfg = LoadTestConfig(soldiers=args.soldiers, clients=c, rate_hz=args.rate, seconds=args.seconds,
                             warmup_s=args.warmup, spawn_server=True, subscribe_all=True, mix=args.mix,
                             latency_metric="delivery")  # fmt: skip
        s = run_loadtest(cfg)
        cpu = s.get("server_cpu_pct")
        rows.append({
            "clients": c, "server_cpu_pct": cpu,
            "server_ms_per_tick": round(cpu * 10.0 / args.rate, 2) if cpu is not None else None,
            "delivered_pct": s.get("delivered_pct"), "delivery_ms_p99": s.get("delivery_ms_p99"),
            "bytes_per_update": s.get("bytes_per_update"), "client_cpu_pct": s.get("client_cpu_pct"),
            "loadavg_before": [round(x, 2) for x in load], "wall_s": round(time.perf_counter() - t0, 1),
        })  # fmt: skip
    out = {"soldiers": args.soldiers, "rate_hz": args.rate, "shared_encodes": not args.per_client,
           "cpus": os.cpu_count(), "runs": rows}  # fmt: skip
    if args.json:
        print(json.dumps(out))
        return 0
    mode = "per-client encodes" if args.per_client else "shared encodes"
    print(f"bench_fanout: {args.soldiers} soldiers at {args.rate:g} Hz, {mode}, {os.cpu_count()} CPUs")
    for r in rows:
        print(f"  {r['clients']} clients: server {r['server_cpu_pct']}% of a core ({r['server_ms_per_tick']} "
              f"ms/tick), delivered {r['delivered_pct']}%, tick->arrival p99 {r['delivery_ms_p99']} ms, "
              f"{r['bytes_per_update']} B/update, load before {r['loadavg_before']}")  # fmt: skip
    return 0


def counted(args: argparse.Namespace) -> int:
    """The counting observers over TCP, one spawned server per client count (see the module)."""
    from client_stub.loadtest.fanout import FanoutConfig, run_fanout

    rows = []
    for c in (int(x) for x in args.clients.split(",")):
        load = os.getloadavg()
        cfg = FanoutConfig(soldiers=args.soldiers, observers=c, rate_hz=args.rate, seconds=args.seconds,
                           warmup_s=args.warmup, version=args.protocol, procs=min(args.procs, c),
                           data="synthetic" if args.data == "synthetic" else "default")  # fmt: skip
        r = run_fanout(cfg)
        r["loadavg_before"] = [round(x, 2) for x in load]
        rows.append(r)
    out = {"soldiers": args.soldiers, "rate_hz": args.rate, "shared_encodes": not args.per_client,
           "protocol": args.protocol, "cpus": os.cpu_count(), "runs": rows}  # fmt: skip
    if args.json:
        print(json.dumps(out))
        return 0
    mode = "per-client encodes" if args.per_client else "shared encodes"
    print(f"bench_fanout: {args.soldiers} soldiers at {args.rate:g} Hz to counting observers, {mode}, "
          f"protocol {args.protocol}, {os.cpu_count()} CPUs")  # fmt: skip
    for r in rows:
        bps = [c["bytes_per_s"] or 0 for c in r["clients"]]  # None: a client got nothing in the window
        bpu = [c["bytes_per_update"] for c in r["clients"] if c["bytes_per_update"]]
        print(f"  {r['observers']} clients: delivered {r['delivered_pct_min']}% "
              f"(mean {r['delivered_pct_mean']}%), "
              f"server {r['server_cpu_pct']}% of a core + {r['server_wait_pct']}% waiting for one, "
              f"{r['server_ms_per_tick']} ms/tick, {round(sum(bps) / len(bps) / 1e6, 2)} MB/s per client, "
              f"{round(sum(bpu) / max(len(bpu), 1), 1)} B/update, observers {r['observer_cpu_pct']}%, "
              f"load before {r['loadavg_before']}")  # fmt: skip
    return 0


def in_process(
    soldiers: int, clients: int, ticks: int, protocol: int = 2, shipped: bool = False, late: float = 0.0,
    mix: str = "realistic",
) -> dict[str, object]:  # fmt: skip
    """CPU per tick of the server's tick and of ``clients`` observers' joint-update encoding (no sockets).

    ``late``: the chance that a session's writer misses a publish (as a writer does on a busy server or
    behind a slow socket); its next write then owes two or more publishes. ``mix="moving"``: every soldier
    walks, runs or crawls (the requests of the TCP measurement) instead of the bench's realistic mix."""
    import tempfile

    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_server import mix_requests

    from protocol.connection import CLIENT, NEED_DATA, PAUSED, Connection
    from protocol.events import DEFAULT_MAX_SOLDIERS, Hello, Subscribe
    from server.app import TtesServer
    from server.config import ServerConfig
    from server.session import Session
    from server.startup import ServerWorld, write_synthetic_data_dir

    tmp = tempfile.TemporaryDirectory(prefix="bench-fanout-")
    limits = {"throttle": 0.0, "max_soldiers": max(DEFAULT_MAX_SOLDIERS, soldiers), "max_requests_per_s": 1e9}
    if shipped:
        cfg = ServerConfig(port=0, **limits)  # type: ignore[arg-type]
    else:
        synth = write_synthetic_data_dir(tmp.name, soldiers=1)
        where = {"data_dir": synth.path, "startup_script": synth.startup_script}
        cfg = ServerConfig(port=0, **where, **limits)  # type: ignore[arg-type]
    server = TtesServer(cfg, ServerWorld(cfg.data_dir, max_soldiers=cfg.max_soldiers))
    server.start_world()
    m = server.world.manager
    assert m is not None
    for _ in range(soldiers - int(m.table.alive.sum())):
        server.world.create_soldier("DI.fig", "AK_47.fig")
    if mix == "moving":
        from client_stub.loadtest.mix import MixDriver

        requests = MixDriver(soldiers, mix="moving", seed=1).initial()
    else:
        requests = mix_requests(soldiers, np.random.default_rng(1))
    m.apply_requests(requests, server.request_time())
    pairs = []
    for k in range(clients):
        s = Session(server.world, server.board_ref, server.config, f"c{k}")
        server.sessions[s.id] = s
        c = Connection(CLIENT, decode_updates=False)
        s.feed(c.send(Hello(f"c{k}", "observer", version=protocol)))
        c.receive_data(s.take_output())
        while c.next_event() not in (NEED_DATA, PAUSED):
            pass
        s.feed(c.send(Subscribe(tuple(range(soldiers)))))
        pairs.append((s, c))
    tick_cpu = enc_cpu = 0.0
    nbytes = nrows = 0
    rng = np.random.default_rng(7)
    memo = server.board_ref.encodes
    encodes = caught = 0
    for t in range(1, ticks + 31):
        c0 = time.process_time()
        server.tick(t / 30)
        c1 = time.process_time()
        missing = (rng.random(clients) < late) & (t > 30)
        misses0, caught0 = (memo.misses, memo.caught_up) if memo is not None else (0, 0)
        outs = [b"" if miss else s.take_output() for (s, _), miss in zip(pairs, missing, strict=True)]
        c2 = time.process_time()
        if t <= 30:
            continue  # warm-up: the first full updates, soldiers getting under way
        if memo is not None:
            encodes += memo.misses - misses0
            caught += memo.caught_up - caught0
        tick_cpu += c1 - c0
        enc_cpu += c2 - c1
        for (_, c), data in zip(pairs, outs, strict=True):
            if not data:
                continue
            c.receive_data(data)
            while (ev := c.next_event()) is not NEED_DATA and ev is not PAUSED:
                nrows += len(getattr(ev, "indices", ()))
            nbytes += len(data)
    return {"clients": clients, "tick_ms": round(1000 * tick_cpu / ticks, 2),
            "encode_ms": round(1000 * enc_cpu / ticks, 2),
            "server_ms_per_tick": round(1000 * (tick_cpu + enc_cpu) / ticks, 2),
            "bytes_per_update": round(nbytes / max(nrows, 1), 2),
            "updates_per_tick": round(nrows / ticks / clients),
            "encodes_per_tick": round(encodes / ticks, 2),
            "caught_up_per_tick": round(caught / ticks, 2)}  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
