"""Benchmark: the soldier manager's tick (Figures 5 and 12, vectorised) for thousands of soldiers.

A realistic mix of soldiers on the synthetic motion library (50-DOF DI.fig-shaped soldier + rifle): resting,
changing posture, walking, running, walking backwards and crawling; a few percent of them get a new request
every tick (speed changes, posture changes, stops and starts), as a TTES client driving many soldiers would
send. Ticks run at 30 Hz of simulated time (no sleeping). Reports microseconds per tick (requests + tick),
the largest soldier count whose tick fits the 33 ms of a 30 Hz frame on one core (measured, then refined by a
linear fit), and what the wire would carry for one client subscribed to every soldier (encode time, bytes/s).

    python bench/bench_server_core.py [--soldiers 10000] [--seconds 4] [--json]
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

from protocol.entity import Appearance, WeaponState, make_entity_requests
from protocol.events import DEFAULT_MAX_SOLDIERS
from server.soldier.manager import SoldierManager
from server.soldier.synthetic import synthetic_motion_library

HZ = 30.0
BUDGET_S = 1.0 / HZ
# (share, appearance, weapon, speed m/s, backward)
MIX = [
    (0.35, Appearance.UPRIGHT, WeaponState.DEPLOYED, 0.0, False),  # resting
    (0.05, Appearance.KNEEL, WeaponState.FIRING, 0.0, False),  # resting, kneeling
    (0.25, Appearance.UPRIGHT, WeaponState.DEPLOYED, 1.4, False),  # walking
    (0.10, Appearance.UPRIGHT, WeaponState.DEPLOYED, 4.0, False),  # running
    (0.05, Appearance.UPRIGHT, WeaponState.DEPLOYED, 0.8, True),  # walking backwards
    (0.10, Appearance.PRONE, WeaponState.DEPLOYED, 0.4, False),  # crawling
    (0.10, Appearance.UPRIGHT, WeaponState.FIRING, 0.0, False),  # posture changes (cycled below)
]
CHANGE_SHARE = 0.02  # soldiers with a new request per tick


def build(n: int, seed: int = 1) -> tuple[SoldierManager, np.ndarray, np.random.Generator]:
    lib = synthetic_motion_library()
    mgr = SoldierManager(lib, throttle=1 / 30, max_soldiers=max(n, DEFAULT_MAX_SOLDIERS))
    for _ in range(n):
        mgr.create_soldier()
    rng = np.random.default_rng(seed)
    shares = np.array([m[0] for m in MIX])
    kind = rng.choice(len(MIX), n, p=shares / shares.sum())
    app = np.array([MIX[k][1] for k in kind])
    wpn = np.array([MIX[k][2] for k in kind])
    speed = np.array([MIX[k][3] for k in kind])
    back = np.array([MIX[k][4] for k in kind])
    hdg = rng.uniform(0, 360, n)
    rows = _requests(np.arange(n), app, wpn, speed, back, hdg)
    mgr.apply_requests(rows, 0.0)
    return mgr, kind, rng


def _requests(idx, app, wpn, speed, back, hdg) -> np.ndarray:
    h = np.radians(hdg)
    sign = np.where(back, -1.0, 1.0)
    vel = np.stack([np.sin(h) * speed * sign, np.cos(h) * speed * sign, np.zeros_like(h)], axis=1)
    return make_entity_requests(idx, app, wpn, vel, hdg, (0.0, 0.0, 0.0))


def churn(mgr: SoldierManager, kind: np.ndarray, rng: np.random.Generator, now: float) -> np.ndarray:
    """A few percent of soldiers get a new request: speed jitter, posture cycling, stop/start."""
    n = len(kind)
    m = max(1, int(n * CHANGE_SHARE))
    idx = np.unique(rng.integers(0, n, m))
    k = kind[idx]
    app = np.array([MIX[x][1] for x in k])
    wpn = np.array([MIX[x][2] for x in k])
    speed = np.array([MIX[x][3] for x in k]) * rng.uniform(0.7, 1.3, len(idx))
    back = np.array([MIX[x][4] for x in k])
    cyc = k == len(MIX) - 1
    postures = np.array([Appearance.UPRIGHT, Appearance.KNEEL, Appearance.PRONE, Appearance.UPRIGHT])
    app[cyc] = postures[rng.integers(0, 4, cyc.sum())]
    wpn[cyc] = np.where(rng.random(cyc.sum()) < 0.5, WeaponState.FIRING, WeaponState.DEPLOYED)
    stop = rng.random(len(idx)) < 0.1
    speed[stop] = 0.0
    return _requests(idx, app, wpn, speed, back, rng.uniform(0, 360, len(idx)))


def run(n: int, seconds: float, encode: bool = False) -> dict:
    mgr, kind, rng = build(n)
    warm = int(HZ)  # one second of warm-up: everyone in their gait
    for k in range(1, warm + 1):
        mgr.tick(k / HZ)
    ticks = int(seconds * HZ)
    times = np.empty(ticks)
    updates = 0
    enc_s = 0.0
    nbytes = 0
    conv = encoder = None
    if encode:
        from protocol.updates import UpdateEncoder
        from server.soldier.wire import WireConverter, update_table_for

        table = update_table_for(mgr.library, 1)
        conv = WireConverter(mgr.library, table)
        encoder = UpdateEncoder(table, max_soldiers=max(n, 1))
    cpu0 = time.process_time()
    wall0 = time.perf_counter()
    for k in range(ticks):
        now = (warm + 1 + k) / HZ
        rows = churn(mgr, kind, rng, now)
        t0 = time.perf_counter()
        mgr.apply_requests(rows, now)
        upd = mgr.tick(now)
        times[k] = time.perf_counter() - t0
        updates += len(upd)
        if encode and conv is not None and encoder is not None:
            t1 = time.perf_counter()
            payloads = encoder.encode(conv.convert(upd), 1 << 20)
            enc_s += time.perf_counter() - t1
            nbytes += sum(len(p) for p in payloads)
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    st = mgr.status()
    out = {
        "soldiers": n,
        "ticks": ticks,
        "us_per_tick_mean": float(times.mean() * 1e6),
        "us_per_tick_p50": float(np.percentile(times, 50) * 1e6),
        "us_per_tick_p99": float(np.percentile(times, 99) * 1e6),
        "us_per_tick_max": float(times.max() * 1e6),
        "updates_per_tick": updates / ticks,
        "core_share_of_realtime": float(times.sum()) / (ticks / HZ),  # requests + tick, one core
        "process_cpu_share_of_realtime": cpu / (ticks / HZ),  # everything measured, encoding included
        "modes": st["modes"],
        "events": st["events"],
        "clip_ends": st["clip_ends"],
        "wall_s": wall,
    }
    if encode:
        out["encode_us_per_tick"] = enc_s / ticks * 1e6
        out["wire_bytes_per_second_one_client"] = nbytes / (ticks / HZ)
    return out


def largest_n(start: int, seconds: float) -> dict:
    """Double the soldier count until a mean tick exceeds 33 ms, then interpolate linearly."""
    points = []
    n = start
    while True:
        r = run(n, seconds)
        points.append((n, r["us_per_tick_mean"] / 1e6))
        if points[-1][1] > BUDGET_S or n >= 400_000:
            break
        n *= 2
    ns = np.array([p[0] for p in points], float)
    ts = np.array([p[1] for p in points])
    if len(ns) >= 2:
        slope, icept = np.polyfit(ns[-2:], ts[-2:], 1)
        est = int((BUDGET_S - icept) / slope) if slope > 0 else int(ns[-1])
    else:
        est = int(ns[0] * BUDGET_S / ts[0])
    return {"measured": [{"soldiers": int(a), "ms_per_tick": b * 1e3} for a, b in points], "largest_n": est}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", type=int, default=10_000)
    ap.add_argument("--seconds", type=float, default=4.0, help="simulated seconds measured per run")
    ap.add_argument("--no-search", action="store_true", help="skip the search for the largest count")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    main_run = run(args.soldiers, args.seconds, encode=True)
    result = {"benchmark": "server_core", "hz": HZ, "cpu_count": os.cpu_count(), "main": main_run}
    if not args.no_search:
        result["capacity"] = largest_n(args.soldiers, min(args.seconds, 2.0))
    if args.json:
        print(json.dumps(result))
        return 0
    r = main_run
    print(
        f"{r['soldiers']} soldiers @ {HZ:.0f} Hz: {r['us_per_tick_mean']:.0f} us/tick mean "
        f"(p50 {r['us_per_tick_p50']:.0f}, p99 {r['us_per_tick_p99']:.0f}, max {r['us_per_tick_max']:.0f}), "
        f"{r['updates_per_tick']:.0f} updates/tick, "
        f"core {100 * r['core_share_of_realtime']:.0f}% of one CPU "
        f"(process incl. encoding {100 * r['process_cpu_share_of_realtime']:.0f}%)"
    )
    print(f"  modes {r['modes']}, {r['events']} request events, {r['clip_ends']} clip ends")
    print(
        f"  wire, one client subscribed to all: encode {r['encode_us_per_tick']:.0f} us/tick, "
        f"{r['wire_bytes_per_second_one_client'] / 1e6:.2f} MB/s"
    )
    if "capacity" in result:
        cap = result["capacity"]
        pts = ", ".join(f"{p['soldiers']}: {p['ms_per_tick']:.1f} ms" for p in cap["measured"])
        print(f"  largest count within {BUDGET_S * 1e3:.1f} ms/tick: ~{cap['largest_n']} ({pts})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
