"""A dead crawler's trunk comes down about his thighs after the physics (issue 14).

The ragdoll of crawl2dead comes to rest bridged between his thighs and his forearms: the thighs lie on the
ground from about their middle to the knee, the hips are 16-18 cm up (a body lying flat has them at about
13.5) and the pelvis and belly 4-5 cm over the ground (the check's ``rest_contact_cm``, limit 2). The arms
kept at a faint tone hold the chest up once the physics sleeps; letting them go in the physics dropped the
chest but slid the forearms 6.5 cm and skated a foot 5 cm (branch ``restc14-wip``).

So the trunk is lowered kinematically (:func:`sunk`, :data:`SINK_SECONDS`), before the chest and head
settle (:mod:`authoring.dead_prone`): the pelvis turns down about the line through each thigh's contact
nearest the hip (:func:`pivot_axis`: the thigh cannot turn about its knee end, its middle already lies on
the ground), so the thighs' contacts stay where they lie and their knee ends lift a little (1-5 cm); the
whole spine bends so that the upper trunk, and with it the arms and head, stays where it lies at every
frame (:func:`held_spine`; the waist bending least, :data:`WAIST_SHARE`); each leg's hip, knee, ankle and
toes turn so that the foot's contacts stay where they lie, sliding no leg node on the ground by more than
:data:`SLIDE_CM` (:func:`planted_leg`; the feet lift 1-2 cm). The turn is the least of :data:`TURNS` that
lays the pelvis and the belly within :data:`DOWN_CM` of the ground (crawl2dead: 9.5 deg; pelvis and belly
4.2/4.5 -> -0.1/0.2 cm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from authoring import dead_settle as ds
from authoring.ik import axis_angle
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames

SINK_SECONDS = 0.5  # s, eased: the trunk comes down about the thighs
TURNS = np.arange(0.5, 15.01, 0.5)  # degrees: the pelvis' turn down about the thighs, the least that lays it
DOWN_CM = 0.5  # cm: the pelvis and the belly are down this low
SLIDE_CM = 0.5  # cm: a leg node on the ground before and after may move this far
CHECKS = 6  # the legs' way is checked at this many even steps
SPINE = ("waist", "vl5", "vl4", "vl3", "vl2", "vl1", "vt12", "vt11", "vt10", "vt9", "vt8", "vt7", "vt6",
         "vt5", "vt4", "vt3", "vt2", "vt1")  # fmt: skip
WAIST_SHARE = 0.2  # the waist's weight in the spine's bend (the others 1): bent most, its mesh gaped open
HELD = "upper_torso"  # the segment (and everything above it: arms, head) that stays where it lies
ORIENT_CM = 30.0  # cm per radian: the held segment's turn weighed against its move
LEG = ("hip", "knee", "ankle", "toes")  # each leg's joints that keep the foot where it lies
LEG_PARTS = ("_thigh", "_knee", "_kneecap", "_foot")


@dataclass(frozen=True)
class Sink:
    """The trunk's way down: the pelvis turned ``turn`` rad about ``axis`` through ``pivot`` (world), and
    the pose at the end."""

    pivot: np.ndarray
    axis: np.ndarray
    turn: float
    pose: np.ndarray


def pivot_axis(body: ds._Body) -> tuple[np.ndarray, np.ndarray] | None:
    """The point and horizontal axis (world) through each thigh's node on the ground nearest its hip (None:
    a thigh lies off the ground)."""
    kin = body.kin
    g = kin.segment_globals(body.q, body.root)
    ends = []
    for side in ("left", "right"):
        on = body.planted & (body.parts == f"{side}_thigh")
        if not on.any():
            return None
        hip = g[kin.segment_names.index(f"{side}_upper_leg"), :3, 3]
        knee = g[kin.segment_names.index(f"{side}_lower_leg"), :3, 3]
        p = body.points[on]
        ends.append(p[int(np.argmin((p - hip) @ (knee - hip)))])
    axis = ends[1] - ends[0]
    axis[1] = 0.0
    return (ends[0] + ends[1]) / 2.0, axis / np.linalg.norm(axis)


def turned_root(root: np.ndarray, pivot: np.ndarray, axis: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """Root globals ``(n, 4, 4)``: ``root`` turned by each of ``turn`` (rad) about ``axis`` through
    ``pivot``."""
    turn = np.atleast_1d(np.asarray(turn, dtype=np.float64))
    r = axis_angle(np.broadcast_to(axis, (len(turn), 3)), turn)
    out = np.repeat(root[None], len(turn), axis=0)
    out[:, :3, :3] = r @ root[:3, :3]
    out[:, :3, 3] = np.einsum("nij,j->ni", r, root[:3, 3] - pivot) + pivot
    return out


def held_spine(kin, q: np.ndarray, root: np.ndarray, held: np.ndarray, iterations: int = 20) -> np.ndarray:
    """``q`` with the :data:`SPINE` angles that bring segment :data:`HELD` back to its global ``held`` with
    the root at ``root`` (damped Gauss-Newton, least change, within the joints' limits)."""
    idx = ds._dofs(kin, SPINE)
    share = np.where(np.isin(idx, ds._dofs(kin, ("waist",))), WAIST_SHARE, 1.0)
    seg = kin.segment_names.index(HELD)
    q = q.copy()
    eps = 1e-4

    def error(qs: np.ndarray) -> np.ndarray:
        g = kin.segment_globals(qs, np.broadcast_to(root, (len(qs), 4, 4)))[:, seg]
        d = g[:, :3, :3] @ held[:3, :3].T
        w = np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], axis=1) / 2
        return np.c_[g[:, :3, 3] - held[:3, 3], ORIENT_CM * w]

    for _ in range(iterations):
        trial = np.repeat(q[None], len(idx) + 1, axis=0)
        trial[np.arange(1, len(idx) + 1), idx] += eps
        e = error(trial)
        jac = (e[1:] - e[0]).T / eps
        jw = jac * share
        step = -jw.T @ np.linalg.solve(jw @ jac.T + 1.0 * np.eye(6), e[0])
        q[idx] = np.clip(q[idx] + step, kin.lower[idx], kin.upper[idx])
        if np.abs(e[0]).max() < 1e-3:
            break
    return q


def planted_leg(body: ds._Body, side: str, q: np.ndarray, way: Sink) -> np.ndarray:
    """``q`` with the ``side`` leg's :data:`LEG` angles that keep its foot's lowest nodes (on the ground, or
    off it) where they lie at the end of ``way`` (its pose unused), into no ground and sliding no leg node on
    the ground by more than :data:`SLIDE_CM` at any of :data:`CHECKS` steps of the way (the root turned and
    the leg's angles blended alike; checked at the end only, a thigh slid 3.8 cm on the way); a compass
    search from the angles the leg has."""
    from authoring.dead_prone import search

    kin = body.kin
    idx = ds._dofs(kin, tuple(f"{side}_{j}" for j in LEG))
    foot = body.parts == f"{side}_foot"
    keep = foot & (body.points[:, 1] <= body.points[foot, 1].min() + CONTACT_HEIGHT_CM)  # what it lies on
    leg = np.array([str(p).startswith(side) and str(p).endswith(LEG_PARTS) for p in body.parts])
    start = body.points[keep]
    down, down0 = body.planted[leg], body.points[leg][body.planted[leg]]
    floor = min(0.0, float(body.points[leg, 1].min()))
    steps = np.arange(1, CHECKS + 1) / CHECKS
    roots = turned_root(body.root, way.pivot, way.axis, steps * way.turn)
    x0 = body.q[idx]

    def cost(x: np.ndarray) -> np.ndarray:
        wrong = np.zeros(len(x))
        for u, root in zip(steps, roots, strict=True):
            qs = np.repeat(body.q[None], len(x), axis=0)  # the legs hang from the root alone
            qs[:, idx] = x0 + u * (x - x0)
            g = kin.segment_globals(qs, np.broadcast_to(root, (len(x), 4, 4)))
            p = np.einsum("nkij,kj->nki", g[:, body.segs[leg], :3, :], body.nodes[leg])
            on = p[:, down]
            slid = np.hypot(*(on - down0)[..., [0, 2]].transpose(2, 0, 1)) * (on[..., 1] <= CONTACT_HEIGHT_CM)
            wrong += np.maximum(0.0, floor - p[..., 1].min(axis=1))
            wrong += np.maximum(0.0, slid.max(axis=1, initial=0.0) - SLIDE_CM)
        moved = np.linalg.norm(p[:, keep[leg]] - start, axis=2).max(axis=1)
        return moved + ds.PENALTY * wrong

    out = q.copy()
    out[idx] = search(cost, x0[None], kin.lower[idx], kin.upper[idx])
    return out


def _lows(body: ds._Body, q: np.ndarray, root: np.ndarray) -> tuple[float, np.ndarray]:
    """The higher of the pelvis' and the belly's lowest nodes (cm) in pose ``q`` at ``root``, and every
    node (world)."""
    g = body.kin.segment_globals(q, root)
    p = np.einsum("kij,kj->ki", g[body.segs, :3, :], body.nodes)
    return max(float(p[body.parts == part, 1].min()) for part in ("pelvis", "belly")), p


def sink(body: ds._Body) -> Sink | None:
    """The least turn of :data:`TURNS` that lays the pelvis and belly within :data:`DOWN_CM` of the ground
    (or the lowest of them), the upper trunk held (:func:`held_spine`), and the legs that keep their feet
    along it (:func:`planted_leg`: they carry no part of the trunk); None if the thighs do not lie on the
    ground or the trunk is down already."""
    at = pivot_axis(body)
    if at is None or _lows(body, body.q, body.root)[0] <= DOWN_CM:
        return None
    pivot, axis = at
    kin = body.kin
    held = kin.segment_globals(body.q, body.root)[kin.segment_names.index(HELD)]
    best: tuple[float, float, np.ndarray] | None = None
    for deg in TURNS:
        turn = -np.radians(deg)  # the pelvis' front down
        root = turned_root(body.root, pivot, axis, turn)[0]
        q = held_spine(kin, body.q, root, held)
        low = _lows(body, q, root)[0]
        if best is None or low < best[0]:
            best = (low, turn, q)
        if low <= DOWN_CM:
            break
    assert best is not None
    _, turn, q = best
    for side in ("left", "right"):
        q = planted_leg(body, side, q, Sink(pivot, axis, turn, q))
    return Sink(pivot, axis, turn, q)


def sunk(figs: FigureSet, frames: ClipFrames) -> ClipFrames:
    """``frames`` with the trunk's way down about the thighs appended (:data:`SINK_SECONDS`, eased): the
    root turned along it, the other angles blended; unchanged if the body is not face down on its thighs
    or lies down already."""
    q0, root0 = frames.poses[-1], frames.roots[-1]
    body = ds._Body(figs, q0, root0, frames.rifles[-1])
    if not ds._face_down(body.kin, q0, root0):
        return frames
    way = sink(body)
    if way is None:
        return frames
    n = round(SINK_SECONDS * frames.fps)
    s = np.arange(1, n + 1) / n
    u = s * s * (3.0 - 2.0 * s)
    poses = q0[None] + u[:, None] * (way.pose - q0)[None]
    roots = turned_root(root0, way.pivot, way.axis, u * way.turn)
    kin = body.kin
    held = kin.segment_globals(q0, root0)[kin.segment_names.index(HELD)]
    for k in range(n - 1):  # the upper trunk held along the way too (blended, it dipped and rose)
        poses[k] = held_spine(kin, poses[k], roots[k], held)
    return ClipFrames(
        np.concatenate([frames.poses, poses]),
        np.concatenate([frames.roots, roots]),
        np.concatenate([frames.rifles, np.repeat(frames.rifles[-1:], n, axis=0)]),
        frames.fps,
    )
