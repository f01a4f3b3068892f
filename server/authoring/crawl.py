"""Crawling (seed 002, 3.3): the high crawl on forearms and knees, a start clip and one full cycle.

The seed's crawl was made by hand from two animations: one from the base (prone) posture into the cyclic
state, and one complete cycle; ending a crawl plays the start backwards. The base here is the graph's
``CRAWL`` posture (on forearms and knees, rifle cradled in both hands).

Four contacts carry the body: the elbows (``upper_arm.distal``) and the knees (``lower_leg.knee``, the ball
of the foot dragging behind). In one cycle of ``CYCLE`` seconds the left knee and then the right knee are
drawn up, each by ``2 * STRIDE`` cm along a low arc while the other stays planted and the body glides forwards
``2 * STRIDE`` cm on its forearms. The upper body keeps the ``CRAWL`` posture with the rifle cradled in both
hands (so the palms never leave it); the forearms slide rather than step — a simplification: IK on the
arms with the hands held on a rigid rifle flipped between elbow solutions. IK (one batched solve)
and the contacts on their tracks. Like the gait clips the clips are local motion (the body's glide removed
as a ramp, ``stride_length`` / ``ground_speed`` recorded).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from server.authoring import ik
from server.authoring.motion import KeyPosture
from server.authoring.postures import RIFLE, SOLDIER, leg
from server.authoring.transitions import ClipFrames, carrier_globals, carry_of, lift_off_ground
from server.peabody import values as V
from server.peabody.fk import FigureKinematics

FPS = 60
BASE = "CRAWL"
CYCLE = 1.6  # seconds per full cycle
STRIDE = 10.0  # cm the body glides per half cycle
START = 0.8  # seconds of the start clip
LIFT = 4.0  # cm a contact lifts while it moves
SWING = 0.5  # seconds a contact takes to move
# contact: (site, chain, start of its move in the cycle, seconds)
CONTACTS: dict[str, tuple[str, tuple[str, ...], float]] = {
    "right_elbow": ("right_upper_arm.distal", ("right_clavicle", "right_shoulder"), 0.0),
    "left_elbow": ("left_upper_arm.distal", ("left_clavicle", "left_shoulder"), 0.0),
    "left_knee": ("left_lower_leg.knee", leg("left"), 0.55),
    "right_knee": ("right_lower_leg.knee", leg("right"), 1.05),
}
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


def _cycle_offset(t: np.ndarray, t_move: float) -> np.ndarray:
    """How far (cm, along the heading) a contact has advanced at time ``t`` of the steady cycle, relative to
    where it would be if it glided with the body: a sawtooth of amplitude ``STRIDE``, zero mean."""
    v = _speed()
    u = ((t - t_move) % CYCLE) / CYCLE  # 0 at the start of its move
    moved = 2.0 * STRIDE * _smooth(((t - t_move) % CYCLE) / SWING)  # world advance within this cycle
    rel = moved - v * u * CYCLE  # relative to the body
    return rel - np.mean(
        2.0 * STRIDE * _smooth(np.linspace(0, CYCLE, 400) / SWING) - v * np.linspace(0, CYCLE, 400)
    )


def _lift(t: np.ndarray, t_move: float) -> np.ndarray:
    s = ((t - t_move) % CYCLE) / SWING
    return np.where(s < 1.0, LIFT * np.sin(np.pi * np.clip(s, 0, 1)), 0.0)


def record_crawl(kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture) -> tuple[np.ndarray, ...]:
    """Frames of the start clip followed by one cycle: (t, poses, roots, rifles, progression z)."""
    v = _speed()
    n_start = round(START * FPS)
    n_cycle = round(CYCLE * FPS)
    n = n_start + n_cycle + 1
    t = np.arange(n) / FPS
    tc = t - START  # cycle time (negative during the start)
    q0, root0, rifle0 = key.poses[SOLDIER], key.locations[SOLDIER], key.locations[RIFLE]
    # the body glides: still at first, reaching the cycle speed when the cycle starts (Hermite)
    d_start = 0.5 * v * START
    u = np.clip(t / START, 0.0, 1.0)
    z_start = -(d_start * (u**3 - 0.5 * u**4) * 2.0)
    z = np.where(t <= START, z_start, -d_start - v * tc)
    w = _smooth(t / START)  # how far into the cyclic state
    g0 = kin.site_globals(q0, root0)
    roots = np.broadcast_to(root0, (n, 4, 4)).copy()
    roots[:, 2, 3] += z
    # a little roll and sway with the alternating limbs
    phase = 2.0 * np.pi * tc / CYCLE
    roll = w * 4.0 * np.sin(phase)
    roots[:, :3, :3] = np.einsum(
        "ij,njk->nik", root0[:3, :3], np.stack([V.rot_y(r * np.pi / 180)[:3, :3] for r in roll])
    )
    roots[:, 0, 3] += w * 1.5 * np.sin(phase)
    goals: list[ik.Goal] = []
    advance = {}
    for name, (site, chain, t_move) in CONTACTS.items():
        p0 = g0[kin.site_names.index(site), :3, 3]
        off = w * _cycle_offset(tc, t_move)
        advance[name] = off
        track = np.tile(p0, (n, 1))
        track[:, 2] += z - off
        track[:, 1] += w * _lift(tc, t_move)
        if name.endswith("elbow"):  # the forearms move with the rifle they cradle: no goal of their own
            continue
        goals.append(ik.Goal(site, track, None, 1.0, 2, chain))
        if name.endswith("knee"):  # the foot drags behind its knee
            side = name.split("_")[0]
            b0 = g0[kin.site_names.index(f"{side}_foot.ball"), :3, 3]
            bt = np.tile(b0, (n, 1))
            bt[:, 2] += z - off
            bt[:, 1] += w * _lift(tc, t_move) * 0.5
            goals.append(ik.Goal(f"{side}_foot.ball", bt, None, 0.5, 2, leg(side)))
    rest = np.broadcast_to(q0, (n, kin.ndof)).copy()
    poses, _ = ik.solve(kin, rest, goals, roots, iterations=60, rest_pose=rest, rest_gain=0.1)
    # the upper body keeps the CRAWL posture, the rifle cradled in it (arms and rifle move with the torso)
    rifles = carrier_globals(kin, poses, roots) @ carry_of(kin, key)
    poses[0], roots[0], rifles[0] = q0, root0, rifle0
    lift_off_ground(kin, poses, roots, rifles)
    # the cycle's last frame is its first, one cycle further on
    poses[-1] = poses[n_start]
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
