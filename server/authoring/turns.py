"""Turning in place and side-stepping (issue 14): STAND_STOWED to STAND_STOWED moved on the ground.

A **turn** pivots on the ball of the foot on the inside of the turn (the left foot for a left turn): that
heel rises (``PIVOT_PITCH``) and the toes bend up past flat (``PIVOT_TOES``) so that only the ball is on the
ground, the pelvis leans over the pivot foot, then the body turns about the pivot ball while the other foot
takes a step round it and lands flat at its place in the turned stance; the pivot heel comes down and the
pelvis settles. A turn of more than ``MAX_STEP_TURN`` degrees is taken in equal steps of the outer foot while
the pivot heel stays up. A right turn is a different motion from a left turn played backwards (its pivot is
the right foot, the rear foot of the staggered stance), so every turn is its own clip.

A **side-step** steps the leading foot out sideways (the pelvis first leans over the trailing foot) and
draws the trailing foot after it to its place in the moved stance; the feet never cross.

Feet use the gait machinery (:mod:`server.authoring.gait`): the stepping foot's track is a
:class:`~server.authoring.gait.Footfall` sequence (heel rising on the ball, lift, flat landing) from
:func:`~server.authoring.gait.foot_track`; in a turn it is a step on the spot in the *start* stance carried
round the pivot by the foot's own turn, so it travels on an arc about the pivot and never crosses the pivot
foot. The upper body keeps STAND_STOWED with the rifle at the ready, turned with the pelvis; IK puts the
heels on their tracks and the palms on the rifle, as for walking.

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

from server.authoring import ik
from server.authoring.gait import (
    ADJUST_PITCH,
    BASE,
    FPS,
    ROCK_UP,
    BaseStance,
    Footfall,
    _frame,
    _keyed,
    _smooth,
    foot_track,
)
from server.authoring.motion import KeyPosture
from server.authoring.postures import RIFLE, SOLDIER, arm, leg, palm_targets
from server.authoring.transitions import ClipFrames, carrier_globals, carry_of
from server.peabody import values as V
from server.peabody.fk import FigureKinematics

DEG = math.pi / 180.0
SIDES = ("left", "right")

TURN_ANGLES = (45, 90, 180)
MAX_STEP_TURN = 90.0  # degrees one step of the outer foot turns at most
PIVOT_PITCH = 14.0  # degrees the pivot heel rises (heel ~5 cm up: off the ground while the foot turns)
PIVOT_TOES = 18.0  # degrees the pivot toes bend up past flat, so their tips clear the ground too
PIVOT_RISE = 1.5  # cm the pelvis rises while the body stands on the pivot ball
LEAN = 0.65  # of the way the pelvis moves towards the pivot foot (the weight goes onto it)
SIDESTEP_LEAN = 4.0  # cm the pelvis leans over the standing foot while the other steps
STEP_LIFT = 8.0  # cm a stepping foot clears the ground
SIDESTEP = 45.0  # cm a side-step moves the soldier
CLEAR = 0.12  # s after lift-off before a stepping foot travels, and before landing that it stops
SIDESTEP_DIP = 4.0  # cm the pelvis lowers while the feet are wide apart
LOOK_AHEAD = 0.12  # s the head leads the body's turn (the soldier looks where he turns)


@dataclass
class StepPlan:
    """One clip's plan (times s, lengths cm, angles degrees, clip frame = the start posture's).

    The body (pelvis, upper body, rifle) is the base posture turned ``turn_keys`` about the ground point
    ``pivot``, shifted by ``x_keys`` / ``z_keys`` (world), leaning ``lean_keys`` (a fraction) of the way
    towards ``lean_to`` (x, z of a point in the start stance, turned with the body) and risen ``rise_keys``.
    Each foot follows ``falls`` in the start stance (None: the pivot's heel lift ``pivot_lift`` = (rise
    start, up, lower start, down)), carried about ``pivot`` by its ``foot_turn`` keys and sideways by its
    ``foot_shift`` keys (cm along x): a stepping foot steps on the spot and is carried only while clear of
    the ground, so nothing moves across the ground while touching it."""

    name: str
    t_end: float
    pivot: tuple[float, float]
    end_move: tuple[float, float, float]
    turn_keys: list[tuple[float, float]]
    x_keys: list[tuple[float, float]]
    z_keys: list[tuple[float, float]]
    lean_keys: list[tuple[float, float]]
    lean_to: tuple[float, float]
    rise_keys: list[tuple[float, float]]
    falls: dict[str, list[Footfall] | None]
    foot_turn: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    foot_shift: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    pivot_lift: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)


def ground_move(x: float, z: float, yaw: float) -> np.ndarray:
    """The 4x4 ground-plane rigid move ``p -> Ry(yaw) p + (x, 0, z)`` (yaw degrees, + = left)."""
    m = V.rot_y(yaw * DEG)
    m[0, 3], m[2, 3] = x, z
    return m


def _about(pivot: tuple[float, float], yaw: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` turns by ``yaw`` degrees about the vertical through ground point ``pivot``."""
    c = np.array([pivot[0], 0.0, pivot[1]])
    r = _frame(np.zeros((len(yaw), 3)), yaw, np.zeros(len(yaw)))
    r[:, :3, 3] = c - r[:, :3, :3] @ c
    return r


def _turn_move(pivot: tuple[float, float], yaw: float) -> tuple[float, float, float]:
    m = _about(pivot, np.array([yaw]))[0]
    return float(m[0, 3]), float(m[2, 3]), float(yaw)


# --- feet ---------------------------------------------------------------------------------------------------


def pivot_track(
    base: BaseStance, side: str, t: np.ndarray, lift: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Heel frames and toe angles (rad) of a pivot foot in the start stance: the heel rises and comes down
    rocking about the ball (the rocker ``ROCK_UP`` above the ball site, as in the gait), the toes bent up
    past flat by ``PIVOT_TOES`` meanwhile so only the ball touches the ground."""
    a, b, c, d = lift
    up = _smooth((t - a) / (b - a)) - _smooth((t - c) / (d - c))
    pitch = -PIVOT_PITCH * up
    yaw = np.full(len(t), base.yaw[side])
    rock = base.ball[side] + np.array([0.0, ROCK_UP, 0.0])
    heel = np.array([base.heel[side][0], 0.0, base.heel[side][1]])
    rocker = heel + V.rot_y(base.yaw[side] * DEG)[:3, :3] @ rock
    frames = _frame(np.zeros((len(t), 3)), yaw, pitch)
    frames[:, :3, 3] = rocker - frames[:, :3, :3] @ rock
    return frames, (PIVOT_PITCH + PIVOT_TOES) * up * DEG


def step_falls(
    base: BaseStance, side: str, steps: list[tuple[float, float, float]], heels: list[tuple[float, float]]
) -> list[Footfall]:
    """Footfalls of a foot that stands at its base place and takes ``steps`` = (heel rise, lift-off, landing)
    to the heel places ``heels`` (at its base yaw), landing flat."""
    falls: list[Footfall] = []
    t_on, heel = -np.inf, base.heel[side]
    for (t_heel, t_off, t_land), nxt in zip(steps, heels, strict=True):
        falls.append(
            Footfall(side, t_on, heel, base.yaw[side], t_on, t_heel, t_off, 0.0, ADJUST_PITCH, lift=STEP_LIFT)
        )
        t_on, heel = t_land, nxt
    falls.append(Footfall(side, t_on, heel, base.yaw[side], t_on, np.inf, np.inf))
    return falls


# --- plans --------------------------------------------------------------------------------------------------


def _r(t: float) -> float:
    return round(t * FPS) / FPS


def plan_turn(base: BaseStance, direction: str, angle: float) -> StepPlan:
    """Turn ``angle`` degrees to ``direction`` ("left" / "right") pivoting on that foot's ball."""
    pivot_side = direction
    stepper = "right" if pivot_side == "left" else "left"
    sign = 1.0 if direction == "left" else -1.0
    ball = tuple(float(v) for v in base.ball_at(pivot_side))
    k = max(1, math.ceil(angle / MAX_STEP_TURN - 1e-9))
    part = angle / k
    swing = _r(0.3 + 0.3 * part / 90.0)  # seconds per step of the outer foot
    t_heel, t_off = 0.2, 0.38  # the outer heel rises, the foot leaves the ground
    lift_up = (0.12, 0.34)  # the pivot heel rises before anything turns
    steps: list[tuple[float, float, float]] = []
    turn_keys: list[tuple[float, float]] = [(0.0, 0.0)]
    foot_keys: list[tuple[float, float]] = [(0.0, 0.0)]
    for i in range(k):
        t_land = _r(t_off + swing)
        steps.append((t_heel, t_off, t_land))
        done, now = sign * part * i, sign * part * (i + 1)
        turn_keys += [(t_off - 0.06, done), (t_land - 0.04, now)]
        foot_keys += [(t_off + CLEAR, done), (t_land - CLEAR, now)]
        t_heel, t_off = t_land + 0.04, _r(t_land + 0.16)
    t_land = steps[-1][2]
    lift = (*lift_up, t_land, t_land + 0.22)
    t_end = _r(t_land + 0.5)
    falls: dict[str, list[Footfall] | None] = {
        pivot_side: None,
        stepper: step_falls(base, stepper, steps, [base.heel[stepper]] * k),
    }
    yaw = sign * angle
    foot_keys.append((t_end, yaw))
    turn_keys.append((t_end, yaw))
    mid = (0.5 * (base.heel[pivot_side][0] + ball[0]), 0.5 * (base.heel[pivot_side][1] + ball[1]))
    return StepPlan(
        f"turn_{direction[0]}{angle:g}",
        t_end,
        ball,
        _turn_move(ball, yaw),
        turn_keys,
        [(0.0, 0.0)],
        [(0.0, 0.0)],
        [(0.0, 0.0), (lift_up[1], LEAN), (t_land, LEAN), (t_end - 0.05, 0.0)],
        mid,
        [(0.0, 0.0), (lift_up[1], PIVOT_RISE), (t_land, PIVOT_RISE), (t_land + 0.25, 0.0)],
        falls,
        foot_turn={pivot_side: turn_keys, stepper: foot_keys},
        pivot_lift={pivot_side: lift},
    )


def plan_sidestep(base: BaseStance, direction: str, distance: float = SIDESTEP) -> StepPlan:
    """Side-step ``distance`` cm to ``direction``: that foot steps out, the other follows."""
    lead = direction
    trail = "right" if lead == "left" else "left"
    dx = -distance if direction == "left" else distance  # left is -x
    lead_step = (0.18, 0.3, 0.72)
    trail_step = (0.86, 0.98, 1.4)
    falls: dict[str, list[Footfall] | None] = {
        lead: step_falls(base, lead, [lead_step], [base.heel[lead]]),
        trail: step_falls(base, trail, [trail_step], [base.heel[trail]]),
    }
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
        [(0.0, 0.0)],
        [(0.0, 0.0)],
        (0.0, 0.0),
        dip,
        falls,
        foot_shift=shift,
    )


# --- recording ----------------------------------------------------------------------------------------------


def record_plan(
    plan: StepPlan, kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture, base: BaseStance
) -> ClipFrames:
    """Every frame of a plan: the body's placement, the feet, then IK (palms on the rifle, heels on their
    tracks, eyes level and turning ``LOOK_AHEAD`` s ahead of the body)."""
    n = round(plan.t_end * FPS) + 1
    t = np.arange(n) / FPS
    q0, root0, rifle0 = key.poses[SOLDIER], key.locations[SOLDIER], key.locations[RIFLE]
    turn = _keyed(plan.turn_keys, t)
    body = _about(plan.pivot, turn)
    # lean towards a point of the start stance, turned with the body
    to = body @ np.array([plan.lean_to[0], 0.0, plan.lean_to[1], 1.0])
    pelvis = body @ np.array([root0[0, 3], 0.0, root0[2, 3], 1.0])
    lean = _keyed(plan.lean_keys, t)[:, None] * (to[:, [0, 2]] - pelvis[:, [0, 2]])
    body[:, 0, 3] += _keyed(plan.x_keys, t) + lean[:, 0]
    body[:, 2, 3] += _keyed(plan.z_keys, t) + lean[:, 1]
    body[:, 1, 3] += _keyed(plan.rise_keys, t)
    roots = body @ root0
    rest = np.broadcast_to(q0, (n, kin.ndof)).copy()
    heels: dict[str, np.ndarray] = {}
    for s in SIDES:
        falls = plan.falls[s]
        if falls is not None:
            local, toes = foot_track(base.ball[s], falls, t, STEP_LIFT)
        else:
            local, toes = pivot_track(base, s, t, plan.pivot_lift[s])
        carried = _about(plan.pivot, _keyed(plan.foot_turn.get(s, [(0.0, 0.0)]), t))
        carried[:, 0, 3] += _keyed(plan.foot_shift.get(s, [(0.0, 0.0)]), t)
        heels[s] = carried @ local
        rest[:, kin.dof_slices[f"{s}_toes"]] = toes[:, None]
    carry = carry_of(kin, key)
    rifles = carrier_globals(kin, rest, roots) @ carry
    sight = kin.site_globals(q0, root0)[kin.site_names.index("bottom_head.sight"), :3, :3]
    goals: list[ik.Goal] = []
    for s in ("right", "left"):
        tg = palm_targets(rkin, rifles, s)
        goals.append(ik.Goal(f"{s}_palm.palmcenter", tg[:, :3, 3], None, 1.0, 3, arm(s)))
        goals.append(
            ik.Goal(f"{s}_palm.palmcenter", None, tg[:, :3, :3], 1.0, 1, arm(s), orientation_weight=8.0)
        )
        goals.append(ik.Goal(f"{s}_foot.heel", heels[s][:, :3, 3], heels[s][:, :3, :3], 1.0, 2, leg(s)))
    look = _about(plan.pivot, _keyed(plan.turn_keys, t + LOOK_AHEAD))[:, :3, :3] @ sight
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
    return {name: (lambda ctx, name=name: _record(ctx)[name]) for name in TURN_CLIPS}
