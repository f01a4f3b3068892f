"""A dying slave's arm in the ground comes out by the arm, not by lifting the whole body (issue 14).

After each rest stage the build lifts the slave's whole body out of the ground
(:func:`authoring.build.lift_off_ground`), smoothed over the clip. Where the master's hands come down onto
the ground as his chest is lowered (prfire2dead frames 66-84), the DI's palms, its shoulders shaped otherwise
than his, went 1-3.6 cm into the ground at each stage; lifted out with the body, its trunk, already lying,
rose 3.4 cm (pelvis 2.8 -> 6.2 cm up) and the whole body floated 3 cm over the ground for half a second.
Where a death lays its slave's trunk by the spine (:attr:`~authoring.death_specs.DeathSpec.slave_spine_laid`,
:mod:`authoring.slave_spine`; from branch proppedslaves-s17-wip 95d5caf) each arm first lifts its parts out
of the ground after the release by its clavicle and shoulder (the dead arm raised as a
whole; with the elbow and wrist too, frames solved alone took other branches and a DI forearm twisted 88
degrees in a frame), the change smoothed over the clip as :func:`~authoring.slave_ground.rest_limbs` does;
what little is left (a few millimetres) is the body's lift.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from authoring import ik
from authoring.postures import segment_heights
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import hann_smooth, smooth_above
from authoring.slave_body import played_body, write_pose
from authoring.slave_contacts import SIDES, SMOOTH_FRAMES
from authoring.slave_ground import part_goals
from server.motion.channelset import Channelset

# an arm part (as rest_limbs names it) -> the psurf segment whose lowest point says how far it is in
ARM_SEGMENTS = {
    **{f"{s}_hand": f"{s}_palm" for s in SIDES},
    **{f"{s}_forearm": f"{s}_lower_arm" for s in SIDES},
    **{f"{s}_upper_arm": f"{s}_upper_arm" for s in SIDES},
}
MARGIN_CM = 0.05  # an arm part is lifted this far out of the ground (the body's lift takes the rest)
SIGMA_FRAMES = 2.0  # the lift is smoothed over the clip (at or above the need): no one-frame turn
PASSES = 3  # a part's lowest point moves along it as the arm turns: solve again for what is left


def lift_slave_arms(slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Turn the slave's arms (``slave``'s joint channels, in place) so that after the release no arm part
    is in the ground; returns the largest lift asked per frame (cm)."""
    release = getattr(slave, "release_frame", None)
    q, loc, stype = played_body(slave, figures)
    n = len(q)
    total = np.zeros(n)
    if release is None or release >= n - 1:
        return total
    kin = figures.kin[stype]
    after = np.arange(n) >= release
    pose = q.copy()
    for _ in range(PASSES):
        low = segment_heights(kin, pose, loc)
        need = {
            part: np.where(after, smooth_above(np.maximum(0.0, MARGIN_CM - low[seg]), SIGMA_FRAMES), 0.0)
            for part, seg in ARM_SEGMENTS.items()
            if seg in low
        }
        worst = np.max(np.stack(list(need.values())), axis=0)
        sub = np.flatnonzero(worst > 1e-3)
        if not len(sub):
            break
        total = np.maximum(total, worst)
        goals = [  # by the clavicle and shoulder alone
            replace(g, joints=tuple(g.joints or ())[:2])
            for g in part_goals(kin, pose[sub], loc[sub], need, sub, {})
        ]
        solved, _ = ik.solve(
            kin, pose[sub], goals, loc[sub], iterations=40,
            damping=2.0, rest_pose=pose[sub], rest_gain=0.05, tolerance=0.05, max_dof_step=0.05,
        )  # fmt: skip
        change = np.zeros_like(pose)
        change[sub] = solved - pose[sub]
        pose = pose + hann_smooth(change, SMOOTH_FRAMES) * after[:, None]
    if total.any():
        write_pose(slave, figures, stype, pose, np.tile(np.eye(4), (n, 1, 1)))
    return total
