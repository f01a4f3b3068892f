"""Benchmark the authoring IK solver and slaving: how long does re-solving a whole clip take?

* DI.fig, one clip of 120 frames: both palm centres on a rifle (priority 1) and both heels planted with their
  orientation (priority 0), every frame in one batched ``solve`` call;
* soldier.fig (134 DOFs), the same goals on 120 frames;
* slaving 120 frames of soldier.fig onto DI.fig (copy, spine blend, the seed's 7-goal constraint table).

    python bench/bench_ik.py [--json] [--frames N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from authoring.ik import Goal, solve
from authoring.slaving import create_master_slave_pair
from peabody.fk import FigureKinematics
from peabody.loader import read_figure

ROOT = Path(__file__).resolve().parents[1]


def _poses(kin: FigureKinematics, n: int, seed: int, spread: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    span = np.minimum(kin.upper - kin.lower, 2.0)
    q = kin.neutral_pose() + rng.uniform(-1, 1, (n, kin.ndof)) * spread * span / 2
    for side in ("left", "right"):  # forearms up, as when holding a rifle
        q[:, kin.dof_slices[f"{side}_shoulder"]] += [0.2, 0.5, 0.3]
        q[:, kin.dof_slices[f"{side}_elbow"]] += [1.3, 0.4]
    return np.clip(q, kin.lower, kin.upper)


def clip_goals(kin: FigureKinematics, n: int) -> tuple[np.ndarray, list[Goal]]:
    """Start poses and goals taken from other reachable poses (so every goal can be met)."""
    target = kin.site_globals(_poses(kin, n, seed=1, spread=0.15))
    goals = []
    for side in ("left", "right"):
        palm = f"{side}_palm.palmcenter"
        goals.append(Goal(palm, target[:, kin.site_names.index(palm), :3, 3], priority=1))
        heel = kin.site_globals(kin.neutral_pose())[kin.site_names.index(f"{side}_foot.heel")]
        legs = [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
        goals.append(Goal(f"{side}_foot.heel", heel[:3, 3], heel[:3, :3], joints=legs))
    return _poses(kin, n, seed=2, spread=0.15), goals


def timed(fn):  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--frames", type=int, default=120)
    args = ap.parse_args()
    n = args.frames
    results: dict[str, object] = {"frames": n}
    for name in ("DI", "soldier"):
        kin = FigureKinematics(read_figure(ROOT / "figures" / f"{name}.fig", load_psurfs=False))
        start, goals = clip_goals(kin, n)
        dt, (_, report) = timed(lambda k=kin, s=start, g=goals: solve(k, s, g, iterations=100))
        results[f"{name}_solve_s"] = round(dt, 4)
        results[f"{name}_ms_per_frame"] = round(1000 * dt / n, 3)
        results[f"{name}_iterations"] = report.iterations
        results[f"{name}_converged"] = round(float(report.converged.mean()), 4)
        results[f"{name}_max_error_cm"] = round(report.max_position_error, 5)
    master = read_figure(ROOT / "figures" / "soldier.fig", load_psurfs=False)
    slave = read_figure(ROOT / "figures" / "DI.fig", load_psurfs=False)
    pair = create_master_slave_pair(master, slave)
    q = _poses(pair.master_kin, n, seed=3, spread=0.15)
    dt, (sq, sloc) = timed(lambda: pair.slave_pose(q))
    mk, sk = pair.master_kin, pair.slave_kin
    ms, ss = mk.site_globals(q), sk.site_globals(sq, sloc)
    palm = [
        np.linalg.norm(
            ms[:, mk.site_names.index(p), :3, 3] - ss[:, sk.site_names.index(p), :3, 3], axis=1
        ).max()
        for p in ("left_palm.palmcenter", "right_palm.palmcenter")
    ]
    results["slaving_s"] = round(dt, 4)
    results["slaving_ms_per_frame"] = round(1000 * dt / n, 3)
    results["slaving_palm_max_cm"] = round(float(max(palm)), 4)
    if args.json:
        print(json.dumps(results))
    else:
        for name in ("DI", "soldier"):
            print(
                f"{name:8s} {n} frames, 4 goals: {results[f'{name}_solve_s']:.3f} s "
                f"({results[f'{name}_ms_per_frame']:.2f} ms/frame, "
                f"{results[f'{name}_iterations']} iterations, "
                f"max error {results[f'{name}_max_error_cm']:.4f} cm)"
            )
        print(
            f"slaving  {n} frames, 7 goals: {results['slaving_s']:.3f} s "
            f"({results['slaving_ms_per_frame']:.2f} ms/frame, "
            f"palms within {results['slaving_palm_max_cm']:.4f} cm)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
