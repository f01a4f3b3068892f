"""A slave lying on its belly keeps its feet as low as the master's (crawl2prstow's turn on the belly).

While the soldier turns over on his belly his feet skim 3-3.7 cm over the ground
(:mod:`authoring.crawl_prone`). The DI/M16 slave is held 1.4 cm higher there (:mod:`authoring.slave_belly`:
its belly reaches lower) and its foot mesh sits about 0.7 cm lower on the toes than soldier.fig's, so its
feet stayed 5-6 cm up for 0.9 s: both feet held up while he lies (the check's ``lying_feet_raised_s``).
Over a window of the clip each slave foot higher than the master's is brought down to it (never below
:data:`FLOOR_CM`, clear of the contact height) by the leg alone, frame by frame: its toes' tip goes down, the
hip, knee and ankle solved (a couple of degrees at the hip). Smoothed at or above the need, as a lift is, a
foot coming down fast was taken 2.8 cm below the master's, into the contact height. The window eases in and
out, so the clip's ends stay exactly as slaved (its last frame is ``PRONE_STOWED``'s pose).
"""

from __future__ import annotations

import numpy as np

from authoring import ik
from authoring.postures import leg
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smoothstep
from authoring.slave_body import part_heights, played_body
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

FLOOR_CM = 2.0  # cm: a foot brought down stays this far up (contact is 1.25 cm; a lifted part leaves at 2)
PASSES = 3  # the toes' tip is near, not at, the foot's lowest node: solve again for what is left
SIDES = ("left", "right")


def lower_slave_feet(
    master: Channelset, slave: Channelset, figures: FigureSet, window: tuple[tuple[float, float], ...]
) -> dict[str, np.ndarray]:
    """Bring ``slave``'s feet down to ``master``'s heights (joint channels, in place) over ``window`` (s:
    the (start, end) it eases in over, then the one it eases out over); returns each foot's lowering (cm)."""
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    kin = figures.kin[stype]
    t = np.arange(slave.nframes) / slave.fps
    (a0, a1), (b0, b1) = window
    w = np.minimum(smoothstep((t - a0) / (a1 - a0)), 1.0 - smoothstep((t - b0) / (b1 - b0)))
    m_foot = part_heights(mq, mloc, figures, mtype, "foot")
    pose = q.copy()
    lowered: dict[str, np.ndarray] = {}
    for _ in range(PASSES):
        s_foot = part_heights(pose, loc, figures, stype, "foot")
        sites = kin.site_globals(pose, loc)
        goals, most = [], 0.0
        for side in [s for s in SIDES if s in m_foot and s in s_foot]:
            need = w * np.maximum(0.0, s_foot[side] - np.maximum(m_foot[side], FLOOR_CM))
            lowered[side] = lowered.get(side, 0.0) + need
            most = max(most, float(need.max()))
            toe = sites[:, kin.site_names.index(f"{side}_toes.distal"), :3, 3].copy()
            toe[:, 1] -= need
            goals.append(ik.Goal(f"{side}_toes.distal", toe, None, 1.0, 1, leg(side)))
        if most < 0.01:
            break
        pose, _ = ik.solve(
            kin, pose, goals, loc, iterations=40, damping=4.0, rest_pose=pose, rest_gain=0.05, tolerance=0.02,
            max_dof_step=0.01,
        )  # fmt: skip
    pose = q + w[:, None] * (pose - q)  # exactly as slaved outside the window
    bound = bind_channelset(slave, [figures.figures[stype]])
    bf = bound.figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return lowered
