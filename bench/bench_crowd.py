"""Benchmark: the crowd renderer's frames per second at 100, 1,000 and 5,000 soldiers (`ttes crowd`).

1280×720, offscreen EGL on Mesa llvmpipe (CPU only), the village terrain, the realistic mix posed on the
client (``--offline``: no server competes for the CPU), the default levels of detail (soldier.fig within
10 m, DI.fig within 30 m, impostors beyond) and the default orbiting camera at the crowd's edge. A frame is
everything from the pose update to ``glFinish``. ``--server`` adds a run fed by a spawned server's update
stream.

    python bench/bench_crowd.py [--soldiers 100,1000,5000] [--seconds 6] [--server] [--json]
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
    ap.add_argument("--soldiers", default="100,1000,5000")
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--server", action="store_true", help="also 1,000 soldiers fed by a spawned server")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    os.environ.setdefault("PYTHONWARNINGS", "ignore")

    from client_stub.crowd.app import CrowdConfig, run_crowd

    width, height = (int(v) for v in args.size.split("x"))
    machine = Machine()
    runs = []
    plan = [(int(n), "offline") for n in args.soldiers.split(",")]
    if args.server:
        plan.append((1000, "server"))
    for n, source in plan:
        st = run_crowd(
            CrowdConfig(soldiers=n, seconds=args.seconds, width=width, height=height, source=source,
                        spawn_server=source == "server")
        )  # fmt: skip
        st.pop("_image", None)
        runs.append(
            {k: st.get(k) for k in ("soldiers", "source", "fps", "frame_ms_p50", "frame_ms_max", "frames",
                                    "cpu_ms_per_frame",
                                    "mean_drawn", "triangles_last_frame", "posing",
                                    "soldier_updates_received")}
        )  # fmt: skip
    out = {
        "width": width,
        "height": height,
        "renderer": "llvmpipe (EGL)",
        "fps": {f"{r['soldiers']}{'' if r['source'] == 'offline' else '_server'}": r["fps"] for r in runs},
        "runs": runs,
        **machine.facts(),
    }
    if args.json:
        print(json.dumps(out))
        return 0
    print(
        f"bench_crowd: {width}x{height}, {os.cpu_count()} CPUs, load average before {out['loadavg_before']}"
    )
    for r in runs:
        d = r["mean_drawn"]
        print(
            f"  {r['soldiers']:>5} soldiers ({r['source']}): {r['fps']} fps, "
            f"frame p50 {r['frame_ms_p50']} ms, "
            f"max {r['frame_ms_max']} ms, CPU {r['cpu_ms_per_frame']} ms/frame; "
            f"drawn near/mid/far {d['near']}/{d['mid']}/{d['far']}, "
            f"{r['triangles_last_frame']} triangles"
        )
    print(f"  {out['wall_s']} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
