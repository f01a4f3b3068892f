"""A prone death's legs roll out on the ground, the pelvis rolling with each (issue 14).

The ragdoll leaves a prone death (prstow2dead, prfire2dead) on his toes, heels 20.2 cm up, and the limp
settle (:mod:`authoring.dead_legs`) cannot lay them: with the pelvis held where it lies, the hip must turn
out ~34 deg more and the thigh's nodes on the ground, 13 cm from the hip joint, slide 3.5-5 cm (the
check's contact_slide limit is 3; branch ``proneheels-s14``), and lifting the thigh clear takes 5 deg or
more of hip extension: the lower legs rose 13-17 cm as his chest came down, a kick (``proneheels-s13``).

A limp body's pelvis rolls with a leg turning out. So here each leg in turn (:data:`ORDER`, over
:data:`LEG_SECONDS`, from the physics' last frame: the first while his chest comes down, the second done
within the check's ``limb_rest_lag_s`` of the trunk) turns out to a shape that lays its heel low
(:data:`TURNED_DEG`, :data:`HIP_TURNS_DEG`) while the pelvis rolls a few degrees about the body's long axis
through its lowest node on the other side and back: that hip rises, and the thigh turns over the ground
instead of dragging across it. The lumbar spine takes the roll back, and the other leg's hip, knee and ankle
keep its foot where it lies (:func:`_kept`): the chest, arms, head and the other foot stay put (rolled as one
piece, the other leg's toes went 1.4 cm into the ground). Per leg, the roll, the hip's lead and the shape are
the best of a small grid (:func:`rolled_leg`): the lowest heel, nothing on the ground sliding more than
:data:`SLIDE_CM`, nothing going into it, the foot within the check's ``lying_feet_up_cm`` (less
:data:`FOOT_UP_MARGIN`) and, once the trunk is down, no leg part rising more than :data:`RISE_CM`. Soldier
DEAD@prstow heels 20.2 -> 11.8 cm, DEAD@prfire 20.2 -> 11.5.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from authoring import dead_settle as ds
from authoring.body_parts import contact_runs
from authoring.quality import CONTACT_HEIGHT_CM, THRESHOLDS
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.rotations import axis_angle
from server.soldier.blend import smoothstep

ORDER = ("left", "right")  # the legs roll out one after the other: the pelvis rolls one way for each
LEG_SECONDS = 0.5  # s, each leg (the second is done within the check's limb_rest_lag_s of the trunk)
# degrees: the knee, the ankle's pointing and its second angle a turned-out leg goes to, its hip turned out
# by one of HIP_TURNS_DEG (soldier.fig's passive range: hip turned out 60, ankle pointed 60, foot everted
# 30; turned out 60 prstow2dead's right heel lay 12.4 cm up, 57: 11.8, prfire2dead's 10.8 and 11.8); its
# hip's first two angles move by one of HIP_MOVES and its toes stay
TURNED_DEG = (8.0, -60.0, 30.0)
HIP_TURNS_DEG = (-57.0, -60.0)
HIP_MOVES = ((-10.0, -1.0), (-10.0, 0.0), (-10.0, 1.0), (0.0, -1.0), (0.0, 0.0), (0.0, 1.0))
ROLLS_DEG = (3.0, 4.0, 5.0, 6.0, 8.0)  # the pelvis's roll tried, least first
LEADS = (0.5, 0.75)  # of a leg's time: its hip's turn is done by then (the knee and foot with the whole)
SPANS = (0.3, 0.45)  # ... the pelvis rolls over this much of it, and back over as much at its end
COMPS = (0.0, 0.5)  # the hip flexes this much of the roll with it (the thigh kept nearer the ground)
# cm: a leg node on the ground moves at most this far while on it (the check: 3, the fall's own slide
# under it)
SLIDE_CM = 1.9
FOOT_UP_MARGIN = 3.0  # cm under the check's lying_feet_up_cm: the foot over the pelvis
RISE_CM = 2.5  # cm: once the trunk is down a leg part's lowest node rises at most this (the check: 3)
DEEP_CM = 0.05  # cm: into the ground, at most
LUMBAR = ("waist", "vl5", "vl4", "vl3", "vl2", "vl1")  # take the pelvis's roll back: the chest stays
# ... and the other leg's hip, knee and ankle keep its foot where it lies
OTHER_LEG = ("hip", "knee", "ankle")
LUMBAR_ITERATIONS = 8
ROT_CM = 30.0  # cm per radian: the chest's turn weighed against its move
LUMBAR_DAMPING = 1e-2


@dataclass(frozen=True)
class Roll:
    """One leg's way out: its angles and the pelvis's roll (rad) at each frame, about ``pivot`` along
    ``axis``; its heel at the end (cm, the check's ``rest_foot_cm``)."""

    side: str
    path: np.ndarray
    roll: np.ndarray
    pivot: np.ndarray
    axis: np.ndarray
    heel: float


def _rolled_roots(root: np.ndarray, pivot: np.ndarray, axis: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """``root`` turned by ``roll`` (rad, each) about the line through ``pivot`` along ``axis``."""
    r = axis_angle(np.repeat(axis[None], len(roll), axis=0), roll)
    m = np.repeat(np.eye(4)[None], len(roll), axis=0)
    m[:, :3, :3] = r
    m[:, :3, 3] = pivot - r @ pivot
    return m @ root


def _pivot(body: ds._Body, side: str) -> tuple[np.ndarray, np.ndarray]:
    """The pelvis's lowest node on the other side and the body's long axis (horizontal, unit), oriented so
    that a positive roll raises the ``side`` hip."""
    kin = body.kin
    g = kin.segment_globals(body.q, body.root)
    waist = g[kin.segment_names.index("lower_torso"), :3, 3]
    chest = g[kin.segment_names.index("t7"), :3, 3]
    other = "right" if side == "left" else "left"
    hip = g[kin.segment_names.index(f"{side}_upper_leg"), :3, 3]
    far = g[kin.segment_names.index(f"{other}_upper_leg"), :3, 3]
    pelvis = body.points[body.parts == "pelvis"]
    there = pelvis[(pelvis - waist) @ (far - waist) > 0.0]
    pivot = there[int(np.argmin(there[:, 1]))]
    axis = (chest - waist) * np.array([1.0, 0.0, 1.0])
    axis /= np.linalg.norm(axis)
    if np.cross(axis, hip - pivot)[1] < 0.0:  # turning about +axis moves hip - pivot by axis x (hip - pivot)
        axis = -axis
    return pivot, axis


def _bump(t: np.ndarray, span: float) -> np.ndarray:
    """0 -> 1 over the first ``span`` of ``t``, held, back to 0 over the last."""
    return smoothstep(np.minimum(t, 1.0 - t) / span)


def rolled_leg(body: ds._Body, side: str, n: int, judged_from: int) -> Roll | None:
    """The ``side`` leg's way out over ``n`` frames (:data:`LEG_SECONDS`) that lays its heel lowest, its
    pelvis rolling (see the module docstring); a rise is judged from frame ``judged_from`` on (the trunk
    down). None where no way keeps to the limits or lays the heel lower than it lies."""
    kin, leg = body.kin, ds._Leg(body, side)
    pivot, axis = _pivot(body, side)
    parts = body.parts[leg.nodes]
    pelvis = body.parts == "pelvis"
    t = np.arange(1, n + 1) / n
    up_limit = THRESHOLDS["lying_feet_up_cm"] - FOOT_UP_MARGIN
    lo, hi = kin.lower[leg.idx], kin.upper[leg.idx]
    best: tuple[tuple[float, float, float], Roll] | None = None
    start_heel = leg._shape(leg.x0[None], 1.0)[1][0]
    start_heel = max(float(start_heel), float(leg.start[leg.foot, 1].min()))
    grid = itertools.product(HIP_MOVES, HIP_TURNS_DEG, ROLLS_DEG, LEADS, SPANS, COMPS)
    for move, hip_turn, phi, lead, span, comp in grid:
        target = leg.x0.copy()
        target[:2] += np.radians(move)
        target[2:6] = np.radians((hip_turn, *TURNED_DEG))
        target = np.clip(target, lo, hi)
        turn = np.repeat(smoothstep(t)[:, None], len(leg.idx), axis=1)
        turn[:, 2] = smoothstep(t / lead)
        path = leg.x0 + turn * (target - leg.x0)
        up = _bump(t, span)
        path[:, 1] += comp * np.radians(phi) * up
        path = np.clip(path, lo, hi)
        roll = np.radians(phi) * up
        roots = _rolled_roots(body.root, pivot, axis, roll)
        q = np.repeat(body.q[None], n, axis=0)
        q[:, leg.idx] = path
        g = kin.segment_globals(q, roots)
        pts = np.einsum("mkij,kj->mki", g[:, body.segs, :3, :], body.nodes)
        legs = np.concatenate([leg.start[None], pts[:, leg.nodes]])
        deep = -float(legs[..., 1].min())
        if deep > DEEP_CM - min(0.0, leg.floor):
            continue
        runs = contact_runs(legs, CONTACT_HEIGHT_CM)
        if runs.slide.max(initial=0.0) > SLIDE_CM:
            continue
        foot_up = float((pts[:, leg.nodes[leg.foot], 1].min(axis=1) - pts[:, pelvis, 1].min(axis=1)).max())
        if foot_up > up_limit:
            continue
        if _rise(legs[judged_from:], parts) > RISE_CM:
            continue
        heel = max(float(g[-1, leg.foot_seg, 1, :] @ leg.heel), float(legs[-1, leg.foot, 1].min()))
        key = (round(heel, 1), phi, float(runs.slide.max(initial=0.0)))
        if heel < start_heel and (best is None or key < best[0]):
            best = (key, Roll(side, path, roll, pivot, axis, heel))
    return None if best is None else best[1]


def _rise(pts: np.ndarray, parts: np.ndarray) -> float:
    """cm: the most any part's lowest node of ``pts`` ``(n, k, 3)`` rises above its lowest (0 if none)."""
    if not len(pts):
        return 0.0
    lows = [pts[:, parts == p, 1].min(axis=1) for p in np.unique(parts)]
    return max(float((low - np.minimum.accumulate(low)).max()) for low in lows)


def _carried(kin, joints: tuple[str, ...]) -> int:
    """The segment a chain of ``joints`` from the pelvis carries (its last joint's child)."""
    last = [s for s in kin.tree_steps() if s[0] == joints[-1]]
    return int(last[0][2])


def _kept(kin, q: np.ndarray, roots: np.ndarray, goal: np.ndarray, joints: tuple[str, ...]) -> np.ndarray:
    """``q`` ``(n, ndof)`` with the angles of ``joints`` (a chain from the pelvis) that keep the segment they
    carry where ``goal`` ``(n, 4, 4)`` has it, the pelvis at ``roots`` (damped Gauss-Newton, within the
    joints' limits)."""
    idx = ds._dofs(kin, joints)
    chest = _carried(kin, joints)
    lo, hi = kin.lower[idx], kin.upper[idx]
    q = q.copy()
    eps = 1e-4

    def error(qs: np.ndarray, rs: np.ndarray, gs: np.ndarray) -> np.ndarray:
        c = kin.segment_globals(qs, rs)[:, chest]
        d = np.einsum("nji,njk->nik", gs[:, :3, :3], c[:, :3, :3])  # goal^T @ now
        w = (
            np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], axis=1)
            / 2.0
        )
        return np.concatenate([c[:, :3, 3] - gs[:, :3, 3], ROT_CM * w], axis=1)

    n, k = len(q), len(idx)
    for _ in range(LUMBAR_ITERATIONS):
        qs = np.repeat(q[:, None], k + 1, axis=1)
        qs[:, np.arange(1, k + 1), idx] += eps
        e = error(
            qs.reshape(n * (k + 1), -1),
            np.repeat(roots, k + 1, axis=0),
            np.repeat(goal, k + 1, axis=0),
        ).reshape(n, k + 1, 6)
        jac = (e[:, 1:] - e[:, :1]).transpose(0, 2, 1) / eps  # (n, 6, k)
        h = np.einsum("nij,nik->njk", jac, jac) + LUMBAR_DAMPING * np.eye(k)
        step = -np.linalg.solve(h, np.einsum("nij,ni->nj", jac, e[:, 0])[..., None])[..., 0]
        q[:, idx] = np.clip(q[:, idx] + step, lo, hi)
    return q


def rolled(figs: FigureSet, frames: ClipFrames, start: int, rest: int, still: int) -> ClipFrames:
    """``frames`` with the legs rolled out from frame ``start`` (the physics' last), each in turn with its
    pelvis's roll (:func:`rolled_leg`), on top of how they lay there; the trunk is down from frame ``rest``;
    the clip lengthened to end ``still`` frames after the last leg. The legs as ``frames`` has them where
    no way out lays a heel lower."""
    kin = figs.kin["body"]
    n = round(LEG_SECONDS * frames.fps)
    end = start + n * len(ORDER) + still + 1
    extra = max(0, end - len(frames.poses))
    poses = np.concatenate([frames.poses, np.repeat(frames.poses[-1:], extra, axis=0)])
    roots = np.concatenate([frames.roots, np.repeat(frames.roots[-1:], extra, axis=0)])
    rifles = np.concatenate([frames.rifles, np.repeat(frames.rifles[-1:], extra, axis=0)])
    legs = ds._leg_dofs(kin)
    poses[start + 1 :, legs] = poses[start, legs]
    lying = roots.copy()
    for i, side in enumerate(ORDER):
        k0 = start + i * n
        q = poses[-1].copy()
        body = ds._Body(figs, q, roots[k0], rifles[-1])
        way = rolled_leg(body, side, n, max(0, rest - k0))
        if way is None:
            continue
        idx = ds._Leg(body, side).idx
        poses[k0 + 1 : k0 + n + 1, idx] = way.path
        poses[k0 + n + 1 :, idx] = way.path[-1]
        span = slice(k0 + 1, k0 + n + 1)
        roots[span] = _rolled_roots(roots[k0], way.pivot, way.axis, way.roll)
        chains = (LUMBAR, tuple(f"{ORDER[1 - i]}_{j}" for j in OTHER_LEG))  # the chest and the other foot
        for chain in chains:
            goal = kin.segment_globals(poses[span], lying[span])[:, _carried(kin, chain)]
            poses[span] = _kept(kin, poses[span], roots[span], goal, chain)
    return ClipFrames(poses, roots, rifles, frames.fps)
