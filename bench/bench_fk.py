"""Benchmark batched forward kinematics (and the Peabody parser's channelset-line throughput).

FK of 10,000 random poses of ``figures/DI.fig`` (23 joints / 50 DOFs / 24 segments) when it exists, else
of a synthetic figure with the same counts and a human-like tree.  Also parses 50,000 channelset frame lines
of each common shape.

    python bench/bench_fk.py [--json] [--poses N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from peabody import values as V
from peabody.fk import FigureKinematics
from peabody.language import parse
from peabody.loader import read_figure
from peabody.model import Dof, Figure, Joint, Segment, Site

ROOT = Path(__file__).resolve().parents[1]
AXES = [np.array(a, dtype=float) for a in ((0, 0, 1), (1, 0, 0), (0, 1, 0))]


def synthetic_figure() -> Figure:
    """24 segments, 23 joints, 50 DOFs: spine+head, two arms, two legs, a helmet."""
    parents = [-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 15, 16, 0, 18, 19, 20, 21, 4]
    fig = Figure("synthetic")
    rng = np.random.default_rng(3)
    for i in range(len(parents)):
        seg = fig.add_segment(Segment(f"s{i}"))
        seg.add_site(Site("proximal"))
        distal = V.translation(*rng.uniform(-5, 5, 2), 0) @ V.translation(0, 0, rng.uniform(10, 40))
        seg.add_site(Site("distal", distal))
        seg.add_site(Site("marker", V.translation(*rng.uniform(-3, 3, 3))))
    ndofs = [3, 3, 3, 3] + [2] * 19
    for j, (child, parent) in enumerate(((c, p) for c, p in enumerate(parents) if p >= 0)):
        dofs = [Dof("R", AXES[k % 3], -1.5, 1.5) for k in range(ndofs[j])]
        site1 = fig.segments[f"s{parent}"].sites["distal"]
        site2 = fig.segments[f"s{child}"].sites["proximal"]
        fig.add_joint(Joint(f"j{child}", site1, site2, dofs))
    fig.root = fig.segments["s0"].sites["proximal"]
    fig.location = V.translation(0, 98, 0)
    return fig


def best_of(fn, repeats: int = 5) -> float:  # type: ignore[no-untyped-def]
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--poses", type=int, default=10_000)
    args = ap.parse_args()

    di = ROOT / "figures" / "DI.fig"
    figure = read_figure(di, load_psurfs=False) if di.exists() else synthetic_figure()
    fk = FigureKinematics(figure)
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(fk.lower), fk.lower, -np.pi)
    hi = np.where(np.isfinite(fk.upper), fk.upper, np.pi)
    poses = rng.uniform(lo, hi, size=(args.poses, fk.ndof))

    t_seg = best_of(lambda: fk.segment_globals(poses))
    t_site = best_of(lambda: fk.site_globals(poses))
    t_one = best_of(lambda: fk.segment_globals(poses[0]), repeats=50)
    deep = max(fk.site_names, key=lambda n: len(fk.joint_path(fk.root_name, n)))  # GetSiteGlobal's worst case
    t_site_one = best_of(lambda: fk.site_global(deep, poses[0]), repeats=50)
    t_build = best_of(lambda: FigureKinematics(figure), repeats=5)

    lines = {
        "figure_frame": '    frame[%d] = ("lower_torso.proximal", trans(31.68cm,43.53cm,-31.05cm));\n',
        "joint_frame": "    frame[%d] = (0.1, -0.2, 0.3);\n",
    }
    parse_rate = {}
    for key, line in lines.items():
        text = "channelset c { sharedchannel s {\n" + "".join(line % i for i in range(50_000)) + "}}\n"
        parse_rate[key] = round(50_000 / best_of(lambda text=text: parse(text), repeats=3))

    result = {
        "figure": figure.filename or figure.name,
        "segments": len(fk.segment_names),
        "joints": len(fk.joint_names),
        "dofs": fk.ndof,
        "sites": len(fk.site_names),
        "poses": args.poses,
        "segment_globals_s": round(t_seg, 4),
        "segment_globals_poses_per_s": round(args.poses / t_seg),
        "site_globals_s": round(t_site, 4),
        "single_pose_ms": round(t_one * 1e3, 3),
        "site_global_ms": round(t_site_one * 1e3, 3),
        "site_global_site": deep,
        "build_ms": round(t_build * 1e3, 3),
        "parse_lines_per_s": parse_rate,
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"FK {result['figure']}: {result['segments']} segments, {result['joints']} joints, "
            f"{result['dofs']} DOFs, {result['sites']} sites"
        )
        rate = result["segment_globals_poses_per_s"]
        print(f"  {args.poses} poses: segments {t_seg * 1e3:.1f} ms ({rate} poses/s)")
        print(f"  sites {t_site * 1e3:.1f} ms")
        print(f"  one pose (all segments) {t_one * 1e3:.3f} ms; precompute {t_build * 1e3:.2f} ms")
        print(f"  site_global({deep}) {t_site_one * 1e3:.3f} ms")
        for key, r in parse_rate.items():
            print(f"  parser, {key} lines: {r} lines/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
