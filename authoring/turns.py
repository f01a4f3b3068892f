"""Turning in place and side-stepping (issue 14): STAND_STOWED to STAND_STOWED moved on the ground.

A **turn** turns the soldier about the vertical through his pelvis, so he ends where he started (issue 14:
turn in place, pivoting on a planted foot; the check's ``turn_travel_cm``). The feet take turns
(:func:`turn_steps`: 45 degrees in two steps, 90 in three, 180 in five), each landing at most
``STEP_AHEAD`` degrees beyond the other in the turned stance; the outer foot steps round first while the
inside foot (the one on the side of the turn, the left foot for a left turn), its heel up, pivots on its
ball; after that every standing foot that steps again pivots on its ball while the other one is in the air
(``PIVOT_SHARE`` of its next step's turn, at most ``PIVOT_MAX`` degrees), and the pelvis leans over the
standing foot. The body turns smoothly through the middle of the yaws both legs can reach once each foot
has landed (:data:`FOOT_TURN_RANGE`: from STAND_STOWED the legs turn a foot inwards, to the right, by up to
60 degrees but outwards hardly at all); the head looks a little ahead. The stance is a fighting stance (the
left foot 26 cm ahead), so no one foot's ball lies under the pelvis: a turn about a ball carried the
soldier 10-71 cm (session 19), and a foot must step to its place in the turned stance. A right turn is not
a left turn played backwards, so every turn is its own clip.

A **side-step** steps the leading foot out sideways (the pelvis first leans over the trailing foot) and
draws the trailing foot after it to its place in the moved stance; the feet never cross.

Feet use the gait machinery (:mod:`authoring.gait`): a stepping foot's track is a
:class:`~authoring.gait.Footfall` sequence (heel rising on the ball, turning on it for a pivot, lift, flat
landing) from :func:`~authoring.gait.foot_track`, a step on the spot in the *start* stance carried (turned
about the pelvis, or shifted sideways) only while it is clear of the ground, so no foot moves across the
ground while touching it but for turning on its ball. The upper body keeps
STAND_STOWED with the rifle at the ready, turned with the pelvis; IK puts the heels on their tracks and the
palms on the rifle, as for walking.

Unlike the gait clips these clips really move the soldier: the clip frame is the start posture's, and the
last frame is STAND_STOWED moved by the ground-plane rigid move ``p -> Ry(yaw) p + (x, 0, z)`` recorded as
the channelset's ``end_offset = (x cm, z cm, yaw deg)`` (+ yaw = to the left, about +Y).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from authoring import ik
from authoring.gait import (
    ADJUST_PITCH,
    BASE,
    FPS,
    BaseStance,
    Footfall,
    carried_rifle_goals,
    foot_track,
)
from authoring.ground_frames import turned_about
from authoring.motion import KeyPosture
from authoring.postures import RIFLE, SOLDIER
from authoring.signal_shaping import keyed
from authoring.transitions import ClipFrames, carrier_globals, carry_of
from peabody import values as V
from peabody.fk import FigureKinematics

DEG = math.pi / 180.0
SIDES = ("left", "right")

TURN_ANGLES = (45, 90, 180)
STEP_AHEAD = 45.0  # degrees a stepping foot lands at most beyond the other one
# how far each foot can turn from its STAND_STOWED yaw relative to the body (+ = to the left), degrees: IK on
# soldier.fig's legs reaches about -60..+5 (left) and -65..+15 (right); the body's turn keeps within both
FOOT_TURN_RANGE = {"left": (-55.0, 3.0), "right": (-60.0, 12.0)}
FIRST_HEEL = 0.3  # s: the first heel rises (the pelvis already leaning over the other foot)
LEAN_OUT = 0.5  # of the way the pelvis moves towards the outer foot while the inside foot steps
LEAN_IN = 0.65  # of the way it moves towards the inside foot while the outer foot steps round it
SIDESTEP_LEAN = 4.0  # cm the pelvis leans over the standing foot while the other steps
STEP_LIFT = 8.0  # cm a stepping foot clears the ground
SIDESTEP = 45.0  # cm a side-step moves the soldier
CLEAR = 0.12  # s after lift-off before a stepping foot travels, and before landing that it stops
SIDESTEP_DIP = 4.0  # cm the pelvis lowers while the feet are wide apart
LOOK_AHEAD = 0.12  # s the head leads the body's turn (the soldier looks where he turns) ...
LOOK_MAX = 15.0  # ... by at most this many degrees (the neck's twist)
PIVOT_SHARE = 0.5  # of its next step's turn a standing foot pivots on its ball while the other one swings
PIVOT_MAX = 20.0  # degrees a foot pivots at most (the ankle and hip turn it further only in a jerk)
# s before the other foot lifts off that the standing foot's heel rises to pivot (1 cm or more up by the time
# it carries the weight alone: the server turns a flat foot about its middle, and its ball slid) ...
HEEL_LEAD = 0.1
HEEL_FIRST = 0.1  # s ... the heel starting to rise this much earlier and the foot turning this much later ...
HEEL_UP = 0.25  # s ... and rising quickly until this long after the rise (off the ground as the foot turns)
PIVOT_LEAD = 0.12  # s before its own lift-off that a pivoting foot has turned


@dataclass
class StepPlan:
    """One clip's plan (times s, lengths cm, angles degrees, clip frame = the start posture's).

    The body (pelvis, upper body, rifle) is the base posture turned ``turn_keys`` (monotone cubic between
    the keys) about the ground point
    ``pivot``, shifted by ``x_keys`` (world), risen ``rise_keys`` and leaning ``lean_keys[side]`` (a
    fraction) of the way towards the middle of that foot. Each foot follows ``falls`` (steps on the spot in
    the start stance), carried about ``pivot`` by its ``foot_turn`` keys and sideways by its ``foot_shift``
    keys (cm along x) only while it is clear of the ground."""

    name: str
    t_end: float
    pivot: tuple[float, float]
    end_move: tuple[float, float, float]
    turn_keys: list[tuple[float, float]]
    x_keys: list[tuple[float, float]]
    rise_keys: list[tuple[float, float]]
    falls: dict[str, list[Footfall]]
    lean_keys: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    foot_turn: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    foot_shift: dict[str, list[tuple[float, float]]] = field(default_factory=dict)


def ground_move(x: float, z: float, yaw: float) -> np.ndarray:
    """The 4x4 ground-plane rigid move ``p -> Ry(yaw) p + (x, 0, z)`` (yaw degrees, + = left)."""
    m = V.rot_y(yaw * DEG)
    m[0, 3], m[2, 3] = x, z
    return m


def _turn_move(pivot: tuple[float, float], yaw: float) -> tuple[float, float, float]:
    m = turned_about(pivot, np.array([yaw]))[0]
    return float(m[0, 3]), float(m[2, 3]), float(yaw)


# --- feet ---------------------------------------------------------------------------------------------------


def step_falls(
    base: BaseStance, side: str, steps: list[tuple[float, float, float]], pivots: list[float] | None = None
) -> list[Footfall]:
    """Footfalls of a foot that stands at its base place and takes ``steps`` = (heel rise, lift-off,
    landing) on the spot, landing flat (where it lands is the carrying's business). ``pivots``: per step, the
    degrees the foot turns on its ball before it lifts off (its heel rising from the rise, the turn done by
    the time it leaves the ground less ``PIVOT_LEAD``)."""
    falls: list[Footfall] = []
    t_on = -np.inf
    heel, yaw = base.heel[side], base.yaw[side]
    for k, (t_heel, t_off, t_land) in enumerate(steps):
        turn = 0.0 if pivots is None else pivots[k]
        pivot: dict[str, Any] = {}
        if turn:  # the heel clears the ground before the foot turns on its ball
            pivot = dict(
                yaw_off=yaw + turn,
                turn_from=t_heel + HEEL_FIRST,
                turn_by=t_off - PIVOT_LEAD,
                early=(t_heel - HEEL_FIRST, t_heel + HEEL_UP),
            )
        falls.append(
            Footfall(side, t_on, heel, yaw, t_on, t_heel, t_off, 0.0, ADJUST_PITCH, lift=STEP_LIFT, **pivot)
        )
        t_on = t_land
    falls.append(Footfall(side, t_on, heel, yaw, t_on, np.inf, np.inf))
    return falls


# --- plans --------------------------------------------------------------------------------------------------


def _r(t: float) -> float:
    return round(t * FPS) / FPS


def turn_steps(angle: float, first: str = "outer") -> list[tuple[str, float]]:
    """("inside" / "outer", yaw reached) of each step of a turn by ``angle`` degrees (> 0): the feet take
    turns, each at most ``STEP_AHEAD`` degrees beyond the other, ``first`` first (the outer foot steps
    round while the inside one pivots)."""
    yaw = {"inside": 0.0, "outer": 0.0}
    out: list[tuple[str, float]] = []
    role = first
    while min(yaw.values()) < angle:
        other = "outer" if role == "inside" else "inside"
        yaw[role] = min(yaw[other] + STEP_AHEAD, float(angle))
        out.append((role, yaw[role]))
        role = other
    return out


def body_yaw(feet: dict[str, float], end: float) -> float:
    """The body's yaw (degrees) once the feet stand turned ``feet``: the middle of the yaws that both legs
    reach (:data:`FOOT_TURN_RANGE`), kept between the start (0) and the turn's ``end``; the end itself once
    both feet are there."""
    if all(v == end for v in feet.values()):
        return end
    lo = max(feet[s] - FOOT_TURN_RANGE[s][1] for s in SIDES)
    hi = min(feet[s] - FOOT_TURN_RANGE[s][0] for s in SIDES)
    a, b = sorted((0.0, end))
    lo, hi = max(lo, a), min(hi, b)
    return 0.5 * (lo + hi) if lo <= hi else 0.5 * sum(feet.values())


def plan_turn(base: BaseStance, direction: str, angle: float) -> StepPlan:
    """Turn ``angle`` degrees to ``direction`` ("left" / "right") about the vertical through the pelvis, in
    the steps of :func:`turn_steps`: the outer foot steps round first while the inside foot, its heel up,
    pivots on its ball; then the feet take turns, each standing foot that steps again pivoting on its ball
    (``PIVOT_SHARE`` of its next step's turn) while the other one is in the air, and every foot landing in
    the turned stance, so the soldier ends where he started (``end_offset`` = (0, 0, yaw))."""
    inside = direction
    outer = "right" if inside == "left" else "left"
    role_side = {"inside": inside, "outer": outer}
    sign = 1.0 if direction == "left" else -1.0
    centre = (float(base.pelvis[0]), float(base.pelvis[1]))
    plan = turn_steps(angle)
    steps: dict[str, list[tuple[float, float, float]]] = {inside: [], outer: []}
    pivots: dict[str, list[float]] = {inside: [], outer: []}
    keys: dict[str, list[tuple[float, float]]] = {inside: [(0.0, 0.0)], outer: [(0.0, 0.0)]}
    lean: dict[str, list[tuple[float, float]]] = {inside: [(0.0, 0.0)], outer: [(0.0, 0.0)]}
    yaw = {inside: 0.0, outer: 0.0}
    body: list[tuple[float, float]] = [(0.0, 0.0), (0.15, 0.0)]  # starting from rest
    t_heel, t_off = FIRST_HEEL, _r(FIRST_HEEL + 0.08)
    for i, (role, target) in enumerate(plan):
        side = role_side[role]
        other = outer if side == inside else inside
        swing = _r(0.35 + 0.15 * (target - sign * yaw[side]) / 90.0)
        t_land = _r(t_off + swing)
        steps[side].append((t_heel, t_off, t_land))
        if len(pivots[side]) < len(steps[side]):  # it lifts off from rest
            pivots[side].append(0.0)
        keys[side] += [(t_off + CLEAR, yaw[side]), (t_land - CLEAR, sign * target)]
        w = LEAN_IN if other == inside else LEAN_OUT  # the weight onto the standing foot
        lean[other] += [(t_off - 0.23, 0.0), (t_off, w), (t_land - 0.05, w), (t_land + 0.12, 0.0)]
        yaw[side] = sign * target
        nxt = next((y for r, y in plan[i + 1 :] if role_side[r] == other), None)
        turned = dict(yaw)
        if nxt is not None:  # the standing foot steps again: it pivots on its ball while this one swings
            pivots[other].append(sign * min(PIVOT_SHARE * (nxt - sign * yaw[other]), PIVOT_MAX))
            turned[other] += pivots[other][-1]
        body.append((t_land, body_yaw(turned, sign * angle)))
        t_heel, t_off = t_off - HEEL_LEAD, _r(t_land + 0.1)
    t_end = _r(t_off + 0.42)
    falls = {s: step_falls(base, s, steps[s], pivots[s]) for s in SIDES}
    return StepPlan(
        f"turn_{direction[0]}{angle:g}",
        t_end,
        centre,
        (0.0, 0.0, sign * angle),
        [*body, (t_end, sign * angle)],
        [(0.0, 0.0)],
        [(0.0, 0.0)],
        falls,
        lean,
        foot_turn=keys,
    )


def plan_sidestep(base: BaseStance, direction: str, distance: float = SIDESTEP) -> StepPlan:
    """Side-step ``distance`` cm to ``direction``: that foot steps out, the other follows."""
    lead = direction
    trail = "right" if lead == "left" else "left"
    dx = -distance if direction == "left" else distance  # left is -x
    lead_step = (0.18, 0.3, 0.72)
    trail_step = (0.86, 0.98, 1.4)
    falls = {lead: step_falls(base, lead, [lead_step]), trail: step_falls(base, trail, [trail_step])}
    shift = {
        s: [(0.0, 0.0), (step[1] + CLEAR, 0.0), (step[2] - CLEAR, dx)]
        for s, step in ((lead, lead_step), (trail, trail_step))
    }
    t_end = 1.85
    lean = SIDESTEP_LEAN * (1.0 if trail == "right" else -1.0)  # over the trailing foot first (left is -x)
    x_keys = [(0.0, 0.0), (0.26, lean), (0.36, lean), (0.9, 0.55 * dx), (1.35, dx - 0.5 * lean), (t_end, dx)]
    dip = [(0.0, 0.0), (0.42, 0.0), (0.72, -SIDESTEP_DIP), (1.0, -SIDESTEP_DIP), (1.45, 0.0)]
    return StepPlan(
        f"sidestep_{direction[0]}",
        t_end,
        (0.0, 0.0),
        (dx, 0.0, 0.0),
        [(0.0, 0.0)],
        x_keys,
        dip,
        falls,
        foot_shift=shift,
    )


# --- recording ----------------------------------------------------------------------------------------------


def body_turn(plan: StepPlan, t: np.ndarray) -> np.ndarray:
    """The body's yaw (degrees) at ``t``: a monotone cubic through ``turn_keys`` (it never overshoots a key
    nor turns back between two), constant outside them."""
    times, values = np.array(plan.turn_keys).T
    if len(times) < 2:
        return np.full(len(t), values[0])
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(times, values)(np.clip(t, times[0], times[-1]))


def record_plan(
    plan: StepPlan, kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture, base: BaseStance
) -> ClipFrames:
    """Every frame of a plan: the body's placement, the feet, then IK (palms on the rifle, heels on their
    tracks, eyes level and turning ``LOOK_AHEAD`` s ahead of the body)."""
    n = round(plan.t_end * FPS) + 1
    t = np.arange(n) / FPS
    q0, root0, rifle0 = key.poses[SOLDIER], key.locations[SOLDIER], key.locations[RIFLE]
    turn = body_turn(plan, t)
    body = turned_about(plan.pivot, turn)
    body[:, 0, 3] += keyed(plan.x_keys, t)
    body[:, 1, 3] += keyed(plan.rise_keys, t)
    rest = np.broadcast_to(q0, (n, kin.ndof)).copy()
    heels: dict[str, np.ndarray] = {}
    pelvis = (body @ np.array([root0[0, 3], 0.0, root0[2, 3], 1.0]))[:, [0, 2]]
    lean = np.zeros((n, 2))
    for s in SIDES:
        local, toes = foot_track(base.ball[s], plan.falls[s], t, STEP_LIFT)
        carried = turned_about(plan.pivot, keyed(plan.foot_turn.get(s, [(0.0, 0.0)]), t))
        carried[:, 0, 3] += keyed(plan.foot_shift.get(s, [(0.0, 0.0)]), t)
        heels[s] = carried @ local
        rest[:, kin.dof_slices[f"{s}_toes"]] = toes[:, None]
        if s in plan.lean_keys:  # towards the middle of the foot (where it is when it carries weight)
            mx, mz = 0.5 * (np.array(base.heel[s]) + base.ball_at(s))
            mid = np.array([mx, 0.0, mz, 1.0])
            foot = (carried @ mid)[:, [0, 2]]
            lean += keyed(plan.lean_keys[s], t)[:, None] * (foot - pelvis)
    body[:, 0, 3] += lean[:, 0]
    body[:, 2, 3] += lean[:, 1]
    roots = body @ root0
    carry = carry_of(kin, key)
    rifles = carrier_globals(kin, rest, roots) @ carry
    sight = kin.site_globals(q0, root0)[kin.site_names.index("bottom_head.sight"), :3, :3]
    goals = carried_rifle_goals(rkin, rifles, heels)
    ahead = np.clip(body_turn(plan, t + LOOK_AHEAD) - turn, -LOOK_MAX, LOOK_MAX)
    look = turned_about(plan.pivot, turn + ahead)[:, :3, :3] @ sight
    goals.append(ik.Goal("bottom_head.sight", None, look, 1.0, 1, ("neck", "head")))
    poses, report = ik.solve(kin, rest, goals, roots, iterations=60, rest_pose=rest, rest_gain=0.1)
    _REPORTS[plan.name] = report
    rifles = carrier_globals(kin, poses, roots) @ carry
    end = ground_move(*plan.end_move)
    poses[0], roots[0], rifles[0] = q0, root0, rifle0
    poses[-1], roots[-1], rifles[-1] = q0, end @ root0, end @ rifle0
    return ClipFrames(poses, roots, rifles, FPS)


_REPORTS: dict[str, ik.SolveReport] = {}


# --- the library's clips ------------------------------------------------------------------------------------


TURN_NODES: tuple[str, ...] = (BASE,)


def turn_plans(base: BaseStance) -> list[StepPlan]:
    plans = [plan_turn(base, d, a) for d in SIDES for a in TURN_ANGLES]
    return plans + [plan_sidestep(base, d) for d in SIDES]


TURN_CLIPS: tuple[str, ...] = (
    *(f"turn_{d[0]}{a}" for d in SIDES for a in TURN_ANGLES),
    "sidestep_l",
    "sidestep_r",
)


def turn_arcs() -> list[tuple[str, str, str, bool]]:
    """(from, to, clip, forward): every clip is a self-loop on STAND_STOWED (it moves the soldier)."""
    return [(BASE, BASE, name, True) for name in TURN_CLIPS]


_CACHE: dict[int, dict[str, tuple[ClipFrames, tuple[float, float, float]]]] = {}


def _record(ctx: Any) -> dict[str, tuple[ClipFrames, tuple[float, float, float]]]:
    if id(ctx) not in _CACHE:
        _CACHE.clear()
        kin, rkin = FigureKinematics(ctx.soldier), FigureKinematics(ctx.rifle)
        key = ctx.keys[BASE]
        base = BaseStance.of(kin, key)
        _CACHE[id(ctx)] = {
            p.name: (record_plan(p, kin, rkin, key, base), p.end_move) for p in turn_plans(base)
        }
    return _CACHE[id(ctx)]


def turn_clips() -> dict[str, Callable[[Any], tuple[ClipFrames, tuple[float, float, float]]]]:
    """Clip name -> generator taking the build context: (frames, end_offset)."""
    return {name: _turn_clip(name) for name in TURN_CLIPS}


def _turn_clip(name: str) -> Callable[[Any], tuple[ClipFrames, tuple[float, float, float]]]:
    """The generator of turn clip ``name`` (a closure per name, not one late-bound loop variable)."""
    return lambda ctx: _record(ctx)[name]
