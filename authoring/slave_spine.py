"""A prone dead slave's trunk shaped by its spine where the master's lies (issue 14).

DI.fig's belly stands further out of the line from pelvis to chest than soldier.fig's: slaved onto a master
the hit presses flat, the DI lay with its pelvis on the ground, its belly 2.6-3.0 cm in it and its chest
2-3 cm above the master's (prfire2dead_low, frames 8-92). The build's ``lift_off_ground`` then raised the
whole body by the belly (pelvis 0.1 -> 3.0 cm), and the later rests, lowering the trunk onto the ground at the
end, left it rising in between (``trunk_rise_cm`` 4.4-5.8). :func:`lay_slave_spine` instead bends the
slave's spine (the pitch of ``waist``, ``belly`` and ``upper_spine``, within their limits; the root and so
the pelvis stay put) so that its belly and chest lie at least as high above the ground as the master's, the
shoulders and neck base at their height (the arms with them), faded in over the frames after the release,
before the other rests. Where a death asks for it (:attr:`~authoring.death_specs.DeathSpec.slave_spine_laid`)
the build then also lifts the arms out of the ground by the arm (:mod:`authoring.slave_arms_lift`) and
``rest_limbs`` no longer turns the trunk onto the ground: there is nothing left in the ground to lift the
body for, nor a trunk to turn.
"""

from __future__ import annotations

import numpy as np

from authoring.quality_frames import FigureSet
from authoring.signal_shaping import gaussian
from authoring.slave_body import played_body, write_pose
from authoring.slave_ground import fade_in
from authoring.slave_rest import part_lows
from server.motion.channelset import Channelset

SPINE_DOFS = (("waist", 1), ("belly", 1), ("upper_spine", 1))  # the spine's pitch (R(-x): flexion)
LAID_PARTS = ("belly", "chest")  # lie as high above the ground as the master's
# ... while these sites keep their height: the shoulders and neck base (the upper torso neither drops nor
# pitches: bent by the waist alone, the DI's arms went 3-5 cm into the ground as the master laid his down)
KEPT_SITES = ("upper_torso.distal", "upper_torso.left_clavicle", "upper_torso.right_clavicle")
FADE_FRAMES = 6  # the bend fades in over this many frames from the release (the hands hold the rifle before)
ITERATIONS = 12  # Gauss-Newton steps (all frames at once)
STEP_DEG = 0.05  # the heights' forward-difference step
MOVE_WEIGHT = 0.02  # cm per degree of bend: of two shapes that lay the trunk, the smaller bend
MAX_STEP_DEG = 4.0  # per iteration (the lowest node can change: the heights are piecewise smooth)
SMOOTH_SIGMA_FRAMES = 2.0  # the bend is smoothed over the clip


def lay_slave_spine(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Bend the slave's spine so its belly and chest lie as high as the master's once he lets go (``slave``'s
    joint channels, in place); returns the bend per frame ``(n, 3)`` (degrees, :data:`SPINE_DOFS`)."""
    release = getattr(slave, "release_frame", None)
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    n = len(q)
    if release is None or release >= n - 1:
        return np.zeros((n, len(SPINE_DOFS)))
    kin = figures.kin[stype]
    cols = np.array([kin.dof_slices[j].start + k for j, k in SPINE_DOFS])
    m_h = part_lows(figures, mtype, mq, mloc)
    w = fade_in(n, release, FADE_FRAMES)
    rows = np.arange(max(0, release - FADE_FRAMES), n)  # solved in full a little before: smoothed, then faded
    s_h = part_lows(figures, stype, q[rows], loc[rows])
    want = {p: np.maximum(s_h[p], np.maximum(m_h[p][rows], 0.0)) for p in LAID_PARTS}
    base = np.degrees(q[rows][:, cols])  # a joint already past a limit is not clamped: only bent no further
    lo = np.minimum(np.degrees(kin.lower[cols]), base)
    hi = np.maximum(np.degrees(kin.upper[cols]), base)
    x = np.zeros((len(rows), len(cols)))
    sites = [kin.site_names.index(s) for s in KEPT_SITES]
    kept = kin.site_globals(q[rows], loc[rows])[:, sites, 1, 3]

    def heights(x: np.ndarray) -> np.ndarray:
        pose = q[rows].copy()
        pose[:, cols] = np.radians(np.clip(base + x, lo, hi))
        h = part_lows(figures, stype, pose, loc[rows])
        at = kin.site_globals(pose, loc[rows])[:, sites, 1, 3] - kept
        return np.concatenate([np.stack([h[p] - want[p] for p in LAID_PARTS], axis=1), at], axis=1)

    eye = np.eye(len(cols))
    for _ in range(ITERATIONS):
        r = heights(x)
        jac = np.stack([(heights(x + STEP_DEG * eye[k]) - r) / STEP_DEG for k in range(len(cols))], axis=2)
        jt = np.transpose(jac, (0, 2, 1))
        a = jt @ jac + MOVE_WEIGHT**2 * eye
        b = -(jt @ r[:, :, None])[:, :, 0] - MOVE_WEIGHT**2 * x
        step = np.linalg.solve(a, b[:, :, None])[:, :, 0]
        x = np.clip(base + x + np.clip(step, -MAX_STEP_DEG, MAX_STEP_DEG), lo, hi) - base
    bend = np.zeros((n, len(cols)))
    bend[rows] = x
    bend = gaussian(bend, SMOOTH_SIGMA_FRAMES) * w[:, None]
    pose = q.copy()
    pose[:, cols] += np.radians(bend)
    write_pose(slave, figures, stype, pose, np.tile(np.eye(4), (n, 1, 1)))
    return bend
