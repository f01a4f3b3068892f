"""Kneeling contacts carried over to the slave: where the master's kneecap rests on the ground, so does the
slave's.

Slaving copies the legs' joint angles, and DI.fig and soldier.fig share the leg skeleton, but DI.fig's
kneecap mesh sits about 1.4 cm higher on its knee site than soldier.fig's (and its toes 0.7 cm): a DI
soldier kneeling with the master's angles floats on his knee and toes. A kneeling thigh hangs straight down
from the hip, so the knee cannot go lower by the leg alone: in the frames where the master's kneecap (the
lower-leg mesh nodes near the ``knee`` site, as the quality check counts them) is on or near the ground, the
slave figure and its rifle are lowered by how far the slave's kneecap is above the master's (never taking the
rest of the body below the ground), and the legs are solved so that every foot stays where it was (a
kneeling leg's toes come down to where the master's are) and a kneeling knee goes down with the body. The
lowering fades in as the master's kneecap comes down (from ``REACH_CM`` to ``REST_CM`` above the ground),
so a knee going down or coming up does not jump. The build's ``lift_off_ground`` then raises any frame
where something else would sink.
"""

from __future__ import annotations

import numpy as np

from server.authoring import ik
from server.authoring.postures import leg, segment_heights
from server.authoring.quality_frames import FigureSet, play
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

REST_CM = 2.0  # the master's kneecap this close to the ground: the slave's goes as low (full weight)
REACH_CM = 6.0  # ... this far up: no goal
SIDES = ("left", "right")
LEG_SEGMENTS = ("upper_leg", "lower_leg", "foot", "toes")


def part_heights(
    poses: np.ndarray, locations: np.ndarray, figures: FigureSet, ptype: str, part: str = "kneecap"
) -> dict[str, np.ndarray]:
    """Per side, the height (cm) of the lowest node of ``{side}_{part}`` (as the quality check names body
    parts: ``kneecap``, ``foot``) in every frame ``(n,)``."""
    kin = figures.kin[ptype]
    nodes, segs = figures.nodes(ptype)
    parts = figures.node_parts(ptype)
    out = {}
    g = kin.segment_globals(poses, locations)[..., 1, :]  # (n, nseg, 4): the rows giving world y
    for side in SIDES:
        sel = parts == f"{side}_{part}"
        if sel.any():
            out[side] = np.einsum("fkj,kj->fk", g[:, segs[sel]], nodes[sel]).min(axis=1)
    return out


def rest_slave_knees(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Lower the slave onto its kneeling knees where the master rests on them (``slave``'s figure and joint
    channels, in place); returns the lowering per frame (cm)."""
    mf, sf = play(master, figures), play(slave, figures)
    mtype = max(mf.poses, key=lambda k: figures.kin[k].ndof)
    stype = max(sf.poses, key=lambda k: figures.kin[k].ndof)
    kin = figures.kin[stype]
    q, loc = sf.poses[stype], sf.locations[stype]
    m_h = part_heights(mf.poses[mtype], mf.locations[mtype], figures, mtype)
    s_h = part_heights(q, loc, figures, stype)
    m_foot = part_heights(mf.poses[mtype], mf.locations[mtype], figures, mtype, "foot")
    s_foot = part_heights(q, loc, figures, stype, "foot")
    weight: dict[str, np.ndarray] = {}
    drop = np.zeros(len(q))
    for side in SIDES:
        if side not in m_h or side not in s_h:
            continue
        w = np.clip((REACH_CM - m_h[side]) / (REACH_CM - REST_CM), 0.0, 1.0)
        weight[side] = w * w * (3.0 - 2.0 * w)
        drop = np.maximum(drop, weight[side] * np.maximum(0.0, s_h[side] - np.maximum(m_h[side], 0.0)))
    # never lower the rest of the body into the ground (lying on the forearms, the knees are not what the
    # slave rests on); the legs are solved again, so they do not count
    rest = [h for seg, h in segment_heights(kin, q, loc).items() if not seg.endswith(LEG_SEGMENTS)]
    drop = np.minimum(drop, np.maximum(0.0, np.min(rest, axis=0)))
    if not drop.any():
        return drop
    lowered = loc.copy()
    lowered[:, 1, 3] -= drop
    sites = kin.site_globals(q, loc)
    goals: list[ik.Goal] = []
    for side in SIDES:  # every foot stays where it is; a kneeling knee goes down with the body
        heel = sites[:, kin.site_names.index(f"{side}_foot.heel")].copy()
        if side in weight:  # and a kneeling leg's toes, if they float above the master's, go down to them
            heel[:, 1, 3] -= weight[side] * np.maximum(0.0, s_foot[side] - np.maximum(m_foot[side], 0.0))
        goals.append(ik.Goal(f"{side}_foot.heel", heel[:, :3, 3], heel[:, :3, :3], 1.0, 2, leg(side)))
        if side in weight:
            knee = sites[:, kin.site_names.index(f"{side}_lower_leg.knee"), :3, 3].copy()
            knee[:, 1] -= drop
            goals.append(ik.Goal(f"{side}_lower_leg.knee", knee, None, weight[side], 1, leg(side)))
    # heavily damped small steps: a kneeling front thigh is near its hip's gimbal (flexion ~90 degrees), where
    # an undamped solve swaps abduction for twist and the hip's angles jump by tens of degrees between frames
    pose, _ = ik.solve(
        kin, q, goals, lowered, iterations=60, damping=6.0, rest_pose=q, rest_gain=0.05, tolerance=0.02,
        max_dof_step=0.02,
    )  # fmt: skip
    bound = bind_channelset(slave, [figures.figures[stype]])
    bf = bound.figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    slave.fig_pos[:, :, 1] -= drop[:, None].astype(slave.fig_pos.dtype)  # the figure and its rifle
    return drop
