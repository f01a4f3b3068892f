"""A crawling DI slave's forearms on the ground no longer than the master's (issue 14, ``crawl_cycle_low``).

Lowered onto its knees (:func:`~authoring.slave_contacts.rest_slave_knees`) and its forearms put at the
master's height (:func:`~authoring.slave_contacts.rest_slave_forearms`), DI's forearms still came down
where the master's hover: the left one, which the master holds 1.6-2 cm up while the body glides over it,
dipped to 1.2 cm and, in contact, swept 3.8 cm sideways with the arm; the right one, planted, stayed
down past the master's lift-off and rolled with the rifle's yaw (4.5 cm; the palms kept exactly turned on
the rifle with the wrists at their limits make the hand's turn the forearm's). Here both arms are solved
again: the palms' places on the rifle and the elbows' places held (each elbow raised by its forearm's
shortfall wherever the master's forearm is above :data:`CLEAR_CM`), the palms' turn on the rifle a
lower-priority goal, so the hand gives way by a few degrees (at most 2.6 on DI) rather than the forearm
rolling on the ground. The clip's first and last frames are kept as slaved (they meet the posture).

Prone, prstow2prfire's master keeps his left forearm 1.8 cm up and still while the rifle comes to the
shoulder, but DI's forearm lies on the ground at both ends (PRONE_STOWED, PRONE_FIRE) 3.4 cm apart, and
slid there (the check's lift-off rule holds a part on the ground until it is 2 cm up). Such a clip
(:data:`STEPS`) has its forearm lifted clear of that in between, a step eased in and out from the ends.
"""

from __future__ import annotations

import numpy as np

from authoring import ik
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smooth_above, smoothstep
from authoring.slave_body import part_heights, played_body
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

SIDES = ("left", "right")
ARM = ("clavicle", "shoulder", "elbow", "wrist")
CLEAR_CM = 1.4  # a forearm the master holds above this stays above it (contact starts at 1.25 cm) ...
LIFT_SIGMA = 3.0  # ... raised by its elbow, the raise smoothed over this many frames (at least as high)
PASSES = 3  # solved again from the result, the raise re-measured
# master clip: (cm, s) the slave's forearm is lifted to in between, the lift eased in and out over this long
# from either end (above the check's 2 cm lift-off, so the forearm steps, not slides, to its new place)
STEPS = {"prstow2prfire": (2.3, 0.25)}
# master clip: (sides, cm, (s, s) eased in over, (s, s) eased out over): the slave's forearm on those sides is
# lifted to that height (wherever it is lower) over that time, whatever the master's does. crawl2prstow's
# DI chest moves 2.3 cm further from the planted right elbow than the master's as his pelvis comes down
# (0.33-0.57 s), and its forearm, held down as his, was dragged 3.2 cm (M16 3.3) along the ground before he
# lifted it; lifted from 0.25 s, it steps over instead (the master's rises at 0.52 s)
TIMED_STEPS = {"crawl2prstow": (("right",), 2.3, (0.2, 0.35), (1.15, 1.3))}


def steps_forearm(name: str) -> bool:
    """Whether clip ``name``'s DI slave has a forearm stepped over at a set time (:data:`TIMED_STEPS`). Not
    its M16 slave: its left forearm is up then, so lifting the right left it with nothing on the ground for
    0.15 s, and its right arm's re-solve flipped 40 degrees in a frame. Stepped over 0.22-0.46 s alone it
    kept support and slid 1.25 cm, but the re-solve still turned its elbow's and wrist's twist 48/40 degrees
    in one frame (21-22; slaved, they sweep it over 13 frames): not yet."""
    return name in TIMED_STEPS


def lift_slave_forearms(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Re-solve ``slave``'s arms (in place) as the module says; returns the per-frame elbow raise (cm, the
    larger side's) of the last pass."""
    q, loc, stype = played_body(slave, figures)
    mq, mloc, mtype = played_body(master, figures)
    kin = figures.kin[stype]
    aloft: dict[str, np.ndarray] = {
        s: (h > CLEAR_CM).astype(float) for s, h in part_heights(mq, mloc, figures, mtype, "forearm").items()
    }
    clear, window = CLEAR_CM, np.ones(len(q))
    step = STEPS.get(master.name.split(".")[0])
    if step is not None:
        clear, ease = step
        t = np.arange(len(q)) / slave.fps
        window = np.minimum(smoothstep(t / ease), smoothstep((t[-1] - t) / ease))
        aloft = {s: a * window for s, a in aloft.items()}
    timed = TIMED_STEPS.get(master.name.split(".")[0])
    if timed is not None:
        sides, clear, (a0, a1), (b0, b1) = timed
        t = np.arange(len(q)) / slave.fps
        window = np.minimum(smoothstep((t - a0) / (a1 - a0)), 1.0 - smoothstep((t - b0) / (b1 - b0)))
        aloft = {s: window * (s in sides) for s in aloft}
    pose = q.copy()
    raised = np.zeros(len(q))
    for _ in range(PASSES):
        sites = kin.site_globals(pose, loc)
        heights = part_heights(pose, loc, figures, stype, "forearm")
        goals: list[ik.Goal] = []
        raised[:] = 0.0
        for side in SIDES:
            chain = tuple(f"{side}_{j}" for j in ARM)
            palm = sites[:, kin.site_names.index(f"{side}_palm.palmcenter")]
            elbow = sites[:, kin.site_names.index(f"{side}_upper_arm.distal"), :3, 3].copy()
            raise_ = smooth_above(aloft[side] * np.maximum(0.0, clear - heights[side]), LIFT_SIGMA)
            elbow[:, 1] += raise_
            raised = np.maximum(raised, raise_)
            goals += [
                ik.Goal(f"{side}_palm.palmcenter", palm[:, :3, 3], None, 1.0, 2, chain),
                ik.Goal(f"{side}_upper_arm.distal", elbow, None, 1.0, 2, chain),
                ik.Goal(f"{side}_palm.palmcenter", None, palm[:, :3, :3], 1.0, 0, chain),
            ]
        pose, _report = ik.solve(
            kin, pose, goals, loc, iterations=60, damping=2.0, rest_pose=pose, rest_gain=0.05,
            tolerance=0.02, max_dof_step=0.03,
        )  # fmt: skip
    pose = q + window[:, None] * (pose - q)  # a step eases in and out of the ends, both as slaved ...
    pose[[0, -1]] = q[[0, -1]]  # ... which meet the posture (CRAWLING)
    bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return raised
