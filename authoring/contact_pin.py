"""A fall's limbs on the ground stay where they touched down (issue 14): hands, forearms, feet, head.

The ragdoll of :mod:`authoring.deaths` slides its contacts as it collapses (ststow2dead: a hand 6.5 cm as
it landed, the toes 7.5 cm as the foot untucked), and :func:`authoring.planted.plant` takes out only the
drift the parts share (it moves the root), not one part dragging against the others. So, in the spirit of
foot-skate cleanup (Kovar, Schreiner and Gleicher, 2002), each limb's contacts are found **by height**, as
the check finds them (a mesh node below :data:`~authoring.quality.CONTACT_HEIGHT_CM`), and held by
re-solving that limb with the project's IK (:func:`authoring.transitions.track_solve`: frame after frame
in small steps, so no joint leaps). The offset that cancels the contact nodes' ground motion
(:func:`~authoring.slave_feet.plant_offsets`, held where the part lifts off, or at the clip's first frame
for a stance that starts there) moves the site of the part nearest its contacts (:data:`PINS`: heel, ball
or toes for a foot, palm, elbow or wrist for a forearm, face for the head); its frame is kept loosely and
the limb's joints carry it there (the arm's without the clavicle, which is the chest's). Between stances
the offset eases back to none, and it is none at a clip's first and last frames: the postures it starts
and ends in (the DEAD rest) do not change.

With ``held_turns`` (the prone deaths) a forearm is held in its turn as well as its place
(:func:`_held_still`, with the clavicle: the shoulder follows the slumping body): held at one site, the
limp forearms of a propped soldier still pivoted under him, their nodes sliding 5-6 cm.

A knee or thigh near the ground is not moved by its foot's pin (:attr:`Pin.stays`, more important than
the foot): held by the hip and knee instead, a knee whose body pitches past its reach (ststow2dead: the
hip travels 63 cm while the thigh allows 52) went 3 cm into the ground and still slid 5. Knees, thighs
and the trunk are left as they fall (:mod:`authoring.knee_hold` moves the root to hold a knee first).
Where holding a limb would still press the body more than :data:`SINK_CM` deeper into the ground (a foot
turned about its held toes), that frame's change is taken back in part (:func:`_above_ground`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from authoring import ik
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smooth_above
from authoring.slave_feet import merged_runs, part_points, plant_offsets
from authoring.transitions import ClipFrames, track_solve
from peabody.model import Figure

SIDES = ("left", "right")
MIN_SHIFT_CM = 0.05  # a site moved less than this is left as it is
TRACK_ITERATIONS = 20  # per frame of the tracking ...
TRACK_DOF_STEP = 0.01  # ... in steps of at most this (rad): a joint turns at most 11 degrees a frame
HELD_DOF_STEP = 0.004  # held_turns: 4.6 degrees (the shoulder's three together leapt 23 degrees a frame)
SETTLED_FRAMES = 6  # held_turns: a stance that begins this early began in the start posture (held there)
HELD_TURN_CM = 40.0  # held_turns: a radian of a forearm's turn weighs this much (held as firmly as its place)
TURN_CM = 5.0  # a radian of a pinned part's turn weighs as much as this much move (held loosely: a foot
# untucking rolls over its toes)
STAY_DOWN_CM, STAY_FREE_CM = 3.0, 10.0  # a staying part this near the ground is kept where it is, fully ...
# ... and from this height up not at all (eased in between)
SINK_CM = 0.5  # cm: holding a limb may press the body this much deeper into the ground than it was
GUARD_STEPS = 8  # bisection steps of the share of a frame's change that keeps the body out of the ground
GUARD_SIGMA_FRAMES = 3.0
EASE_FRAMES = 15  # a limb's hold eases in (and out) over this many frames next to its stance
PASSES = 2  # the nodes on the ground change a little as a limb moves: measure and solve again


@dataclass(frozen=True)
class Pin:
    """A body part held still while on the ground: its parts (as the check names them, ``{side}`` filled
    in), the sites that may carry its goal and the joints that move it there."""

    parts: tuple[str, ...]
    sites: tuple[str, ...]  # the one nearest the part's contacts carries the goal
    joints: tuple[str, ...]
    priority: int = 0  # a larger number is more important: a knee on the ground before its foot
    stays: bool = False  # not moved, only kept where it is while near the ground (a knee under its foot)
    turns: bool = False  # with ``held_turns``: its turn on the ground is held too (a forearm pivoting)

    def sided(self, side: str) -> Pin:
        parts, sites, joints = (
            tuple(x.format(side=side) for x in xs) for xs in (self.parts, self.sites, self.joints)
        )
        return Pin(parts, sites, joints, self.priority, self.stays, self.turns)


LEG = ("{side}_hip", "{side}_knee", "{side}_ankle", "{side}_toes")
ARM = ("{side}_shoulder", "{side}_elbow", "{side}_wrist")  # not the clavicle: it is the chest's
PINS: tuple[Pin, ...] = (
    Pin(("{side}_foot",), ("{side}_foot.heel", "{side}_foot.ball", "{side}_toes.distal"), LEG),
    Pin(("{side}_knee", "{side}_kneecap", "{side}_thigh"), ("{side}_lower_leg.knee",), LEG[:2], 1, True),
    Pin(("{side}_hand",), ("{side}_palm.palmcenter",), ARM),
    Pin(("{side}_forearm",), ("{side}_lower_arm.proximal", "{side}_lower_arm.distal"), ARM[:2], turns=True),
)
HEAD = Pin(
    ("head",),
    ("bottom_head.nose", "bottom_head.chin", "bottom_head.left_ear", "bottom_head.right_ear"),
    ("neck", "head"),
)


def pins(kin, table: tuple[Pin, ...] = PINS, head: bool = True) -> list[Pin]:
    """The pins of a figure: both sides' limbs (of ``table``) and the head, those whose site and joints it
    has."""
    out = [p.sided(side) for side in SIDES for p in table] + ([HEAD] if head else [])
    return [
        Pin(
            p.parts,
            tuple(s for s in p.sites if s in kin.site_names),
            tuple(j for j in p.joints if j in kin.dof_slices),
            p.priority,
            p.stays,
            p.turns,
        )
        for p in out
        if any(s in kin.site_names for s in p.sites)
    ]


def _nearest_site(kin, sites: np.ndarray, points: np.ndarray, names: tuple[str, ...]) -> str:
    """Of ``names``, the site nearest the part's nodes on the ground, on average over the frames with any
    (the heel for a foot on its heel, the toes' tip for one on its toes)."""
    down = points[..., 1] <= CONTACT_HEIGHT_CM
    frames = np.flatnonzero(down.any(axis=1))
    if len(names) == 1 or not len(frames):
        return names[0]
    centre = np.array([points[f, down[f]].mean(axis=0) for f in frames])
    at = [kin.site_names.index(s) for s in names]
    dist = np.linalg.norm(sites[frames][:, at][..., :3, 3] - centre[:, None], axis=-1).mean(axis=0)
    return names[int(np.argmin(dist))]


def _goal(
    kin,
    pose: np.ndarray,
    loc: np.ndarray,
    figures: FigureSet,
    ptype: str,
    pin: Pin,
    held_turns: bool = False,
    held_from: int = 0,
) -> tuple[ik.Goal, np.ndarray]:
    """One pin's goal (its site moved by the offset that holds its contacts, its frame kept loosely; a
    staying part's where it is, weighed by how near the ground it is) and the move per frame (cm)."""
    points = part_points(pose, loc, figures, ptype, pin.parts)
    sites = kin.site_globals(pose, loc)
    near = _nearest_site(kin, sites, points, pin.sites)
    site = sites[:, kin.site_names.index(near)]
    weight: float | np.ndarray = 1.0
    if pin.stays or not points.shape[1]:
        move = np.zeros((len(pose), 3))
        low = points[..., 1].min(axis=1) if points.shape[1] else np.full(len(pose), np.inf)
        u = np.clip((STAY_FREE_CM - low) / (STAY_FREE_CM - STAY_DOWN_CM), 0.0, 1.0)
        weight = u * u * (3.0 - 2.0 * u)
    elif held_turns and pin.turns:
        move, turn = (_near_stances(x, points) for x in _held_still(site, points, held_from))
        target = _turned(turn, site[:, :3, :3])
        joints = (f"{pin.parts[0].split('_')[0]}_clavicle", *pin.joints)  # the shoulder follows the body
        joints = tuple(j for j in joints if j in kin.dof_slices)
        goal = ik.Goal(near, site[:, :3, 3] + move, target, weight, pin.priority, joints, HELD_TURN_CM)
        return goal, np.maximum(np.linalg.norm(move, axis=1), HELD_TURN_CM * np.linalg.norm(turn, axis=1))
    else:
        move = _near_stances(plant_offsets(points, at_lift_off=True), points)
    goal = ik.Goal(near, site[:, :3, 3] + move, site[:, :3, :3], weight, pin.priority, pin.joints, TURN_CM)
    return goal, np.linalg.norm(move, axis=1)


def _held_still(site: np.ndarray, points: np.ndarray, held_from: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The move ``(n, 3)`` and turn ``(n, 3)``, a rotation vector, that hold the site ``(n, 4, 4)`` of a part
    whose nodes ``points`` are on the ground where it was at touchdown (a stance from the start posture,
    :data:`SETTLED_FRAMES`) or at lift-off (the others, as :func:`~authoring.slave_feet.plant_offsets`
    ``at_lift_off``), eased in between
    the stances and none at the first and last frames: a forearm held at one site still pivoted about it
    (prfire2dead: 28 degrees, its nodes slid 5 cm). None up to ``held_from`` either (the hands still hold
    the rifle: held from the first frame, a palm left the grip by 1.1 cm)."""
    from scipy.spatial.transform import Rotation

    n = len(site)
    move, turn = np.zeros((n, 3)), np.zeros((n, 3))
    runs = merged_runs(np.asarray((points[..., 1] <= CONTACT_HEIGHT_CM).any(axis=1)))
    for a, b in runs:
        if (a == 0 and b == n - 1) or b <= held_from:
            continue
        k = max(a, held_from) if a <= max(SETTLED_FRAMES, held_from) else b
        a = max(a, held_from)
        move[a : b + 1] = site[k, :3, 3] - site[a : b + 1, :3, 3]
        rel = site[k, :3, :3] @ site[a : b + 1, :3, :3].transpose(0, 2, 1)
        turn[a : b + 1] = Rotation.from_matrix(rel).as_rotvec()
    held = np.zeros(n, dtype=bool)
    for a, b in runs:
        held[a : b + 1] = True
    held[[0, -1]] = True  # none there
    held[: held_from + 1] = True
    move[[0, -1]], turn[[0, -1]] = 0.0, 0.0
    return _eased_between(move, held), _eased_between(turn, held)


def _eased_between(x: np.ndarray, held: np.ndarray) -> np.ndarray:
    """``x`` ``(n, d)`` where ``held``, eased (smoothstep) from one held frame's value to the next between."""
    out = x.copy()
    idx = np.flatnonzero(held)
    for lo, hi in itertools.pairwise(idx):
        if hi - lo > 1:
            u = (np.arange(lo + 1, hi) - lo) / (hi - lo)
            out[lo + 1 : hi] = x[lo] + (u * u * (3.0 - 2.0 * u))[:, None] * (x[hi] - x[lo])
    return out


def _turned(turn: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """The frames ``(n, 3, 3)`` turned by the rotation vectors ``turn`` ``(n, 3)`` (world)."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_rotvec(turn).as_matrix() @ frames)


def _near_stances(move: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``move`` eased in and out only over the :data:`EASE_FRAMES` next to each stance: a limb in the air
    longer than that moves as it fell in between (eased over the whole gap, the hands that still held the
    rifle moved off it, 47 frames before they landed)."""
    out = move.copy()
    stance = np.zeros(len(move), dtype=bool)
    for a, b in merged_runs(np.asarray((points[..., 1] <= CONTACT_HEIGHT_CM).any(axis=1))):
        stance[a : b + 1] = True
    edges = np.flatnonzero(np.diff(np.r_[True, stance, True].astype(np.int8)))
    for first, stop in zip(edges[::2], edges[1::2], strict=True):  # the gaps [first, stop)
        if stop - first <= 2 * EASE_FRAMES:
            continue
        lo = move[first - 1] if first > 0 else np.zeros(3)
        hi = move[stop] if stop < len(move) else np.zeros(3)
        u = np.arange(1, EASE_FRAMES + 1) / (EASE_FRAMES + 1)
        s = (u * u * (3.0 - 2.0 * u))[:, None]
        out[first:stop] = 0.0
        out[first : first + EASE_FRAMES] = lo * (1.0 - s)
        out[stop - EASE_FRAMES : stop] = hi * s
    return out


def pin_contacts(
    pose: np.ndarray,
    loc: np.ndarray,
    figures: FigureSet,
    ptype: str,
    held_turns: bool = False,
    held_from: int = 0,
    table: tuple[Pin, ...] = PINS,
    head: bool = True,
) -> tuple[np.ndarray, float]:
    """``pose`` ``(n, ndof)`` (root globals ``loc``) with every limb's contacts held (see the module
    docstring; ``table``, ``head``: which, as :func:`pins`); returns the poses and the largest move of a site
    (cm)."""
    kin = figures.kin[ptype]
    worst = 0.0
    start = pose
    for _ in range(PASSES):
        goals: list[ik.Goal] = []
        moved = np.zeros(len(pose))
        for pin in pins(kin, table, head):
            goal, m = _goal(kin, pose, loc, figures, ptype, pin, held_turns, held_from)
            goals.append(goal)
            moved = np.maximum(moved, m)
        if not (moved > MIN_SHIFT_CM).any():
            break
        worst = max(worst, float(moved.max()))
        step = HELD_DOF_STEP if held_turns else TRACK_DOF_STEP
        pose = track_solve(kin, pose, goals, loc, iterations=TRACK_ITERATIONS, max_dof_step=step)
    return _above_ground(kin, np.asarray(start), pose, loc), worst


def _lowest(kin, pose: np.ndarray, loc: np.ndarray) -> np.ndarray:
    """Per frame the body's lowest mesh node (cm)."""
    from authoring.postures import lowest_point

    return np.asarray(lowest_point(kin, pose, loc), dtype=np.float64)


def _above_ground(kin, before: np.ndarray, after: np.ndarray, loc: np.ndarray) -> np.ndarray:
    """``after`` taken back toward ``before`` in the frames where holding a limb pressed the body deeper
    than :data:`SINK_CM` into the ground (a foot turned about its held toes): per frame the largest share
    of the change that does not, the shares smoothed over the clip (at or below the need, so no joint
    leaps)."""
    floor = np.minimum(_lowest(kin, before, loc), 0.0) - SINK_CM
    ok = _lowest(kin, after, loc) >= floor
    if ok.all():
        return after
    lo, hi = np.zeros(len(after)), np.ones(len(after))
    for _ in range(GUARD_STEPS):  # bisection on the share of the change, every frame at once
        mid = 0.5 * (lo + hi)
        fine = _lowest(kin, before + mid[:, None] * (after - before), loc) >= floor
        lo, hi = np.where(fine, mid, lo), np.where(fine, hi, mid)
    share = np.where(ok, 1.0, lo)
    return before + _smooth_below(share, GUARD_SIGMA_FRAMES)[:, None] * (after - before)


def pin_frames(
    frames: ClipFrames, soldier: Figure, held_turns: bool = False, held_from: int = 0
) -> ClipFrames:
    """A simulated clip of ``soldier`` with its limbs' contacts held (:func:`pin_contacts`); ``held_turns``:
    the forearms' turns too, from the frame ``held_from`` on (:func:`_held_still`)."""
    figs = FigureSet({"body": soldier})
    poses, _ = pin_contacts(frames.poses, frames.roots, figs, "body", held_turns, held_from)
    return ClipFrames(poses, frames.roots, frames.rifles, frames.fps)


def _smooth_below(share: np.ndarray, sigma: float) -> np.ndarray:
    """``share`` smoothed over frames, never above it (the mirror of :func:`smooth_above`)."""
    return 1.0 - smooth_above(1.0 - share, sigma)
