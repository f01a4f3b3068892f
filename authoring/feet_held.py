"""A standing death's feet stay on the ground as his knees land: the shins do not kick up (issue 14).

Falling forward, a shot standing soldier comes down on his knees and toes and pitches onto his chest, the
thighs swinging flat about the knees. The ragdoll of :mod:`authoring.deaths` holds its knees bent by their
damping (limp, they flung the shins up as he hit the ground), so as the thighs swing flat the shins swing
up with them: stfire2dead's feet rose 17 cm off the ground, heels 38 cm up, shins about 45 degrees in the
air, at 1.1-1.3 s, just as his trunk landed. A man who folds down with the ground keeps his toes where they
touch: the knee opens as the thigh comes down over the shin.

So, after the fall is planted (:func:`held_feet`), from the frame each foot leaves the ground near the end
of its first stance (the last frame it is down, :func:`lift_off`) the leg's knee, ankle and toes are solved
frame by frame (a bounded least-squares, deterministic) to keep the foot's ball and toe tip where they were
then, each angle staying near the recorded one (:data:`NEAR_CM_PER_DEG`): the thigh (hip and root) falls
as recorded. The settle (:mod:`authoring.dead_settle`) lays the legs out from there.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.fk import FigureKinematics
from peabody.model import Figure

SIDES = ("left", "right")
JOINTS = ("knee", "ankle", "toes")  # what moves to keep the foot: the thigh falls as recorded
SITES = ("foot.ball", "toes.distal")  # held where they are as the foot leaves the ground
# cm of a held site's miss that a degree off the recorded angle weighs as: the foot held, the leg near its
# fall (the left foot of stfire2dead, its ankle at soldier.fig's eversion limit, rises 6 cm instead of 17)
NEAR_CM_PER_DEG = 0.1


def lift_off(low: np.ndarray) -> int | None:
    """The last frame of a foot's first stance (its lowest node's heights ``low`` ``(n,)`` within the check's
    contact height), None if it never leaves the ground or is never on it."""
    down = low <= CONTACT_HEIGHT_CM
    if not down[0] or down.all():
        return None
    return int(np.argmin(down)) - 1


def _miss(
    a: np.ndarray,
    kin: FigureKinematics,
    q: np.ndarray,
    root: np.ndarray,
    leg: tuple[np.ndarray, list[int], np.ndarray],
    target: np.ndarray,
) -> np.ndarray:
    """The held sites' miss (cm) with the leg's angles ``a`` (``leg``: their indices, the held sites, the
    recorded angles), and each angle's turn off the recorded one weighed by :data:`NEAR_CM_PER_DEG`."""
    idx, sites, recorded = leg
    q[idx] = a
    at = kin.site_globals(q, root)[sites, :3, 3]
    return np.concatenate([(at - target).ravel(), NEAR_CM_PER_DEG * np.degrees(a - recorded)])


def held_feet(frames: ClipFrames, soldier: Figure) -> ClipFrames:
    """``frames`` (a planted fall of ``soldier``) with each foot held where it leaves the ground at the end
    of its first stance, by the knee, ankle and toes (see the module docstring)."""
    figs = FigureSet({"body": soldier})
    kin = figs.kin["body"]
    nodes, segs = figs.nodes("body")
    parts = figs.node_parts("body")
    poses = frames.poses.copy()
    y = np.einsum("nkj,kj->nk", kin.segment_globals(poses, frames.roots)[:, segs, 1, :], nodes)
    for side in SIDES:
        start = lift_off(y[:, parts == f"{side}_foot"].min(axis=1))
        if start is None:
            continue
        idx = np.concatenate(
            [
                np.arange(kin.dof_slices[f"{side}_{j}"].start, kin.dof_slices[f"{side}_{j}"].stop)
                for j in JOINTS
            ]
        )
        sites = [kin.site_names.index(f"{side}_{s}") for s in SITES]
        target = kin.site_globals(poses[start], frames.roots[start])[sites, :3, 3]
        lo, hi = kin.lower[idx], kin.upper[idx]
        x = poses[start, idx]
        for f in range(start + 1, len(poses)):
            q, root = poses[f].copy(), frames.roots[f]
            leg = (idx, sites, poses[f, idx].copy())
            x = least_squares(_miss, np.clip(x, lo, hi), bounds=(lo, hi), args=(kin, q, root, leg, target)).x
            poses[f, idx] = x
    return ClipFrames(poses, frames.roots, frames.rifles, frames.fps)
