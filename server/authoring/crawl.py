"""Crawling (seed 002, 3.3): the crawl on forearms and knees, a start clip and one full cycle.

The seed's crawl was made by hand from two animations: one from the base (prone) posture into the cyclic
state, and one complete cycle; ending a crawl plays the start backwards. The base here is the graph's
``CRAWL`` posture (on forearms and knees, toes dug into the ground behind, rifle cradled in both hands).

Each leg touches the ground at the kneecap (``lower_leg.knee``) and the tip of the toes (``toes.distal``).
Both stay planted in the world while the body glides forwards over them; once per cycle of ``CYCLE``
seconds each leg (the right half a cycle after the left) rises clear of the ground (``LIFT``), is drawn
forwards ``2 * STRIDE`` cm and put down again, so nothing drags. The start clip keeps the left leg planted
while the body gets going and moves the right leg the half stride that puts both where the cycle starts
with them. With both knees planted the pelvis has to follow them (the thigh cannot stretch), so it may
rise, pitch, yaw and roll (``PELVIS_DOFS``, held back towards its glide by ``PELVIS_HOLD``), and the spine
keeps the chest on its own smooth glide. The ankles keep the posture's angles (they sit at their limits
there; letting the solver move them flipped the foot between the two limits): the hips, knees and toes
place the toe tips. The upper body keeps the ``CRAWL`` posture with the rifle cradled in both hands (so the
palms never leave it); the forearms slide with the chest rather than step — a simplification: IK on the
arms with the hands held on a rigid rifle flipped between elbow solutions. Every frame is one batched IK
solve from the posture. Like the gait clips the clips are local motion (the body's glide removed as a ramp,
``stride_length`` / ``ground_speed`` recorded).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from server.authoring import ik
from server.authoring.motion import KeyPosture
from server.authoring.postures import RIFLE, SOLDIER, SPINE, leg
from server.authoring.transitions import CARRIER, ClipFrames, carrier_globals, carry_of, lift_off_ground
from server.peabody import values as V
from server.peabody.fk import FigureKinematics

FPS = 60
BASE = "CRAWL"
CYCLE = 1.2  # seconds per full cycle
STRIDE = 6.0  # cm the body glides per half cycle
START = 0.6  # seconds of the start clip
SWING = 0.45  # seconds a leg takes to move forwards
LIFT = {"knee": 3.5, "toes": 4.5}  # cm a contact rises while it moves (clear of the 2.5 cm contact band)
ROLL = 2.0  # degrees the chest rolls towards the planted side
SWAY = 1.0  # cm the chest sways sideways
PELVIS_DOFS = ("ty", "rx", "ry", "rz")  # the pelvis rises, pitches, yaws and rolls over the planted knees
PELVIS_HOLD = 0.4  # weight of the pull back towards the pelvis's glide (more: the knees slide instead)
CHEST_HOLD = 0.1  # weight of the chest's glide (more: the spine's bend gets jerky, and DI's slaving with it)
# contact sites of one leg: the kneecap and the tip of the toes (dug into the ground behind)
LEG_SITES = {"knee": "{s}_lower_leg.knee", "toes": "{s}_toes.distal"}
CRAWL_NODES: tuple[str, ...] = ("CRAWL", "CRAWLING")


def crawl_arcs() -> list[tuple[str, str, str, bool]]:
    """(from, to, clip, forward) of the crawl graph; ``CRAWLING`` is the cyclic state."""
    return [
        ("CRAWL", "CRAWLING", "crawl_start", True),
        ("CRAWLING", "CRAWLING", "crawl_cycle", True),
        ("CRAWLING", "CRAWL", "crawl_start", False),
    ]


def _smooth(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _speed() -> float:
    return 2.0 * STRIDE / CYCLE


def body_travel(t: np.ndarray) -> np.ndarray:
    """The body's glide (cm along +Z, so negative = forwards) at time ``t``: still at first, reaching the
    cycle speed when the cycle starts (a Hermite ease that ends with the cycle's slope), then steady."""
    v = _speed()
    d_start = 0.5 * v * START
    u = np.clip(t / START, 0.0, 1.0)
    return np.where(t <= START, -d_start * (2.0 * u**3 - u**4), -d_start - v * (t - START))


def _first_swing() -> float:
    """Cycle time the left leg starts to move (the right moves half a cycle later): the time that puts the
    left knee, planted through the whole start clip, exactly where the cycle starts with it."""
    v = _speed()
    half = 0.5 * v * (CYCLE - SWING)
    return CYCLE - SWING - (half - float(body_travel(np.array(START)))) / v


def swings(side: str, t_end: float) -> list[tuple[float, float]]:
    """(start time, cm forwards) of every move of one leg up to ``t_end``.

    In the cycle each leg moves ``2 * STRIDE`` once, the left at :func:`_first_swing`, the right half a
    cycle later; between its moves a leg stays planted while the body glides over it. In the start clip the
    body glides ``-body_travel(START)`` cm while the left leg stays planted (its cycle timing is chosen so
    that this is exactly where the cycle wants it), and the right leg makes the one shorter move that puts it
    where the cycle starts with it: every contact of the start clip's last frame is the cycle's first.
    """
    v = _speed()
    a = _first_swing() + (0.0 if side == "left" else 0.5 * CYCLE)
    if a < 0.0 or a + SWING > CYCLE:
        raise ValueError("a leg's move must fit in the cycle")
    # where the contact is relative to the body (0 = where the CRAWL posture has it) at the cycle's start:
    # in stance since (a + SWING - CYCLE), from half a stance's glide ahead of the posture's place
    half = 0.5 * v * (CYCLE - SWING)
    rel = -half + v * (CYCLE - a - SWING)
    out: list[tuple[float, float]] = []
    first = -(float(body_travel(np.array(START))) + rel)  # how far the start clip must move it
    if abs(first) > 1e-6:
        t0 = START + a - CYCLE  # so that it lands when its stance of the cycle begins
        if t0 < 0.0 or first < 0.0:
            raise ValueError("the start clip cannot put this leg where the cycle starts")
        out.append((t0, first))
    k = 0
    while START + a + k * CYCLE < t_end:
        out.append((START + a + k * CYCLE, 2.0 * STRIDE))
        k += 1
    return out


def _progress(s: np.ndarray) -> np.ndarray:
    """How far along its path a moving contact is (0..1) at ``s`` (0..1) of its move: it rises first and
    travels while clear of the ground."""
    return _smooth((s - 0.12) / 0.76)


def _rise(s: np.ndarray) -> np.ndarray:
    """Height (fraction of the lift) of a moving contact at ``s`` of its move: up, across, down."""
    inside = (s > 0.0) & (s < 1.0)
    return np.where(inside, np.minimum(_smooth(s / 0.3), _smooth((1.0 - s) / 0.3)), 0.0)


def contact_track(p0: np.ndarray, t: np.ndarray, moves: list[tuple[float, float]], lift: float) -> np.ndarray:
    """World track ``(n, 3)`` of a contact that starts at ``p0``: planted, except during its moves."""
    track = np.tile(p0, (len(t), 1))
    for t0, dist in moves:
        s = (t - t0) / SWING
        track[:, 2] -= dist * _progress(s)
        track[:, 1] += lift * _rise(s)
    return track


def record_crawl(kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture) -> tuple[np.ndarray, ...]:
    """Frames of the start clip followed by one cycle: (t, poses, roots, rifles, progression z)."""
    n_start = round(START * FPS)
    n_cycle = round(CYCLE * FPS)
    n = n_start + n_cycle + 1
    t = np.arange(n) / FPS
    tc = t - START  # cycle time (negative during the start)
    q0, root0, rifle0 = key.poses[SOLDIER], key.locations[SOLDIER], key.locations[RIFLE]
    z = body_travel(t)
    w = _smooth(t / START)  # how far into the cyclic state
    g0 = kin.site_globals(q0, root0)
    roots = np.broadcast_to(root0, (n, 4, 4)).copy()
    roots[:, 2, 3] += z
    # the chest glides with the body, rolling a little with the alternating legs
    chest0 = kin.segment_globals(q0, root0)[kin.segment_names.index(CARRIER)]
    phase = 2.0 * np.pi * (tc - _first_swing() - 0.5 * SWING) / CYCLE
    roll = w * ROLL * np.sin(phase) * np.pi / 180.0
    chest = np.broadcast_to(chest0, (n, 4, 4)).copy()
    chest[:, :3, :3] = np.stack([V.rot_z(r)[:3, :3] for r in roll]) @ chest0[:3, :3]
    chest[:, 2, 3] += z
    chest[:, 0, 3] += w * SWAY * np.sin(phase)
    goals: list[ik.Goal] = [
        ik.Goal(
            f"{CARRIER}.proximal",
            chest[:, :3, 3],
            chest[:, :3, :3],
            CHEST_HOLD,
            1,
            SPINE,
            orientation_weight=40.0,
        )
    ]
    # the pelvis is free to follow the planted knees, but held back towards its glide (moving it is
    # cheap for the solver, and a pelvis that rolls to lift the moving leg twists the planted one)
    goals.append(ik.Goal(kin.root_name, roots[:, :3, 3], roots[:, :3, :3], PELVIS_HOLD, 1, ()))
    for side in ("left", "right"):
        moves = swings(side, float(t[-1]))
        for part, fmt in LEG_SITES.items():
            site = fmt.format(s=side)
            track = contact_track(g0[kin.site_names.index(site), :3, 3], t, moves, LIFT[part])
            chain = leg(side) if part == "knee" else (f"{side}_hip", f"{side}_knee", f"{side}_toes")
            goals.append(ik.Goal(site, track, None, 1.0, 1, chain))
    rest = np.broadcast_to(q0, (n, kin.ndof)).copy()
    poses, report = ik.solve(
        kin, rest, goals, roots, iterations=80, rest_pose=rest, rest_gain=0.1, root_dofs=PELVIS_DOFS
    )
    roots = report.root_location
    # the upper body keeps the CRAWL posture, the rifle cradled in it (arms and rifle move with the chest)
    rifles = carrier_globals(kin, poses, roots) @ carry_of(kin, key)
    poses[0], roots[0], rifles[0] = q0, root0, rifle0
    lift_off_ground(kin, poses, roots, rifles)
    # the cycle's last frame is its first, one cycle further on (pose, pelvis and rifle)
    poses[-1] = poses[n_start]
    for frames in (roots, rifles):
        frames[-1] = frames[n_start]
        frames[-1, 2, 3] += z[-1] - z[n_start]
    return t, poses, roots, rifles, z


def _cut(
    t: np.ndarray, poses: np.ndarray, roots: np.ndarray, rifles: np.ndarray, z: np.ndarray, i0: int, i1: int
) -> tuple[ClipFrames, float, float]:
    sl = slice(i0, i1 + 1)
    travel = z[i1] - z[i0]
    u = (t[sl] - t[i0]) / (t[i1] - t[i0])
    r, f = roots[sl].copy(), rifles[sl].copy()
    shift = z[i0] + u * travel
    r[:, 2, 3] -= shift
    f[:, 2, 3] -= shift
    dist = abs(float(travel))
    return ClipFrames(poses[sl].copy(), r, f, FPS), dist, dist / (t[i1] - t[i0])


_CACHE: dict[int, dict[str, tuple[ClipFrames, float, float]]] = {}


def _record(ctx: Any) -> dict[str, tuple[ClipFrames, float, float]]:
    if id(ctx) not in _CACHE:
        _CACHE.clear()
        kin, rkin = FigureKinematics(ctx.soldier), FigureKinematics(ctx.rifle)
        t, poses, roots, rifles, z = record_crawl(kin, rkin, ctx.keys[BASE])
        ns = round(START * FPS)
        _CACHE[id(ctx)] = {
            "crawl_start": _cut(t, poses, roots, rifles, z, 0, ns),
            "crawl_cycle": _cut(t, poses, roots, rifles, z, ns, len(t) - 1),
        }
    return _CACHE[id(ctx)]


def crawl_clips() -> dict[str, Callable[[Any], tuple[ClipFrames, float, float]]]:
    """Clip name -> generator taking the build context."""
    return {name: (lambda ctx, name=name: _record(ctx)[name]) for name in ("crawl_start", "crawl_cycle")}
