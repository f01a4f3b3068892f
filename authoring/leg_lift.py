"""A kneeling soldier's legs roll off the ground as he falls: a foot or knee that would skid lifts (issue 14).

As a kneeling soldier tips over (kstow2dead, kfire2dead), the ragdoll of :mod:`authoring.deaths` drags the
parts of his legs on the ground: the feet 4.8-4.9 cm (kfire2dead's tucked toes 7 cm in 4 frames as the hip
came down past the knee; kstow2dead's foot after it landed), the kneeling knee 5.9-6.1 (frames 0-44).
Holding the knee by moving the root (:mod:`authoring.knee_hold`) made the feet drag instead. A real body does
neither: a part in contact stays put or leaves the ground, the knee and foot unloading and coming up as the
hip passes over the knee, landing once and staying.

So, last (after the fall is planted, pinned and settled), each foot and knee (with its kneecap) whose node
on the ground (the check's ``CONTACT_HEIGHT_CM``) would slide more than :data:`SLIDE_BUDGET_CM` from where
it touched down **lifts**, from the frame it has slid that far to the frame from which it stays within that
of where it comes to rest (:func:`lift_windows`): its lowest node is raised to :data:`LIFT_CM` (clearly off
the ground), the lift smoothed at or above the need (nothing snaps up). The leg's own joints carry it
(:func:`lifted`: IK per frame on the knee's or the foot's site, the foot keeping its turn loosely so it
rises level; the knee before the foot, a lifted foot's hip moved the knee: 4.6 cm), the leg's other parts
on the ground kept where they are, and the lift adds to no joint's turn between two frames more than
:data:`STEP_DEG` (:func:`_no_leaps`). Root, trunk, arms and rifle are not touched, so the fall, its arms'
fall and its DEAD rest (the last frame) stay as they were. A thigh cannot lift so: its nodes by the hip
joint do not rise with the hip's turn (lifted by the hip, kfire2dead's left thigh slid 8 cm, not 7.4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from authoring import ik
from authoring.body_parts import contact_runs
from authoring.quality import CONTACT_HEIGHT_CM, one_frame_flicks
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smooth_above
from authoring.slave_feet import part_points
from authoring.transitions import ClipFrames
from peabody.model import Figure

SIDES = ("left", "right")
SLIDE_BUDGET_CM = 1.0  # a node on the ground may slide this far before its part lifts (the check: feet 2)
LIFT_CM = 2.5  # a lifted part's lowest node this high: clearly off the ground (contact is 1.25)
LIFT_SIGMA_FRAMES = 3.0  # the lift smoothed over this many frames (at or above the need)
HOLD_CM = 3.0  # the leg's other parts this low are kept where they are while a part lifts
UP = np.array([0.0, 1.0, 0.0])
TURN_CM = 5.0  # a radian of a lifted site's turn weighs as much as this much move: the foot rises level
IK_ITERATIONS = 40
PASSES = 3  # each leg lifted, measured and lifted again (a lifted part's new nodes on the ground)
STEP_DEG = 10.0  # a joint's turn between two frames, lifted: at most this or the fall's own
LEG_JOINTS = ("hip", "knee", "ankle", "toes")
EASE_FLICK_DEG = 4.0  # eased_legs: a leg's change that flicks this much is smoothed there


@dataclass(frozen=True)
class LegPart:
    """A part of a leg that may lift: its parts as the check names them, the sites the lift is put on (the
    part's turn kept loosely: a flat foot lifted by its ball alone turned its heel into the ground), the
    joints that carry it (``{side}`` filled in by :meth:`sided`)."""

    parts: tuple[str, ...]
    sites: tuple[str, ...]
    joints: tuple[str, ...]

    def sided(self, side: str) -> LegPart:
        parts, sites, joints = (
            tuple(x.format(side=side) for x in xs) for xs in (self.parts, self.sites, self.joints)
        )
        return LegPart(parts, sites, joints)


LEG_PARTS: tuple[LegPart, ...] = (
    LegPart(
        ("{side}_foot",), ("{side}_foot.ball",), ("{side}_hip", "{side}_knee", "{side}_ankle", "{side}_toes")
    ),
    LegPart(("{side}_knee", "{side}_kneecap"), ("{side}_lower_leg.knee",), ("{side}_hip", "{side}_knee")),
)


def lift_windows(points: np.ndarray, budget: float = SLIDE_BUDGET_CM) -> np.ndarray:
    """``(n,)`` the frames a part whose nodes are ``points`` ``(n, k, 3)`` must be off the ground: per
    contact run of a node that slides more than ``budget``, from the frame it has slid that far from its
    touchdown to the frame from which it stays within ``budget`` of where the run ends."""
    out = np.zeros(len(points), dtype=bool)
    runs = contact_runs(points, CONTACT_HEIGHT_CM)
    for k, a, b, slide in zip(runs.node, runs.first, runs.last, runs.slide, strict=True):
        if slide <= budget:
            continue
        xz = points[a : b + 1, k][:, [0, 2]]
        from_start = np.linalg.norm(xz - xz[0], axis=1)
        to_end = np.linalg.norm(xz - xz[-1], axis=1)
        lift = int(np.argmax(from_start > budget))
        moving = np.flatnonzero(to_end > budget)
        land = int(moving[-1]) + 1 if len(moving) else lift
        out[a + lift : a + land] = True
    return out


def _need(points: np.ndarray, window: np.ndarray) -> np.ndarray:
    """``(n,)`` how far (cm) to raise the part so its lowest node is at :data:`LIFT_CM` in ``window``,
    smoothed at or above that need."""
    need = np.where(window, np.maximum(0.0, LIFT_CM - points[..., 1].min(axis=1)), 0.0)
    return smooth_above(need, LIFT_SIGMA_FRAMES) if need.any() else need


def lifted(frames: ClipFrames, soldier: Figure, steps: tuple[tuple[str, float], ...] = ()) -> ClipFrames:
    """``frames`` (a planted, pinned fall of ``soldier``) with every leg part that would skid lifted instead
    (see the module docstring); the lift turns a joint whose name starts with one of ``steps``' prefixes at
    most its degrees a frame beyond the fall's own turn, any other :data:`STEP_DEG`
    (``DeathSpec.legs_lift_step_deg``)."""
    figs = FigureSet({"body": soldier})
    kin = figs.kin["body"]
    poses, roots = np.array(frames.poses), frames.roots
    for side in SIDES * PASSES:
        legs = [p.sided(side) for p in LEG_PARTS]
        points = [part_points(poses, roots, figs, "body", leg.parts) for leg in legs]
        needs = [_need(p, lift_windows(p)) for p in points]
        if not any(need.any() for need in needs):
            continue
        sites = kin.site_globals(poses, roots)
        goals = []
        for rank, (leg, p, need) in enumerate(zip(legs, points, needs, strict=True)):
            # a part lifted carries its lift (a knee before its foot); one on the ground and not lifted is
            # kept where it is, before both
            down = (p[..., 1].min(axis=1) <= HOLD_CM) & (need == 0.0)
            for name in leg.sites:
                at = sites[:, kin.site_names.index(name)]
                up = at[:, :3, 3] + need[:, None] * UP
                lift = ik.Goal(name, up, at[:, :3, :3], (need > 0.0) * 1.0, rank, leg.joints, TURN_CM)
                goals += [lift, ik.Goal(name, at[:, :3, 3], None, down * 1.0, len(legs), leg.joints)]
        rows = np.flatnonzero(np.any([need > 0.0 for need in needs], axis=0))
        solved, _ = ik.solve(
            kin, poses[rows], [g.rows(rows) for g in goals], roots[rows], iterations=IK_ITERATIONS
        )
        poses[rows] = solved
    step = np.full(kin.ndof, STEP_DEG)
    for prefix, deg in steps:
        for joint, sl in kin.dof_slices.items():
            step[sl] = deg if joint.startswith(prefix) else step[sl]
    smooth = _no_leaps(np.asarray(frames.poses), poses, step)
    return ClipFrames(smooth, frames.roots, frames.rifles, frames.fps)


def _no_leaps(fall: np.ndarray, lifted_poses: np.ndarray, step_deg: np.ndarray) -> np.ndarray:
    """``lifted_poses`` with the lift (their difference from ``fall``, ``(n, ndof)``) following its own
    course only as fast as keeps each DOF's turn between two frames within its ``step_deg`` ``(ndof,)`` or
    the fall's own turn there (kstow2dead's knee already turns 19.5 degrees in one frame as the leg
    lands)."""
    step = np.diff(fall, axis=0)
    room = np.maximum(np.abs(step), np.radians(step_deg))
    lift = lifted_poses - fall
    out = lift.copy()
    for f in range(1, len(fall)):
        out[f] = out[f - 1] + np.clip(
            lift[f] - out[f - 1], -room[f - 1] - step[f - 1], room[f - 1] - step[f - 1]
        )
    return fall + out


def eased_legs(
    fall: ClipFrames, held: ClipFrames, soldier: Figure, sigma: float, together: bool = False
) -> ClipFrames:
    """``held`` (``fall`` pinned and lifted) with its legs' change from ``fall`` smoothed (Gaussian,
    ``sigma`` frames) where that change flicks (a frame's turn differing by :data:`EASE_FLICK_DEG` from both
    its neighbours', as the check measures): a pin that lets a leg go in one frame, or a lift that turns an
    ankle for a single frame, becomes a turn over a few frames (kstow2dead: the right foot's pin stretched
    the knee to 2 degrees as the leg came down and gave it back 19 degrees in a frame, its lift turned the
    hip and ankle 10 degrees for one frame). Elsewhere, and at the first and last frames, as held (smoothed
    throughout, the slaves' legs, solved from his, dragged a foot 9.6 cm: their kneeling rest is
    sensitive to every millimetre of the master's legs). Frames ``held`` appends past ``fall`` (still frames
    after an arms' fall that outlasts the physics, kstow2dead's early-going arms) are measured against
    ``fall``'s last. ``together``: where one leg DOF's change flicks, every leg DOF's is smoothed (smoothed
    one by one, ststow2dead's left knee held still as its hip turned on: the foot jumped 3.9 m/s)."""
    kin = FigureSet({"body": soldier}).kin["body"]
    before, poses = np.asarray(fall.poses), np.array(held.poses)
    before = np.concatenate([before, np.repeat(before[-1:], len(poses) - len(before), axis=0)])
    cols = np.zeros(kin.ndof, dtype=bool)
    for side in SIDES:
        for joint in LEG_JOINTS:
            cols[kin.dof_slices[f"{side}_{joint}"]] = True
    change = poses[:, cols] - before[:, cols]
    turn = np.degrees(np.diff(change, axis=0))
    flicks = np.zeros(change.shape, dtype=bool)  # the frames either side of a flicking turn
    flicks[1:-2] = one_frame_flicks(turn) > EASE_FLICK_DEG
    flicks[1:] |= flicks[:-1]
    if together:
        flicks[:] = flicks.any(axis=1, keepdims=True)
    where = np.stack([smooth_above(f * 1.0, sigma) for f in flicks.T], axis=1)
    where = np.clip(where, 0.0, 1.0)
    where[[0, -1]] = 0.0
    smooth = gaussian_filter1d(change, sigma, axis=0, mode="nearest")
    eased = before[:, cols] + change + where * (smooth - change)
    poses[:, cols] = np.where(where > 0.0, np.clip(eased, kin.lower[cols], kin.upper[cols]), poses[:, cols])
    return ClipFrames(poses, held.roots, held.rifles, held.fps)
