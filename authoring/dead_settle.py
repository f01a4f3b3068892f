"""A face-down dead body goes limp after the physics: the head drops (issue 14).

The ragdoll of :mod:`authoring.deaths` comes to rest face down on its toes, heels up (19-23 cm), and a prone
soldier keeps his head up about 30 cm, like a live one: muscles that rolled the legs out or dropped the head
in the simulation dragged the feet and slid the forearms. So once the physics has settled, a short
kinematic settle (:data:`SETTLE_SECONDS`, eased, deterministic) is appended, the body staying where it lies:

**the head drops**: the neck, head and upper back angles (within soldier.fig's limits) that lay the head
lowest, into neither the ground, the arms nor the rifle and sliding no node on the ground
(:func:`dropped_head`): the cheek comes to rest where it can.

Rolling the legs out the same way (hip, knee, ankle per leg, optimised for the lowest heel) was tried and
taken out: with the pelvis where it lies, the thighs and knees on the ground slid 5-14 cm while the legs
turned (the thigh turns about the hip, it cannot roll along the ground) and the heels came down only 0-4 cm.

Only a body lying on its front (the pelvis' front pointing down, :data:`FACE_DOWN`) settles so.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from authoring.body_parts import SegmentHulls
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.model import Figure

SETTLE_SECONDS = 0.8  # s, eased: the body goes limp after the physics has settled
STILL_SECONDS = 0.1  # s: then lies still (the clip ends at rest)
FACE_DOWN = 0.5  # cosine: the pelvis' front points down at least this much
HEAD_CLEARANCE = 0.3  # cm: the head's lowest node stops this far above the ground
SLIDE_CM = 2.0  # cm: a node on the ground before and after may move this far (the check: feet 2, others 3)
PENALTY = 50.0  # per cm into the ground, the body or the rifle
MOVE_COST = 0.01  # per degree moved: of two equally low shapes the nearer one
HEAD_DOFS = ("vt4", "vt3", "vt2", "vt1", "neck", "head")  # the upper back gives a little too
ARM_PARTS = ("_forearm", "_hand", "_upper_arm")  # what the head may come to rest on, but not go into


def _face_down(kin, q: np.ndarray, root: np.ndarray) -> bool:
    g = kin.segment_globals(q, root)[kin.segment_names.index("lower_torso")]
    return float(g[1, 2]) >= FACE_DOWN  # the front (-Z) pointing down: +Z up


def _dofs(kin, joints: tuple[str, ...]) -> np.ndarray:
    return np.concatenate([np.arange(kin.dof_slices[j].start, kin.dof_slices[j].stop) for j in joints])


def _minimise(
    cost: Callable[[np.ndarray], float], starts: list[np.ndarray], lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """Powell's method from each start within the bounds (deterministic): the lowest it finds, or the first
    start if nothing is lower."""
    from scipy.optimize import minimize

    best, best_cost = np.clip(starts[0], lo, hi), cost(np.clip(starts[0], lo, hi))
    for x in starts:
        r = minimize(
            cost,
            np.clip(x, lo, hi),
            method="Powell",
            bounds=list(zip(lo, hi, strict=True)),
            options={"xtol": 1e-3},
        )
        if r.fun < best_cost:
            best, best_cost = np.asarray(r.x), float(r.fun)
    return best


class _Body:
    """The dead body's last frame: its mesh nodes by part, to shape a limb against the ground."""

    def __init__(self, figs: FigureSet, q: np.ndarray, root: np.ndarray, rifle: np.ndarray) -> None:
        self.kin = figs.kin["body"]
        self.nodes, self.segs = figs.nodes("body")
        self.parts = figs.node_parts("body")
        self.q, self.root = q, root
        rnodes, rsegs = figs.nodes("rifle")
        rg = figs.kin["rifle"].segment_globals(np.zeros(figs.kin["rifle"].ndof), rifle)
        self.rifle_points = np.einsum("kij,kj->ki", rg[rsegs, :3, :], rnodes)
        self.points = self.heights(q)[1]
        self.planted = self.points[:, 1] <= CONTACT_HEIGHT_CM

    def heights(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g = self.kin.segment_globals(q, self.root)
        return g, np.einsum("kij,kj->ki", g[self.segs, :3, :], self.nodes)

    def misplaced(self, q: np.ndarray) -> float:
        """cm the shape ``q`` goes wrong by: its lowest node below y = 0 (not counting what lay that deep
        already) plus how far beyond :data:`SLIDE_CM` the nodes on the ground there and now slid."""
        p = self.heights(q)[1]
        base = min(0.0, float(self.points[:, 1].min()))
        still = self.planted & (p[:, 1] <= CONTACT_HEIGHT_CM)
        slid = np.hypot(*(p[still] - self.points[still])[:, [0, 2]].T)
        return max(0.0, base - float(p[:, 1].min())) + max(0.0, float(slid.max(initial=0.0)) - SLIDE_CM)


def dropped_head(body: _Body) -> np.ndarray:
    """The neck's and head's angles that lay the head lowest, into neither the ground, the body nor the
    rifle."""
    kin = body.kin
    idx = _dofs(kin, HEAD_DOFS)
    head = body.parts == "head"
    head_segs = np.unique(body.segs[head])
    arms = np.unique(body.segs[[str(p).endswith(ARM_PARTS) for p in body.parts]])
    others = SegmentHulls.build(body.nodes, body.segs, arms)
    heads = SegmentHulls.build(body.nodes, body.segs, head_segs)
    x0 = body.q[idx]

    def cost(x: np.ndarray) -> float:
        q = body.q.copy()
        q[idx] = x
        g, p = body.heights(q)
        into_body, _, _ = others.depth(p[None, head], g[None])
        into_head, _, _ = heads.depth(body.rifle_points[None], g[None])
        low = float(p[head, 1].min())
        pen = max(0.0, HEAD_CLEARANCE - low) + into_body + into_head + body.misplaced(q)
        return low + PENALTY * pen + MOVE_COST * float(np.degrees(np.abs(x - x0)).sum())

    return _minimise(cost, [x0], kin.lower[idx], kin.upper[idx])


def limp_target(figs: FigureSet, frames: ClipFrames) -> np.ndarray | None:
    """The limp shape the last frame settles into, or None if the body does not lie on its front."""
    q, root, rifle = frames.poses[-1], frames.roots[-1], frames.rifles[-1]
    body = _Body(figs, q, root, rifle)
    if not _face_down(body.kin, q, root):
        return None
    target = q.copy()
    target[_dofs(body.kin, HEAD_DOFS)] = dropped_head(body)
    return target


def settle(frames: ClipFrames, soldier: Figure, rifle: Figure) -> ClipFrames:
    """``frames`` with the limp settle appended (see the module docstring); unchanged if not face down."""
    figs = FigureSet({"body": soldier, "rifle": rifle})
    target = limp_target(figs, frames)
    if target is None:
        return frames
    n = round(SETTLE_SECONDS * frames.fps)
    s = np.arange(1, n + 1) / n
    u = np.concatenate([s * s * (3.0 - 2.0 * s), np.ones(round(STILL_SECONDS * frames.fps))])
    last = frames.poses[-1]
    poses = last[None] + u[:, None] * (target - last)[None]
    k = len(u)
    return ClipFrames(
        np.concatenate([frames.poses, poses]),
        np.concatenate([frames.roots, np.repeat(frames.roots[-1:], k, axis=0)]),
        np.concatenate([frames.rifles, np.repeat(frames.rifles[-1:], k, axis=0)]),
        frames.fps,
    )
