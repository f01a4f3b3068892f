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

Judged by height alone, a thigh turned out 1.8-2.0 cm above the ground and then laid down was in the air:
the check (a part that comes down stays on the ground until it rises past its ``LIFT_OFF_CM``) saw it
slide 5.5-6.0 cm. So :func:`rolled` judges each leg's ways as the check does, on the clip so far
(:func:`rolled_ways` ``before``, :data:`CHECKED_SLIDE_CM`), and takes the first that, played on the
whole body, slides nothing further than the check allows or than it slid already.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from authoring import dead_settle as ds
from authoring.body_parts import FOOT_PARTS, contact_runs
from authoring.quality import CONTACT_HEIGHT_CM, LIFT_OFF_CM, THRESHOLDS
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
ROLLS_DEG = (3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0)  # the pelvis's roll tried, least first
LEADS = (0.5, 0.75)  # of a leg's time: its hip's turn is done by then (the knee and foot with the whole)
SPANS = (0.3, 0.45)  # ... the pelvis rolls over this much of it, and back over as much at its end
COMPS = (0.0, 0.5)  # the hip flexes this much of the roll with it (the thigh kept nearer the ground)
# cm: a leg node on the ground moves at most this far while on it (the check: 3, the fall's own slide
# under it)
SLIDE_CM = 1.9
# cm: judged on the whole clip as the check judges it (a thigh lifting off or coming down just above the
# ground, under LIFT_OFF_CM, slides: prstow2dead's left thigh turned out 1.8 cm up and landed, 5.5 cm), a leg
# node moves at most this far over its whole run on the ground, the fall's own drift in it (prfire2dead's
# right thigh slid 1.7 cm in the physics)
CHECKED_SLIDE_CM = 2.6
CHECKED_MARGIN_CM = 0.005  # cm under the check's contact_slide_cm / foot_skate_cm: any other node's run
MAX_WAYS = 40  # the best ways of a leg tried on the whole clip, in order
FOOT_UP_MARGIN = 2.5  # cm under the check's lying_feet_up_cm: the foot over the pelvis
RISE_CM = 2.5  # cm: once the trunk is down a leg part's lowest node rises at most this (the check: 3)
DEEP_CM = 0.05  # cm: into the ground, at most
# the whole spine takes the pelvis's roll back, the shoulders staying (the lumbar spine alone left the
# chest turned: a forearm lifting off the ground dipped 1 cm and slid 3.0-3.5 cm, prstow2dead 2.3)
LUMBAR = ("waist", "vl5", "vl4", "vl3", "vl2", "vl1", "vt12", "vt11", "vt10", "vt9", "vt8", "vt7", "vt6",
          "vt5", "vt4", "vt3", "vt2", "vt1")  # fmt: skip
# ... and the other leg's hip and knee keep its shin where it lies (its foot too: its thigh, turned about the
# hip, went 1 cm into the ground and slid 2.8 cm)
OTHER_LEG = ("hip", "knee")
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


def legs_nodes(body: ds._Body) -> np.ndarray:
    """The mesh nodes of both legs of ``body``."""
    return np.concatenate([ds._Leg(body, side).nodes for side in ORDER])


def _bump(t: np.ndarray, span: float) -> np.ndarray:
    """0 -> 1 over the first ``span`` of ``t``, held, back to 0 over the last."""
    return smoothstep(np.minimum(t, 1.0 - t) / span)


def rolled_leg(body: ds._Body, side: str, n: int, judged_from: int) -> Roll | None:
    """The ``side`` leg's way out over ``n`` frames (:data:`LEG_SECONDS`) that lays its heel lowest, its
    pelvis rolling (see the module docstring); a rise is judged from frame ``judged_from`` on (the trunk
    down). None where no way keeps to the limits or lays the heel lower than it lies."""
    ways = rolled_ways(body, side, n, judged_from)
    return ways[0] if ways else None


def rolled_ways(
    body: ds._Body, side: str, n: int, judged_from: int, before: np.ndarray | None = None
) -> list[Roll]:
    """The ``side`` leg's ways out over ``n`` frames (:data:`LEG_SECONDS`) that lay its heel lower than it
    lies, its pelvis rolling (see the module docstring), the heel lowest first; a rise is judged from frame
    ``judged_from`` on (the trunk down). ``before``: both legs' nodes (:func:`legs_nodes`) over the clip up
    to this frame: their slides are judged as the check does, with that way on the ground
    (:data:`CHECKED_SLIDE_CM`); None: the leg's own nodes by height alone (:data:`SLIDE_CM`)."""
    kin, leg = body.kin, ds._Leg(body, side)
    pivot, axis = _pivot(body, side)
    parts = body.parts[leg.nodes]
    pelvis = body.parts == "pelvis"
    t = np.arange(1, n + 1) / n
    up_limit = THRESHOLDS["lying_feet_up_cm"] - FOOT_UP_MARGIN
    lo, hi = kin.lower[leg.idx], kin.upper[leg.idx]
    judged = legs_nodes(body)
    release = np.where(np.isin(body.parts[judged], FOOT_PARTS), CONTACT_HEIGHT_CM, LIFT_OFF_CM)
    ways: list[tuple[tuple[float, float, float], Roll]] = []
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
        if before is None:
            runs = contact_runs(legs, CONTACT_HEIGHT_CM)
        else:  # as the check judges them: the legs' way on the ground so far, and the lift-off rule
            both = np.concatenate([body.points[None, judged], pts[:, judged]])
            runs = contact_runs(np.concatenate([before[:-1], both]), CONTACT_HEIGHT_CM, release)
            runs.slide = runs.slide[runs.last >= len(before) - 1]  # what is done already is not chosen
        if runs.slide.max(initial=0.0) > (SLIDE_CM if before is None else CHECKED_SLIDE_CM):
            continue
        foot_up = float((pts[:, leg.nodes[leg.foot], 1].min(axis=1) - pts[:, pelvis, 1].min(axis=1)).max())
        if foot_up > up_limit:
            continue
        if _rise(legs[judged_from:], parts) > RISE_CM:
            continue
        heel = max(float(g[-1, leg.foot_seg, 1, :] @ leg.heel), float(legs[-1, leg.foot, 1].min()))
        key = (round(heel, 1), phi, float(runs.slide.max(initial=0.0)))
        if heel < start_heel:
            ways.append((key, Roll(side, path, roll, pivot, axis, heel)))
    return [w for _, w in sorted(ways, key=lambda kw: kw[0])]


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


def _points(body: ds._Body, poses: np.ndarray, roots: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """The world points ``(n, k, 3)`` of ``body``'s mesh ``nodes`` over ``poses`` and ``roots``."""
    g = body.kin.segment_globals(poses, roots)
    return np.einsum("fkij,kj->fki", g[:, body.segs[nodes], :3, :], body.nodes[nodes])


def _slides(points: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """Per node of ``points`` ``(n, k, 3)``: its worst slide on the ground, as the check judges it (a part
    but a foot lifting off stays on the ground until it rises past its ``LIFT_OFF_CM``)."""
    release = np.where(np.isin(parts, FOOT_PARTS), CONTACT_HEIGHT_CM, LIFT_OFF_CM)
    return contact_runs(points, CONTACT_HEIGHT_CM, release).per_node(points.shape[1])[0]


def _rolled_in(
    kin, clip: tuple[np.ndarray, np.ndarray, np.ndarray], way: Roll, k0: int, other: str
) -> tuple[np.ndarray, np.ndarray]:
    """The poses and roots of ``clip`` (poses, roots, the roots as he lies) with ``way`` from frame ``k0``
    on, the chest and the ``other`` leg's shin kept where they lie (:func:`_kept`)."""
    poses, roots, lying = (a.copy() for a in clip)
    n = len(way.path)
    idx = ds._dofs(kin, tuple(f"{way.side}_{j}" for j in ds.LEG_DOFS))
    poses[k0 + 1 : k0 + n + 1, idx] = way.path
    poses[k0 + n + 1 :, idx] = way.path[-1]
    span = slice(k0 + 1, k0 + n + 1)
    roots[span] = _rolled_roots(roots[k0], way.pivot, way.axis, way.roll)
    for chain in (LUMBAR, tuple(f"{other}_{j}" for j in OTHER_LEG)):
        goal = kin.segment_globals(poses[span], lying[span])[:, _carried(kin, chain)]
        poses[span] = _kept(kin, poses[span], roots[span], goal, chain)
    return poses, roots


def rolled(figs: FigureSet, frames: ClipFrames, start: int, rest: int, still: int) -> ClipFrames:
    """``frames`` with the legs rolled out from frame ``start`` (the physics' last), each in turn with its
    pelvis's roll (:func:`rolled_ways`), on top of how they lay there; the trunk is down from frame ``rest``;
    the clip lengthened to end ``still`` frames after the last leg. Each leg takes the first of its ways
    that, played on the whole clip so far, slides no node on the ground (as the check judges it) further
    than the check allows (a leg's: :data:`CHECKED_SLIDE_CM`) or than it slid already; the legs as
    ``frames`` has them where none does."""
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
        body = ds._Body(figs, poses[-1].copy(), roots[k0], rifles[-1])
        every = np.arange(len(body.parts))
        before = _points(body, poses[: k0 + 1], roots[: k0 + 1], legs_nodes(body))
        limit = np.where(np.isin(every, legs_nodes(body)), CHECKED_SLIDE_CM, THRESHOLDS["contact_slide_cm"])
        limit = np.where(np.isin(body.parts, FOOT_PARTS), THRESHOLDS["foot_skate_cm"], limit)
        allowed = np.maximum(
            limit - CHECKED_MARGIN_CM, _slides(_points(body, poses, roots, every), body.parts)
        )
        for way in rolled_ways(body, side, n, max(0, rest - k0), before)[:MAX_WAYS]:
            p, r = _rolled_in(kin, (poses, roots, lying), way, k0, ORDER[1 - i])
            got = _slides(_points(body, p, r, every), body.parts)
            if (got <= allowed + 1e-6).all():
                poses, roots = p, r
                break
    return ClipFrames(poses, roots, rifles, frames.fps)
