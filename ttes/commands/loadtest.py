"""`ttes loadtest`: drive N soldiers over C connections with a realistic DIS-rate mix and measure the server.

Measures over the steady state: steady-mover updates received per second against those expected (every
walking, running or crawling soldier in every tick the server's throttle lets it have: READY's tick rate
and throttle), request -> first reflecting update latency (p50, p99,
max), bytes per soldier update, dropped and late updates, and the server's CPU (when it was spawned, or
given by --server-pid); and what the server says it is (its STATUS: a front-end names its shards). --ramp
grows N until the server falls behind and reports the largest N it sustained. Loopback by default; every
loop is bounded in count and time.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from ttes.arguments import UsageError, count, host, non_negative, number, port, positive
from ttes.link_options import add_link_options, link_credentials
from ttes.output import na

if TYPE_CHECKING:
    from client_stub.loadtest.session import LoadTestConfig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "loadtest", help="load-test a Jack/TTES server with many soldiers", description=__doc__
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--spawn-server", action="store_true", help="run a `ttes server` child on loopback")
    where.add_argument("--host", type=host, default="127.0.0.1", help="server address (default 127.0.0.1)")
    p.add_argument("--port", type=port, default=7000, help="server port (default 7000)")
    p.add_argument("--soldiers", type=count(1), default=100, help="soldiers N (the first stage with --ramp)")
    p.add_argument("--clients", type=count(1), default=2, help="client connections C sharing the soldiers")
    p.add_argument(
        "--rate", type=positive, default=30.0, help="update rate HZ (the spawned server's tick rate)"
    )
    p.add_argument("--seconds", type=positive, default=10.0, help="steady-state seconds measured (per stage)")
    p.add_argument("--warmup", type=non_negative, default=3.0, help="seconds before measuring (per stage)")
    p.add_argument("--mix", choices=("realistic", "moving"), default="realistic", help="what the soldiers do")
    p.add_argument("--seed", type=int, default=1, help="the mix's and the step jitter's random seed")
    p.add_argument(
        "--no-jitter",
        action="store_true",
        help="step the mix at a fixed phase (10 Hz divides the tick rate: every request then lands at one "
        "phase of the tick period, and the latency measures that phase only)",
    )
    p.add_argument(
        "--subscribe-all",
        action="store_true",
        help="every connection subscribes to every soldier (the connections are then one client: all its "
        "soldiers count against the server's per-client cap, 4,096 by default)",
    )
    p.add_argument("--decode", action="store_true", help="decode every joint update (as an image generator)")
    p.add_argument(
        "--server-data",
        choices=("auto", "synthetic", "default"),
        default="auto",
        help="spawned server's motion library (auto: the shipped one if present, else synthetic)",
    )
    p.add_argument(
        "--throttle", default="0", help="spawned server's --throttle seconds, or 'script' (default 0)"
    )
    p.add_argument(
        "--server-pid", type=count(1), help="PID of an external server on this machine (for its CPU)"
    )
    p.add_argument("--ramp", action="store_true", help="grow N until the server falls behind")
    p.add_argument("--ramp-factor", type=float, default=1.3, help="N multiplier per ramp stage")
    p.add_argument("--ramp-max-soldiers", type=count(1), default=8000)
    p.add_argument("--ramp-max-seconds", type=positive, default=600.0, help="wall-clock bound of the ramp")
    p.add_argument(
        "--min-delivered-pct", type=number(0, 100), default=99.0, help="ramp criterion: delivered/expected"
    )
    p.add_argument(
        "--max-p99-ms",
        type=positive,
        metavar="MS",
        help="ramp criterion: p99 latency (default 100 ms, DIS's budget for tightly coupled interactions; a "
        "request waits up to one server tick before it is computed)",
    )
    p.add_argument(
        "--latency-metric",
        choices=("request", "delivery"),
        default="request",
        help="ramp latency criterion: request->update, or server tick->arrival (excludes the tick wait)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="FILE.png", help="write throughput and latency over time")
    add_link_options(p)
    p.set_defaults(func=run)


def config(args: argparse.Namespace) -> LoadTestConfig:
    """The load test the arguments ask for (the library's defaults where an option has none of its own)."""
    from client_stub.loadtest.session import LoadTestConfig

    throttle: float | None = None if args.throttle == "script" else float(args.throttle)
    return LoadTestConfig(
        soldiers=args.soldiers,
        clients=args.clients,
        rate_hz=args.rate,
        seconds=args.seconds,
        warmup_s=args.warmup,
        host=args.host,
        port=args.port,
        spawn_server=args.spawn_server,
        server_data=args.server_data,
        server_pid=args.server_pid,
        throttle=throttle,
        mix=args.mix,
        seed=args.seed,
        step_jitter=not args.no_jitter,
        subscribe_all=args.subscribe_all,
        decode=args.decode,
        ramp=args.ramp,
        ramp_factor=args.ramp_factor,
        ramp_max_soldiers=args.ramp_max_soldiers,
        ramp_max_s=args.ramp_max_seconds,
        min_delivered_pct=args.min_delivered_pct,
        max_p99_ms=LoadTestConfig.max_p99_ms if args.max_p99_ms is None else args.max_p99_ms,
        latency_metric=args.latency_metric,
        credentials=link_credentials(args),
    )


def run(args: argparse.Namespace) -> int:
    from client_stub.link.spawn import SpawnError
    from client_stub.loadtest.client import LoadError
    from client_stub.loadtest.session import run_loadtest
    from ttes.output import print_json

    cfg = config(args)
    try:  # values that do not go together (more clients than soldiers): a usage error
        cfg.check()
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    from server.gc_freeze import freeze_loaded
    from ttes.progress import ProgressBar

    freeze_loaded()  # the generator's imports out of its GC's full collections (24 ms stalls, as a server's)
    try:
        with ProgressBar("ttes loadtest") as bar:
            result = run_loadtest(cfg, progress=bar)
    except (LoadError, SpawnError) as exc:
        print(f"ttes loadtest: error: {exc}", file=sys.stderr)
        return 1
    if args.plot:
        from client_stub.loadtest.plot import plot_result

        plot_result(result, args.plot)
    if args.json:
        print_json(result)
    else:
        print(format_result(result))
    return 0


def format_result(r: dict) -> str:
    """A short human summary ("n/a" where a value could not be measured)."""

    def f(key: str, unit: str = "") -> str:
        return na(r.get(key), unit)

    from client_stub.loadtest.role import role_line
    from client_stub.loadtest.worst import worst_line

    if r.get("ramp"):
        return _format_ramp(r)
    worst = worst_line(r.get("worst_probes") or [], r.get("probes_over_1s_causes"))
    return "\n".join(
        [
            f"ttes loadtest: {r['soldiers']} soldiers, {r['clients']} clients, {r['rate_hz']:g} Hz, "
            f"{r['seconds']:g} s steady state ({r.get('mode')} mode)",
            f"  server                  {role_line(r.get('server', {}))}",
            f"  steady-mover updates/s  {f('updates_per_s')} of {f('expected_updates_per_s')} expected "
            f"({f('delivered_pct', '%')}; {f('steady_movers_mean')} movers on average; server "
            f"{f('ready_tick_hz', ' Hz')}, throttle {f('ready_throttle', ' s')}: one update per "
            f"{f('ticks_per_update')} tick(s))",
            f"  all soldier updates/s   {f('all_updates_per_s')} "
            f"(nominal N x rate = {f('nominal_updates_per_s')})",
            f"  latency request->update p50 {f('latency_ms_p50', ' ms')}, p99 {f('latency_ms_p99', ' ms')}, "
            f"max {f('latency_ms_max', ' ms')} ({f('latency_samples')} probes; "
            f"{f('probes_over_1s')} over 1 s, {f('probes_over_1s_superseded')} of them superseded)",
            *([f"  {worst}"] if worst else []),
            f"  tick->arrival p50 {f('delivery_ms_p50', ' ms')}, p99 {f('delivery_ms_p99', ' ms')}; "
            f"dropped {f('dropped_updates')}, late {f('late_updates')} ({f('late_pct', '%')})",
            f"  bytes per update        {f('bytes_per_update')} ({f('bytes_per_s')} bytes/s)",
            f"  server CPU              {f('server_cpu_pct', '%')} of one core; load generator "
            f"{f('client_cpu_pct', '%')}",
        ]
    )


def _format_ramp(r: dict) -> str:
    """The ramp's verdict (which criterion the failing stage missed) and one line per stage."""
    from client_stub.loadtest.role import role_line

    c = r["criteria"]
    latency = f"p99 {c['latency_metric']} latency <= {c['max_p99_ms']:g} ms"
    criteria = f"delivered >= {c['min_delivered_pct']:g}%, {latency}"
    best, first_fail = r["largest_sustained_soldiers"], r["first_failed_soldiers"]
    last = r["stages"][-1] if r["stages"] else {}
    if best is None:
        verdict = (
            f"  no N sustained: the first stage (N={first_fail}) failed ({last.get('failed_on', '')}); "
            "try a smaller --soldiers, or a looser --max-p99-ms / --min-delivered-pct"
        )
    else:
        more = f"N={first_fail} failed ({last.get('failed_on', '')})" if first_fail else "none failed"
        verdict = f"  largest sustained N = {best} ({more})"
    lines = [
        f"ttes loadtest --ramp: {r['clients']} clients at {r['rate_hz']:g} Hz, criteria: {criteria}",
        verdict,
        f"  server: {role_line(r.get('server', {}))}",
    ]
    for s in r["stages"]:
        lines.append(
            f"  N={s['soldiers']:>6}  delivered {na(s['delivered_pct'], '%')}  updates/s "
            f"{na(s['updates_per_s'])} of {na(s['expected_updates_per_s'])}  latency p50/p99 "
            f"{na(s['latency_ms_p50'])}/{na(s['latency_ms_p99'])} ms  "
            f"tick->arrival p99 {na(s['delivery_ms_p99'], ' ms')}  "
            f"server CPU {na(s['server_cpu_pct'], '%')}  "
            f"{'ok' if s['passed'] else 'FAIL'}"
        )
    return "\n".join(lines)
