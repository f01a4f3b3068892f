"""Walking, backward walking and running (seed 002, 3.3): a procedural gait with IK foot planting.

In 1994 Hyeongseok Ko's walking system made these strides; this is a small system in its spirit. A walk is
a timeline of **footfalls** (which foot, when it lands, where, turned how). Between footfalls each foot rolls:

* it lands pitched (heel first; backwards, toes first) and rocks flat about that contact point;
* it stays flat while it carries the body;
* before the other foot lands its heel rises, the foot rocking about the ball of the foot (a point
  ``ROCK_UP`` above the ball site, so the ball and the flat toes' tip each move under a centimetre);
* it leaves the ground and swings along an arc ``lift`` cm high to its next footfall, turning in the air.

A rocker's contact point never moves, so a foot on the ground never slides; a foot on the ground never
turns either (a pivot would sweep its toe tip or heel across the ground): a foot that must change its
place or yaw takes a step. The pelvis follows the
footfalls: it progresses at the gait's speed (accelerating out of the base posture in the start step and
slowing into it in the end step), bobs (lowest after a walking footfall, at mid-stance when running), sways
over the supporting foot and turns with the swinging leg; its speed profile is integrated so that it arrives
exactly where the footfalls need it. The upper body carries the rifle at the ready (the spine, head and rifle
carry of a key posture, the spine counter-rotating the pelvis's turn). IK then puts each heel on its
trajectory (hip, knee, ankle) and keeps the palm centres on the rifle
(:func:`authoring.transitions.track_solve`).

A **session** is a start step (one foot swings out of the base posture), cycle steps and an end step (the
other foot swings back into the base posture); clips are cut at footfalls, so one ends exactly where the
next begins. The base stance is staggered with the feet turned out, the gait's feet point straight, so
the start step begins with a little step of the standing foot (lifted ``ADJUST_LIFT`` cm, placed straight
about where its ball stood) before the first foot swings, and the end step ends with a little step of
the last foot to its base place and yaw once the trailing foot has landed. While the pelvis pulls away
in the start step, the standing heel peels off early (``Footfall.early``) so the leg is never
overstretched. Session ``left`` gives ``start_l, cycle_r, cycle_l, end_r``; session ``right`` gives
``start_r, end_l`` (its cycles are the same steps: both sessions place the feet by the same rules). The
letter is the foot that swings.

Clips are **local motion**: a clip's origin is the ground point under the pelvis at its first frame, less
the base posture's pelvis offset (so a standing soldier's origin is between his feet), and the pelvis's
travel to the next clip's origin is removed as a linear ramp; ``stride_length`` (that travel, cm) and
``ground_speed`` (travel / duration, cm/s) are recorded so the server can scale playback to the speed.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypedDict

import numpy as np

from authoring import ik
from authoring.ground_frames import turned_frames
from authoring.motion import KeyPosture
from authoring.postures import RIFLE, SOLDIER, arm, leg, palm_targets, spine_angles
from authoring.signal_shaping import keyed, smoothstep
from authoring.transitions import (
    PARTS,
    ClipFrames,
    carrier_globals,
    carry_of,
    slerp_frames,
)
from peabody import quaternion
from peabody import values as V
from peabody.fk import FigureKinematics, rigid_inverse

FPS = 60
DEG = math.pi / 180.0
SIDES = ("left", "right")
BASE = "STAND_STOWED"  # the base posture of locomotion: standing, rifle at the ready (seed 002, 3.3)


# the rocker of a rising heel: this far (cm) above the ball site, half way to the toe joint (3 cm above it)
ROCK_UP = 1.5
# a standing foot that must change its place or yaw (into or out of the base stance) takes a little step:
# the heel rises on the ball (s), the foot swings (s) this high (cm) and lands flat, then settles (s)
ADJUST_RISE = 0.12
ADJUST_SWING = 0.22
ADJUST_LIFT = 6.0
ADJUST_PITCH = 15.0
ADJUST_SETTLE = 0.2
ADJUST_SWAY = 3.0  # the pelvis leans this far (cm) over the other foot meanwhile


def _frames(t: float) -> float:
    """``t`` rounded to whole frames (clips are cut at footfalls, which must fall on frames)."""
    return round(t * FPS) / FPS


@dataclass(frozen=True)
class Gait:
    """Parameters of one gait (lengths cm, times s, angles degrees)."""

    name: str
    step_length: float  # between successive footfalls along the heading
    step_time: float
    direction: float  # +1 forwards (towards -Z), -1 backwards
    carry: str  # key posture of the upper body and rifle
    reach: float  # how far ahead of the pelvis (along the travel) a foot lands
    height: float = 96.0  # mean pelvis height
    bob: float = 1.8
    sway: float = 2.5
    turn: float = 5.0  # pelvis turn amplitude
    lean: float = 3.0  # pelvis pitch forwards
    lift: float = 9.0  # swing clearance
    # a swinging foot goes up before it goes along and comes down after it: over these first and last
    # fractions of a swing it moves (nearly) only vertically, so a sole or toe tip still within a centimetre
    # of the ground does not skim along it
    swing_rise: float = 0.06
    swing_drop: float = 0.06
    strike: float = 15.0  # foot pitch at landing (+: toes up, rocking about the heel; -: toes first)
    flat: float = 0.18  # fraction of a step to rock flat after landing
    heel_off: float = 0.62  # the heel rises at this fraction of the step the foot supports
    toe_off: float = 1.15  # the foot leaves the ground this many steps after landing
    toe_off_pitch: float = 35.0
    low_at: float = 0.0  # step phase of the lowest pelvis
    start_time: float = 0.7
    end_time: float = 0.8

    @property
    def speed(self) -> float:
        return self.step_length / self.step_time


WALK = Gait("walk", 74.0, 0.55, 1.0, "WALK_READY", reach=37.0, height=94.0, toe_off_pitch=30.0)
BWALK = Gait(
    "bwalk",
    46.0,
    0.6,
    -1.0,
    "WALK_READY",
    reach=23.0,
    height=97.0,
    bob=1.2,
    sway=2.0,
    turn=3.0,
    lean=0.0,
    lift=7.0,
    strike=-10.0,
    toe_off_pitch=20.0,
    start_time=0.75,
    end_time=0.85,
)
RUN = Gait(
    "run",
    118.0,
    0.35,
    1.0,
    "RUN_READY",
    reach=34.0,
    height=93.0,
    bob=2.5,
    sway=2.0,
    turn=7.0,
    lean=14.0,
    lift=20.0,
    strike=6.0,
    flat=0.1,
    heel_off=0.28,
    toe_off=0.55,
    toe_off_pitch=25.0,
    swing_rise=0.0,
    swing_drop=0.0,
    low_at=0.3,
    start_time=0.7,
    end_time=0.9,
)
GAITS: dict[str, Gait] = {g.name: g for g in (WALK, BWALK, RUN)}


# --- footfalls and the feet ---------------------------------------------------------------------------------


@dataclass
class Footfall:
    """One foot on the ground: lands at ``t_on`` with its heel at ``heel`` (x, z) turned ``yaw`` degrees,
    pitched ``strike``; flat by ``t_flat``; heel rises at ``t_heel`` (rocking about the ball, turning to
    ``yaw_off``); leaves the ground at ``t_off`` pitched ``-toe_off_pitch``."""

    side: str
    t_on: float
    heel: tuple[float, float]
    yaw: float
    t_flat: float
    t_heel: float
    t_off: float
    strike: float = 0.0
    toe_off_pitch: float = 35.0
    yaw_off: float | None = None  # None: keeps ``yaw``
    turn_by: float | None = None  # the turn to ``yaw_off`` is done by this time (default t_off)
    lift: float | None = None  # clearance of the swing that leaves this footfall (None: the gait's)
    # (from, join): the heel starts rising early at ``from``, meeting the regular rise at ``join`` (the pelvis
    # of a start step pulls away from the standing foot sooner than in the cycle it joins)
    early: tuple[float, float] | None = None
    # fractions of the swing that leaves this footfall at its start / end where the foot only goes up / down
    rise: float = 0.0
    drop: float = 0.0
    turn_from: float | None = None  # the turn to ``yaw_off`` starts at this time (default t_heel)


def foot_track(
    ball: np.ndarray,
    falls: list[Footfall],
    t: np.ndarray,
    lift: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Heel frames ``(n, 4, 4)`` and toe-joint angles (radians) of one foot at times ``t``.

    ``ball``: the ball relative to the heel on the flat foot (foot frame). The foot rocks about a point
    ``ROCK_UP`` above the ball (the rounded ball of the foot, between the ball site on the sole and the toe
    joint above it), so neither the ball nor the flat toes' tip slides more than ``ROCK_UP * sin(pitch)``.
    A swing goes up before it goes along and comes down after it (the footfall's ``rise`` / ``drop``,
    :attr:`Gait.swing_rise`). Landing toes first, the toes bend up ahead of touching down as the rocking
    foot holds them, so they do not snap up at the footfall."""
    ball = np.asarray(ball, dtype=float) + np.array([0.0, ROCK_UP, 0.0])
    n = len(t)
    heel = np.zeros((n, 3))
    yaw = np.zeros(n)
    pitch = np.zeros(n)
    about_ball = np.zeros(n, dtype=bool)
    for k, f in enumerate(falls):
        nxt = falls[k + 1] if k + 1 < len(falls) else None
        end = nxt.t_on if nxt is not None else np.inf
        live = (t < end) & ((t >= f.t_on) | (k == 0))
        if not live.any():
            continue
        tt = t[live]
        yaw_off = f.yaw if f.yaw_off is None else f.yaw_off
        turn_by = f.t_off if f.turn_by is None else f.turn_by
        y = np.full(len(tt), f.yaw)
        if np.isfinite(f.t_heel) and yaw_off != f.yaw:
            t_turn = f.t_heel if f.turn_from is None else f.turn_from
            y = f.yaw + (yaw_off - f.yaw) * smoothstep((tt - t_turn) / max(turn_by - t_turn, 1e-9))
        p = np.zeros(len(tt))
        on_ball = np.zeros(len(tt), dtype=bool)
        if f.strike:
            land = tt < f.t_flat
            p = np.where(land, f.strike * (1.0 - smoothstep((tt - f.t_on) / max(f.t_flat - f.t_on, 1e-9))), p)
            on_ball |= land & (f.strike < 0)
        t_rise = f.t_heel if f.early is None else min(f.t_heel, f.early[0])
        rising = (tt >= t_rise) & (tt < f.t_off)
        if rising.any():
            r = smoothstep((tt[rising] - f.t_heel) / max(f.t_off - f.t_heel, 1e-9))
            if f.early is not None:
                e0, ej = f.early
                rj = smoothstep(np.array([(ej - f.t_heel) / max(f.t_off - f.t_heel, 1e-9)]))[0]
                ramp = rj * smoothstep((tt[rising] - e0) / max(ej - e0, 1e-9))
                r_early = np.where(tt[rising] <= ej, ramp, 0.0)
                r = np.maximum(r, r_early)
            p[rising] = -f.toe_off_pitch * r
        on_ball |= rising
        h = np.tile([f.heel[0], 0.0, f.heel[1]], (len(tt), 1))
        # a rocker about the ball keeps the ball where the flat foot (at its landing yaw) had it
        flat_ball = np.array([f.heel[0], 0.0, f.heel[1]]) + V.rot_y(f.yaw * DEG)[:3, :3] @ ball
        fr = turned_frames(np.zeros((len(tt), 3)), y, p)
        h = np.where(on_ball[:, None], flat_ball - fr[:, :3, :3] @ ball, h)
        swing = tt >= f.t_off
        if nxt is not None and swing.any():
            s = (tt[swing] - f.t_off) / max(nxt.t_on - f.t_off, 1e-9)
            u = smoothstep((s - f.rise) / (1.0 - f.rise - f.drop))
            a = flat_ball - turned_frames(np.zeros((1, 3)), [yaw_off], [-f.toe_off_pitch])[0, :3, :3] @ ball
            b = np.array([nxt.heel[0], 0.0, nxt.heel[1]])
            if nxt.strike < 0:  # landing toes first: aim the heel so the ball touches down at its place
                nb = b + V.rot_y(nxt.yaw * DEG)[:3, :3] @ ball
                b = nb - turned_frames(np.zeros((1, 3)), [nxt.yaw], [nxt.strike])[0, :3, :3] @ ball
            hs = a + u[:, None] * (b - a)
            hs[:, 1] += (lift if f.lift is None else f.lift) * np.sin(np.pi * np.clip(s, 0.0, 1.0))
            h[swing] = hs
            p[swing] = -f.toe_off_pitch + smoothstep((s - 0.15) / 0.7) * (nxt.strike + f.toe_off_pitch)
            y[swing] = yaw_off + u * (nxt.yaw - yaw_off)
            on_ball[swing] = False
        heel[live], yaw[live], pitch[live], about_ball[live] = h, y, p, on_ball
    frames = turned_frames(heel, yaw, pitch)
    toes = np.where(about_ball & (pitch < 0), -pitch, 0.0)
    # after toe-off the toes straighten over the first part of the swing
    for k, f in enumerate(falls[:-1]):
        nxt = falls[k + 1]
        sw = (t >= f.t_off) & (t < nxt.t_on)
        if sw.any() and np.isfinite(f.t_off):
            s = (t[sw] - f.t_off) / max(nxt.t_on - f.t_off, 1e-9)
            toes[sw] = f.toe_off_pitch * (1.0 - smoothstep(s / 0.35))
            if nxt.strike < 0:
                toes[sw] += -nxt.strike * smoothstep((s - 0.6) / 0.4)
    return frames, toes.clip(0.0, 60.0) * DEG


# --- sessions -----------------------------------------------------------------------------------------------


@dataclass
class BaseStance:
    """The base posture's feet (heel (x, z), yaw) and pelvis ground point, from its key posture."""

    heel: dict[str, tuple[float, float]]
    yaw: dict[str, float]
    ball: dict[str, np.ndarray]  # ball relative to heel, foot frame
    pelvis: np.ndarray  # (x, z)

    @classmethod
    def of(cls, kin: FigureKinematics, key: KeyPosture) -> BaseStance:
        q, root = key.poses[SOLDIER], key.locations[SOLDIER]
        g = kin.site_globals(q, root)
        g0 = kin.site_globals(np.zeros(kin.ndof), np.eye(4))
        heel, yaw, ball = {}, {}, {}
        for s in SIDES:
            h = g[kin.site_names.index(f"{s}_foot.heel")]
            heel[s] = (float(h[0, 3]), float(h[2, 3]))
            yaw[s] = math.degrees(math.atan2(h[0, 2], h[2, 2]))
            ball[s] = (
                g0[kin.site_names.index(f"{s}_foot.ball"), :3, 3]
                - g0[kin.site_names.index(f"{s}_foot.heel"), :3, 3]
            )
        return cls(heel, yaw, ball, np.array([root[0, 3], root[2, 3]]))

    def ball_at(self, side: str) -> np.ndarray:
        """The base ball position (x, z)."""
        h = np.array([self.heel[side][0], 0.0, self.heel[side][1]])
        b = h + V.rot_y(self.yaw[side] * DEG)[:3, :3] @ self.ball[side]
        return b[[0, 2]]

    def track(self, side: str) -> np.ndarray:
        """Heel (x, z) of the foot turned straight about its base ball: where the gait puts this foot."""
        return self.ball_at(side) - self.ball[side][[0, 2]]


@dataclass
class Session:
    """A stretch of locomotion: footfalls, the pelvis's keys, the upper body's keys and the clip cuts.

    ``z_keys``: (time, z, dz/dt) of the pelvis progression (cubic Hermite between keys);
    ``x_keys``: (time, x);
    ``gait_keys``: (time, gait) whose oscillation parameters blend between keys; ``upper_keys``: (time, key
    posture) of the spine, head, arms and rifle carry; ``base_keys``: (time, weight) of the base posture's
    pelvis
    placement (1 at rest, 0 in the gait); ``landings``: (time, foot) of the footfalls that set the step phase.
    """

    falls: dict[str, list[Footfall]]
    cuts: list[tuple[str, float, float]]
    landings: list[tuple[float, str]]
    z_keys: list[tuple[float, float, float]]
    x_keys: list[tuple[float, float]]
    gait_keys: list[tuple[float, Gait]]
    upper_keys: list[tuple[float, str]]
    base_keys: list[tuple[float, float]]
    t_end: float
    # a flying foot whose course changes: its footfalls had it gone on as before, and the time span over which
    # its course turns from the old landing to the new one (so clips meet where the foot is in the air)
    retarget: dict[str, tuple[list[Footfall], float, float]] = field(default_factory=dict)


def _steady(g: Gait, side: str, t_on: float, heel: tuple[float, float]) -> Footfall:
    T = g.step_time
    return Footfall(
        side,
        t_on,
        heel,
        0.0,
        t_on + g.flat * T,
        t_on + g.heel_off * T,
        t_on + g.toe_off * T,
        g.strike,
        g.toe_off_pitch,
        **_swing(g),
    )


class _SwingShape(TypedDict):
    """:class:`Footfall`'s swing-shape keywords, typed for ``**`` unpacking."""

    rise: float
    drop: float


def _swing(g: Gait) -> _SwingShape:
    """A footfall's swing shape (``rise``, ``drop``) in gait ``g``."""
    return {"rise": g.swing_rise, "drop": g.swing_drop}


def _pelvis_z(g: Gait, heel_z: float) -> float:
    """The pelvis's progression coordinate when a foot lands with its heel at ``heel_z``."""
    return heel_z + g.direction * g.reach


def plan_session(gait: Gait, first: str, cycles: int, base: BaseStance) -> Session:
    """A start step (``first`` swings out of the base posture), ``cycles`` cycle steps, an end step.

    The base stance is staggered (feet turned out), the gait's feet point straight: in the start step the
    standing foot first takes a little step (:data:`ADJUST_RISE`...) to its gait place (turned straight
    about its ball), then ``first`` swings; in the end step, once the trailing foot has landed, the last
    foot takes a little step to its base place. A foot on the ground never pivots, so it never scrapes."""
    g = gait
    T, d, L, v = g.step_time, g.direction, g.step_length, g.speed
    other = "right" if first == "left" else "left"
    track = {s: base.track(s) for s in SIDES}
    falls: dict[str, list[Footfall]] = {s: [] for s in SIDES}
    # the standing foot's little step, the first foot's weight-bearing meanwhile
    a_heel = 0.03
    a_off = a_heel + ADJUST_RISE
    a_land = _frames(a_off + ADJUST_SWING)
    t_heel = a_land + 0.05  # the first foot rises as soon as the other has landed
    t_start = _frames(t_heel + 0.85 * g.start_time)
    z0, z1 = float(base.pelvis[1]), _pelvis_z(g, float(track[other][1]) - d * L)
    t_push = max(a_land, t_start - 2.0 * abs(z1 - z0) / v)  # the pelvis sets off
    t_early = max(a_land + 0.1, t_push)  # the standing heel peels off as the pelvis pulls away
    falls[other].append(
        Footfall(
            other,
            -np.inf,
            base.heel[other],
            base.yaw[other],
            -np.inf,
            a_heel,
            a_off,
            0.0,
            ADJUST_PITCH,
            lift=ADJUST_LIFT,
            **_swing(g),
        )
    )
    falls[other].append(
        Footfall(
            other,
            a_land,
            (float(track[other][0]), float(track[other][1])),
            0.0,
            a_land,
            t_start + (g.heel_off - 1.0) * T,
            t_start + (g.toe_off - 1.0) * T,
            0.0,
            g.toe_off_pitch,
            early=(t_early, min(t_start, t_start + (g.toe_off - 1.0) * T)),
            **_swing(g),
        )
    )
    # the first foot rises at its base yaw and turns straight in the air
    falls[first].append(
        Footfall(
            first,
            -np.inf,
            base.heel[first],
            base.yaw[first],
            -np.inf,
            t_heel,
            t_heel + 0.3 * g.start_time,
            0.0,
            g.toe_off_pitch,
            **_swing(g),
        )
    )
    z = float(track[other][1]) - d * L
    falls[first].append(_steady(g, first, t_start, (float(track[first][0]), z)))
    landings = [(t_start - T, other), (t_start, first)]
    cuts = [(f"start_{first[0]}", 0.0, t_start)]
    t, side = t_start, first
    for _ in range(cycles):
        nxt = "right" if side == "left" else "left"
        t, z = _frames(t + T), z - d * L
        falls[nxt].append(_steady(g, nxt, t, (float(track[nxt][0]), z)))
        landings.append((t, nxt))
        cuts.append((f"cycle_{nxt[0]}", t - T, t))
        side = nxt
    # end step: the last foot stays flat while the trailing foot swings to its base place relative to it and
    # lands flat; then the last foot steps (about its ball) to its base place and yaw
    last, trail = side, ("right" if side == "left" else "left")
    lf = falls[last][-1]
    shift = np.array(lf.heel) - track[last]  # how far the whole base stance moved
    t_land = _frames(t + 0.7 * g.end_time)
    e_heel = t_land + 0.02
    e_off = e_heel + ADJUST_RISE
    e_land = _frames(e_off + ADJUST_SWING)
    t_end = _frames(e_land + ADJUST_SETTLE)
    falls[last][-1] = Footfall(
        last,
        lf.t_on,
        lf.heel,
        0.0,
        lf.t_flat,
        e_heel,
        e_off,
        lf.strike,
        ADJUST_PITCH,
        lift=ADJUST_LIFT,
        **_swing(g),
    )
    lh = np.array(base.heel[last]) + shift
    falls[last].append(
        Footfall(last, e_land, (float(lh[0]), float(lh[1])), base.yaw[last], e_land, np.inf, np.inf)
    )
    th = np.array(base.heel[trail]) + shift
    old_trail = [*falls[trail], _steady(g, trail, t + T, (float(track[trail][0]), z - d * L))]
    falls[trail].append(
        Footfall(trail, t_land, (float(th[0]), float(th[1])), base.yaw[trail], t_land, np.inf, np.inf)
    )
    cuts.append((f"end_{trail[0]}", t, t_end))
    # the pelvis: still until it must go, at speed between the first and last footfalls, stopping at the base;
    # leaning over the supporting foot during the little steps
    x_mid = 0.5 * float(track["left"][0] + track["right"][0])
    zl, ze = _pelvis_z(g, lf.heel[1]), float(base.pelvis[1] + shift[1])
    t_stop = min(t + 2.0 * abs(ze - zl) / v, t_land)
    z_keys = [(0.0, z0, 0.0), (t_push, z0, 0.0), (t_start, z1, -d * v), (t, zl, -d * v), (t_stop, ze, 0.0)]
    if t_stop < t_end:
        z_keys.append((t_end, ze, 0.0))
    lean_start = ADJUST_SWAY * (1.0 if first == "right" else -1.0)  # towards the first foot (left is -x)
    lean_end = ADJUST_SWAY * (1.0 if trail == "right" else -1.0)
    bx_end = float(base.pelvis[0] + shift[0])
    x_keys = [
        (0.0, float(base.pelvis[0])),
        (a_off, float(base.pelvis[0]) + lean_start),
        (a_land, float(base.pelvis[0]) + lean_start),
        (t_start, x_mid),
        (t, x_mid),
        (e_heel, bx_end + lean_end),
        (e_land, bx_end + lean_end),
        (t_end, bx_end),
    ]
    return Session(
        falls,
        cuts,
        landings,
        z_keys,
        x_keys,
        [(0.0, g)],
        [(0.0, BASE), (t_start, g.carry), (t, g.carry), (t_end, BASE)],
        [(0.0, 1.0), (t_start, 0.0), (t, 0.0), (t_end, 1.0)],
        t_end,
        {trail: (old_trail, t, t_land)},
    )


def plan_change(a: Gait, b: Gait, base: BaseStance, name: str) -> Session:
    """One step from gait ``a`` (the left foot has just landed) into gait ``b`` (the right foot lands)."""
    track = {s: base.track(s) for s in SIDES}
    xl, xr = float(track["left"][0]), float(track["right"][0])
    z0 = 0.0
    falls: dict[str, list[Footfall]] = {s: [] for s in SIDES}
    falls["right"].append(_steady(a, "right", -a.step_time, (xr, z0 + a.direction * a.step_length)))
    left = _steady(a, "left", 0.0, (xl, z0))
    pz0 = _pelvis_z(a, z0)
    z1 = z0 - b.direction * b.step_length  # the right foot lands one step of ``b`` ahead of the left
    pz1 = _pelvis_z(b, z1)
    v0, v1 = a.speed, b.speed
    dur = _frames(2.0 * abs(pz1 - pz0) / (v0 + v1))
    # the left foot leaves the ground as it would in gait ``b`` (it is mid-swing when the right lands)
    tb = dur - b.step_time
    left = Footfall(
        "left",
        0.0,
        (xl, z0),
        0.0,
        left.t_flat,
        min(left.t_heel, tb + b.heel_off * b.step_time),
        tb + b.toe_off * b.step_time,
        a.strike,
        b.toe_off_pitch,
        **_swing(b),
    )
    falls["left"] += [left, _steady(b, "left", dur + b.step_time, (xl, z1 - b.direction * b.step_length))]
    falls["right"].append(_steady(b, "right", dur, (xr, z1)))
    # had the old gait gone on, the right foot would land here
    old_right = [falls["right"][0], _steady(a, "right", a.step_time, (xr, z0 - a.direction * a.step_length))]
    return Session(
        falls,
        [(name, 0.0, dur)],
        [(-a.step_time, "right"), (0.0, "left"), (dur, "right")],
        [(0.0, pz0, -a.direction * v0), (dur, pz1, -b.direction * v1)],
        [(0.0, 0.5 * (xl + xr)), (dur, 0.5 * (xl + xr))],
        [(0.0, a), (dur, b)],
        [(0.0, a.carry), (dur, b.carry)],
        [(0.0, 0.0), (dur, 0.0)],
        dur,
        {"right": (old_right, 0.0, dur)},
    )


def _hermite(keys: list[tuple[float, float, float]], t: np.ndarray) -> np.ndarray:
    """Piecewise cubic Hermite through (time, value, slope) keys; constant outside."""
    out = np.full(len(t), keys[0][1])
    for (t0, p0, m0), (t1, p1, m1) in itertools.pairwise(keys):
        h = t1 - t0
        sel = (t >= t0) & (t <= t1)
        if h <= 0 or not sel.any():
            continue
        u = (t[sel] - t0) / h
        u2, u3 = u * u, u * u * u
        out[sel] = (
            (2 * u3 - 3 * u2 + 1) * p0
            + (u3 - 2 * u2 + u) * h * m0
            + (-2 * u3 + 3 * u2) * p1
            + (u3 - u2) * h * m1
        )
    out[t > keys[-1][0]] = keys[-1][1]
    return out


def _segment_weights(keys: list[tuple[float, Any]], t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For (time, item) keys: the index of the key before ``t`` and the smoothstep weight to the next one."""
    times = np.array([k[0] for k in keys])
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(keys) - 1)
    j = np.minimum(i + 1, len(keys) - 1)
    span = np.where(j > i, times[j] - times[i], 1.0)
    w = np.where(j > i, smoothstep((t - times[i]) / span), 0.0)
    return i, w


def _gait_param(session: Session, name: str, t: np.ndarray) -> np.ndarray:
    return keyed([(k, getattr(g, name)) for k, g in session.gait_keys], t)


def _phase(session: Session, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Step phase in [0, 1] between footfalls and the sign of the supporting side (+1 left)."""
    times = np.array([w for w, _ in session.landings])
    feet = np.array([1.0 if f == "left" else -1.0 for _, f in session.landings])
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1)
    nxt = np.minimum(k + 1, len(times) - 1)
    step = np.where(nxt > k, times[nxt] - times[k], session.gait_keys[-1][1].step_time)
    return np.clip((t - times[k]) / step, 0.0, 1.0), feet[k]


# --- recording a session ------------------------------------------------------------------------------------


@dataclass
class Recorded:
    """A recorded session: world frames of the soldier and rifle at times ``t``."""

    session: Session
    t: np.ndarray
    poses: np.ndarray
    roots: np.ndarray
    rifles: np.ndarray
    pelvis: np.ndarray  # (n, 2) ground point (x, z) of the progression


_LAST_REPORT: dict[str, ik.SolveReport] = {}


def carried_rifle_goals(
    rkin: FigureKinematics, rifles: np.ndarray, heels: dict[str, np.ndarray]
) -> list[ik.Goal]:
    """IK goals of a standing soldier on his feet with the rifle in his hands: palm centres on the rifle
    (position first, then the hold's orientation) and each heel frame on its track."""
    goals: list[ik.Goal] = []
    for s in ("right", "left"):
        tg = palm_targets(rkin, rifles, s)
        goals.append(ik.Goal(f"{s}_palm.palmcenter", tg[:, :3, 3], None, 1.0, 3, arm(s)))
        goals.append(
            ik.Goal(f"{s}_palm.palmcenter", None, tg[:, :3, :3], 1.0, 1, arm(s), orientation_weight=8.0)
        )
        goals.append(ik.Goal(f"{s}_foot.heel", heels[s][:, :3, 3], heels[s][:, :3, :3], 1.0, 2, leg(s)))
    return goals


def record_session(
    session: Session,
    kin: FigureKinematics,
    rkin: FigureKinematics,
    keys: dict[str, KeyPosture],
    tag: str = "",
) -> Recorded:
    """Every frame of a session: pelvis, feet, upper body, then IK (see the module docstring)."""
    base_key = keys[BASE]
    base = BaseStance.of(kin, base_key)
    n = round(session.t_end * FPS) + 1
    t = np.arange(n) / FPS
    z = _hermite(session.z_keys, t)
    x = keyed(session.x_keys, t)
    beta = keyed(session.base_keys, t)
    phase, side = _phase(session, t)
    P = {
        k: _gait_param(session, k, t)
        for k in ("height", "bob", "sway", "turn", "lean", "low_at", "direction", "lift")
    }
    ph = np.clip(phase, 0.0, 1.0)
    bob = P["height"] - P["bob"] * np.cos(2.0 * np.pi * (phase - P["low_at"]))
    sway = -P["sway"] * side * np.sin(np.pi * ph)  # over the supporting foot (left is -x)
    turn = -P["turn"] * side * P["direction"] * np.cos(np.pi * ph)
    base_root = base_key.locations[SOLDIER]
    gait_rot = turned_frames(np.zeros((n, 3)), turn, -P["lean"])
    roots = np.stack([slerp_frames(gait_rot[i], base_root, np.array([beta[i]]))[0] for i in range(n)])
    roots[:, 0, 3] = x + (1.0 - beta) * sway
    roots[:, 1, 3] = beta * base_root[1, 3] + (1.0 - beta) * bob
    roots[:, 2, 3] = z
    # the feet
    heels, toes = {}, {}
    lift = float(np.max(P["lift"]))
    for s in SIDES:
        heels[s], toes[s] = foot_track(base.ball[s], session.falls[s], t, lift)
        old = session.retarget.get(s)
        if old is not None:  # blend from the course to the old landing into the new one
            h0, t0 = foot_track(base.ball[s], old[0], t, lift)
            u = smoothstep((t - old[1]) / max(old[2] - old[1], 1e-9))
            heels[s] = np.stack(
                [slerp_frames(a, b, np.array([w]))[0] for a, b, w in zip(h0, heels[s], u, strict=True)]
            )
            toes[s] = t0 + u * (toes[s] - t0)
    # the upper body's rest pose and the rifle's carry, blended between the keys
    i, w = _segment_weights(session.upper_keys, t)
    names = [k for _, k in session.upper_keys]
    qk = np.stack([keys[nm].poses[SOLDIER] for nm in names])
    ck = np.stack([carry_of(kin, keys[nm]) for nm in names])
    j = np.minimum(i + 1, len(names) - 1)
    rest = qk[i] + w[:, None] * (qk[j] - qk[i])
    carries = np.stack(
        [slerp_frames(ck[a], ck[b], np.array([u]))[0] for a, b, u in zip(i, j, w, strict=True)]
    )
    twist = spine_angles(kin, 0.0, 0.0, 1.0).reshape(-1)
    idx = np.concatenate(
        [np.arange(kin.dof_slices[jn].start, kin.dof_slices[jn].stop) for jn in PARTS["spine"][1:]]
    )
    rest[:, idx] -= ((1.0 - beta) * turn)[:, None] * twist[None]
    for s in SIDES:
        rest[:, kin.dof_slices[f"{s}_toes"]] = toes[s][:, None]
        k = kin.dof_slices[f"{s}_knee"]
        rest[:, k] = np.maximum(rest[:, k], 12.0 * DEG)
    # IK: palms on the rifle (carried by the rest pose's upper torso), heels on their tracks, eyes ahead
    rifles = carrier_globals(kin, rest, roots) @ carries
    goals = carried_rifle_goals(rkin, rifles, heels)
    goals.append(ik.Goal("bottom_head.sight", None, np.eye(3), 1.0, 1, ("neck", "head")))
    poses, report = ik.solve(kin, rest, goals, roots, iterations=60, rest_pose=rest, rest_gain=0.1)
    _LAST_REPORT[tag] = report
    rifles = carrier_globals(kin, poses, roots) @ carries
    if session.base_keys[0][1] == 1.0:  # a start: the first frame is the base posture exactly
        poses[0], roots[0], rifles[0] = base_key.poses[SOLDIER], base_root, base_key.locations[RIFLE]
    if session.base_keys[-1][1] == 1.0:  # an end: the last frame is the base posture, moved with the walk
        move = np.eye(4)
        move[0, 3], move[2, 3] = x[-1] - base.pelvis[0], z[-1] - base.pelvis[1]
        poses[-1], roots[-1], rifles[-1] = (
            base_key.poses[SOLDIER],
            move @ base_root,
            move @ base_key.locations[RIFLE],
        )
    return Recorded(session, t, poses, roots, rifles, np.stack([x, z], axis=1))


def cut(
    rec: Recorded, name: str, t0: float, t1: float, base_offset: np.ndarray
) -> tuple[ClipFrames, float, float]:
    """One clip of a session in its local frame; returns (frames, stride length cm, ground speed cm/s)."""
    i0, i1 = round(t0 * FPS), round(t1 * FPS)
    sl = slice(i0, i1 + 1)
    start, end = rec.pelvis[i0], rec.pelvis[i1]
    travel = end - start
    u = (rec.t[sl] - rec.t[i0]) / max(rec.t[i1] - rec.t[i0], 1e-9)
    shift = np.zeros((i1 - i0 + 1, 3))
    shift[:, 0] = start[0] - base_offset[0] + u * travel[0]
    shift[:, 2] = start[1] - base_offset[1] + u * travel[1]
    roots = rec.roots[sl].copy()
    rifles = rec.rifles[sl].copy()
    roots[:, :3, 3] -= shift
    rifles[:, :3, 3] -= shift
    dist = float(np.hypot(*travel))
    return ClipFrames(rec.poses[sl].copy(), roots, rifles, FPS), dist, dist / (t1 - t0)


# --- the library's locomotion clips -------------------------------------------------------------------------


LOCO_NODES: tuple[str, ...] = (BASE, "WALK_L", "WALK_R", "BWALK_L", "BWALK_R", "RUN_L", "RUN_R")


def loco_arcs() -> list[tuple[str, str, str, bool]]:
    """(from, to, clip, forward) of the locomotion graph; node ``WALK_L`` is 'walking, the left foot has just
    landed' (the right foot swings next)."""
    out: list[tuple[str, str, str, bool]] = []
    for g, node in (("walk", "WALK"), ("bwalk", "BWALK"), ("run", "RUN")):
        out += [
            (BASE, f"{node}_L", f"{g}_start_l", True),
            (BASE, f"{node}_R", f"{g}_start_r", True),
            (f"{node}_L", f"{node}_R", f"{g}_cycle_r", True),
            (f"{node}_R", f"{node}_L", f"{g}_cycle_l", True),
            (f"{node}_L", BASE, f"{g}_end_r", True),
            (f"{node}_R", BASE, f"{g}_end_l", True),
        ]
    out += [("WALK_L", "RUN_R", "walk2run", True), ("RUN_L", "WALK_R", "run2walk", True)]
    return out


_SESSIONS: dict[tuple[str, int], dict[str, tuple[ClipFrames, float, float]]] = {}


def _record_all(ctx: Any) -> dict[str, tuple[ClipFrames, float, float]]:
    kin, rkin = FigureKinematics(ctx.soldier), FigureKinematics(ctx.rifle)
    base = BaseStance.of(kin, ctx.keys[BASE])
    out: dict[str, tuple[ClipFrames, float, float]] = {}
    plans: list[tuple[str, Session, tuple[str, ...]]] = []
    for gait in (WALK, BWALK, RUN):
        plans.append(
            (gait.name, plan_session(gait, "left", 2, base), ("start_l", "cycle_r", "cycle_l", "end_r"))
        )
        plans.append((gait.name, plan_session(gait, "right", 0, base), ("start_r", "end_l")))
    plans.append(("", plan_change(WALK, RUN, base, "walk2run"), ("walk2run",)))
    plans.append(("", plan_change(RUN, WALK, base, "run2walk"), ("run2walk",)))
    for prefix, session, keep in plans:
        rec = record_session(session, kin, rkin, ctx.keys, prefix or session.cuts[0][0])
        for name, t0, t1 in session.cuts:
            if name in keep:
                full = f"{prefix}_{name}" if prefix else name
                out[full] = cut(rec, name, t0, t1, base.pelvis)
    return out


def session_clips(ctx: Any) -> dict[str, tuple[ClipFrames, float, float]]:
    """Every locomotion clip (recorded once per build context)."""
    key = ("all", id(ctx))
    if key not in _SESSIONS:
        _SESSIONS.clear()
        _SESSIONS[key] = _record_all(ctx)
    return _SESSIONS[key]


LOCO_CLIPS: tuple[str, ...] = (
    *tuple(
        f"{g}_{c}"
        for g in ("walk", "bwalk", "run")
        for c in ("start_l", "start_r", "cycle_l", "cycle_r", "end_l", "end_r")
    ),
    "walk2run",
    "run2walk",
)


def locomotion_clips() -> dict[str, Callable[[Any], tuple[ClipFrames, float, float]]]:
    """Clip name -> generator taking the build context (all sessions are recorded on first use)."""
    return {name: _session_clip(name) for name in LOCO_CLIPS}


def _session_clip(name: str) -> Callable[[Any], tuple[ClipFrames, float, float]]:
    """The generator of session clip ``name`` (a closure per name, not one late-bound loop variable)."""
    return lambda ctx: session_clips(ctx)[name]


__all__ = [
    "BWALK",
    "GAITS",
    "LOCO_NODES",
    "RUN",
    "WALK",
    "BaseStance",
    "Footfall",
    "Gait",
    "foot_track",
    "loco_arcs",
    "locomotion_clips",
    "plan_session",
    "quaternion",
    "record_session",
    "rigid_inverse",
]
