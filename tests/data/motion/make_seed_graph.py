"""Regenerate the seed's posture graph (seed 002, Figure 7) and its 17 small channelsets.

Run ``python tests/data/motion/make_seed_graph.py``. Figure 7 elides most lines; the missing files and arcs
are invented to match Figure 3 and the text: reverse transitions play the forward file backwards, DEAD is left
only by playing ststow2dead backwards (10 s), there is no direct PRONE_FIRE <-> KNEEL_FIRE transition, and the
quickest way from STAND_STOWED to PRONE_FIRE is STAND_STOWED -> CRAWL -> PRONE_STOWED -> PRONE_FIRE (3.6 s).

Each channelset is recorded at 10 fps for the toy figures of ``server.motion.synthetic`` (``toy_soldier.fig``
with 7 DOFs, ``toy_rifle.fig``) and moves from the start posture's pose to the end posture's pose
(smoothstep), so consecutive transitions join exactly.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2]))

from server.motion.channelset import FigureTrack, JointTrack, make_channelset  # noqa: E402
from server.motion.channelset_file import save_channelset  # noqa: E402
from server.motion.posture_graph import Arc, PostureGraph, write_posture_graph  # noqa: E402
from server.soldier.synthetic import ONE_WAY, POSTURES, STATIC_FILES  # noqa: E402  (the same Figure 7 table)

FPS = 10
FILES = STATIC_FILES  # token: (file stem, start, end, seconds); every file is played forwards start->end
SS, SF, KS, KF, PS, PF, CR, DE = POSTURES

# pose vector (waist x3, neck x2, right_knee, left_knee), pelvis height (cm), heading (deg), rifle raised?
POSES = {
    SS: ([0.0, 0.0, 0.0], [0.0, 0.0], 0.0, 0.0, 98.0, 0.0, False),
    SF: ([0.0, 0.2, 0.0], [0.1, 0.0], 0.0, 0.0, 98.0, 15.0, True),
    KS: ([0.3, 0.0, 0.0], [0.0, 0.0], 1.6, 0.1, 60.0, 0.0, False),
    KF: ([0.3, 0.2, 0.0], [0.1, 0.0], 1.6, 0.1, 60.0, 15.0, True),
    PS: ([1.4, 0.0, 0.0], [-0.6, 0.0], 0.0, 0.0, 15.0, 0.0, False),
    PF: ([1.4, 0.1, 0.0], [-0.8, 0.1], 0.0, 0.0, 15.0, 10.0, True),
    CR: ([1.2, 0.0, 0.1], [-0.5, 0.0], 0.4, 0.2, 25.0, 0.0, False),
    DE: ([1.5, 0.0, 0.5], [-0.2, 0.4], 0.3, 0.6, 12.0, -30.0, False),
}


def _state(p: str) -> tuple[np.ndarray, float, float, bool]:
    waist, neck, rk, lk, height, heading, raised = POSES[p]
    return np.array([*waist, *neck, rk, lk]), height, heading, raised


def _placement(height: float, heading_deg: float, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    h = math.radians(heading_deg)
    m = np.eye(4)
    m[0, 0] = m[2, 2] = math.cos(h)
    m[0, 2] = math.sin(h)
    m[2, 0] = -math.sin(h)
    m[:3, 3] = (dx, height + dy, 0.0)
    return m


def make_file(stem: str, start: str, end: str, seconds: float) -> None:
    n = round(seconds * FPS) + 1
    s = np.linspace(0.0, 1.0, n)
    w = s * s * (3 - 2 * s)  # smoothstep: starts and ends at rest
    p0, h0, a0, r0 = _state(start)
    p1, h1, a1, r1 = _state(end)
    pose = p0 + (p1 - p0) * w[:, None]
    height = h0 + (h1 - h0) * w
    heading = a0 + (a1 - a0) * w
    lift = (float(r0) + (float(r1) - float(r0)) * w) * 20.0
    soldier = np.stack([_placement(height[i], heading[i]) for i in range(n)])
    rifle = np.stack([_placement(height[i] + 30.0, heading[i], dx=20.0, dy=lift[i]) for i in range(n)])
    tracks = [
        FigureTrack("soldier", "toy_soldier.fig", "soldier", ["s0.proximal"] * n, soldier),
        FigureTrack("rifle", "toy_rifle.fig", "rifle", ["s0.proximal"] * n, rifle),
        JointTrack("waist", "toy_soldier.fig", "waist", pose[:, 0:3]),
        JointTrack("neck", "toy_soldier.fig", "neck", pose[:, 3:5]),
        JointTrack("right.knee", "toy_soldier.fig", "right_knee", pose[:, 5:6]),
        JointTrack("left_knee", "toy_soldier.fig", "left_knee", pose[:, 6:7]),
    ]
    save_channelset(make_channelset(f"{stem}_low.chset", FPS, tracks), HERE / f"{stem}_low.chset.env")


def main() -> None:
    arcs: list[Arc] = []
    for token, (stem, start, end, seconds) in enumerate(FILES):
        make_file(stem, start, end, seconds)
        arcs.append(Arc(start, end, token, True, seconds))
        if end not in ONE_WAY:
            arcs.append(Arc(end, start, token, False, seconds))
    arcs.append(Arc(DE, SS, 4, False, 10.0))
    graph = PostureGraph(POSTURES, [f"{stem}_low.chset.env" for stem, *_ in FILES], arcs)
    write_posture_graph(graph, HERE / "soldier_low.graph")


if __name__ == "__main__":
    main()
