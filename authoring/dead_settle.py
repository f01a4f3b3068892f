"""A face-down dead body goes limp after the physics: the head drops, the legs roll out (issue 14).

The ragdoll of :mod:`authoring.deaths` comes to rest face down on its toes, heels up (19-23 cm), and a prone
soldier keeps his head up about 30 cm, like a live one: muscles that rolled the legs out or dropped the head
in the simulation dragged the feet and slid the forearms. So once the physics has settled, a short
kinematic settle (:data:`SETTLE_SECONDS`, eased, deterministic) is appended, the body staying where it lies:

**the head drops**: the neck, head and upper back angles (within soldier.fig's limits) that lay the head
lowest, into neither the ground, the arms nor the rifle and sliding no node on the ground
(:func:`dropped_head`): the cheek comes to rest where it can.

**the legs are lifted, turned out and laid down** (:mod:`authoring.dead_legs`): each leg's hip, knee,
ankle and toe angles that lay its heel lowest (the check's ``rest_foot_cm``) within the figure's limits,
reached through the air (the hip extended first) so that nothing on the ground skids; soldier.fig's
limits (hip turned out 45 deg, foot everted 30 deg, ankle pointed 50 deg) leave the heels 13-15 cm up.
A leg that no lift clears **goes limp** where it lies (:func:`limp_leg`): the angles that lay its heel
lowest, into no ground and sliding no leg node on the ground by more than :data:`LEG_SLIDE_CM` between any
two of :data:`LEG_CHECKS` steps of the settle (a node's run on the ground began in the fall and the check
judges the run's whole extent); a batched grid and pattern search (:data:`LEG_GRID`, :data:`LEG_STEP`).
Powell over the same angles with a 2 cm allowance slid thighs, knees and toes 5-14 cm for heels 2-4 cm
lower: the thigh turns about the hip, it cannot roll along the ground; so the limp heels came down only a
little (soldier.fig: 20.3-22.5 -> 18.9-21.5 cm).

Only a body lying on its front (the pelvis' front pointing down, :data:`FACE_DOWN`) settles so. A prone
death (``propped``) is left propped on its elbows, the head 18-19 cm up even dropped: its chest comes down
instead (:mod:`authoring.dead_prone`: spine, neck and head, the arms laid anew and lifted clear while they
move), its legs turning out with it (a limp leg as the torso comes down).

A body on its back (a death that asks for it, ``arms_fall``) **lets its arms fall** instead (issue 14:
kfire2dead's forearms stood up 37 cm; an arm tone in the physics made the DI slaves' feet jump, branch
``legsup14-kfire``): the clavicle, shoulder, elbow and wrist angles of each arm that lay it lowest
(:func:`fallen_arm`: its highest part's lowest node, as the check measures, plus a little of its nodes' mean
height), into neither the ground, the rest of the body nor the rifle and sliding no node on the ground;
from the arm's own pose and the best shapes of a coarse grid (:data:`ARM_GRID`), both arms in either order
(:data:`SIDE_ORDERS`). On his back, a hand falls to its own side (:meth:`_Arm.astray`) and a shape whose
straight way (in the angles) lifts a part of the arm is wrong (kstow2dead's left forearm, laid from over the
chest on the far side, rose 40 cm). The fall accelerates like a dropped limb and lands softly
(:func:`fall_easing`), each arm along a way bent through a control pose so that no part of it rises
(:mod:`authoring.dead_arms`: kfire2dead's right hand swung up 18.6 cm over the head, eased straight). Half
on his side, the top arm reaches the ground only past the head, its elbow on the body (17.5 cm), curled
over his head: a death that keeps its arms from there (``DeathSpec.arms_headward_cm``) lays such an arm
anew against the other (:func:`_relaid`; kfire2dead's lies out across his chest, 11.8 cm). The arms
fall as the body lands (:func:`_arms_fall`: from the frame it is down, as the check's ``limb_rest_lag_s``
sees it, in :data:`ARM_FALL_SECONDS`), over the physics' last frames: appended after them, kfire2dead's arm
hung in the air 1.5 s after he lay still (the asleep ragdoll's damped joints hold it) and was then lowered.
A death that asks (:attr:`ArmsFall.early_s`) lets its arms go before it is down and gives them longer
(:data:`EARLY_LONGER`): kfire2dead's relaid top arm, swept 90 cm across his chest in 0.6 s, whipped its hand
round at 9 m/s; a dead arm drops with the body, it is not flung after it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from authoring import dead_arms, quality_rest
from authoring.body_parts import SegmentHulls
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.quality_rest import DOWN_CM, NEAR_CM, TORSO_PARTS, pelvis_turns, rest_frame
from authoring.transitions import ClipFrames
from peabody.model import Figure
from server.soldier.blend import smoothstep

SETTLE_SECONDS = 0.8  # s, eased: the body goes limp after the physics has settled
STILL_SECONDS = 0.1  # s: then lies still (the clip ends at rest)
LEGS_LAND_SECONDS = 0.4  # s: the legs are laid as the body lands (a limp leg flopping: 0.3-0.4 s, as an arm)
LANDED_MARGIN = 2  # frames: a leg laid as he lands may rise until this long before the trunk is down (the
# check's rest_rise_cm from its rest frame: the pins after the settle may move the head a little)
FACE_DOWN = 0.5  # cosine: the pelvis' front points down at least this much
HEAD_CLEARANCE = 0.3  # cm: the head's lowest node stops this far above the ground
SLIDE_CM = 2.0  # cm: a node on the ground before and after may move this far (the check: feet 2, others 3)
PENALTY = 50.0  # per cm into the ground, the body or the rifle
MOVE_COST = 0.01  # per degree moved: of two equally low shapes the nearer one
HEAD_DOFS = ("vt4", "vt3", "vt2", "vt1", "neck", "head")  # the upper back gives a little too
ARM_PARTS = ("_forearm", "_hand", "_upper_arm")  # what the head may come to rest on, but not go into
FACE_UP = 0.3  # cosine: the pelvis' front points up at least this much (kfire2dead: half on his side)
ARM_DOFS = ("clavicle", "shoulder", "elbow", "wrist")
SUPINE = 0.7  # the shoulders' line at least this level: on his back, an arm's own side is clear
ARM_FALL_SECONDS = 0.4  # s: a dead arm drops to the ground as the body lands (a limp arm swinging down
# from the shoulder: 0.3-0.4 s); kfire2dead: 0.8 s, after the physics, 1.5 s after he lay still
ARM_CLEARANCE = 0.3  # cm: an arm's lowest node stops this far above the ground
HEADWARD_FALL_SECONDS = 0.6  # s: an arm laid anew from over the head (_relaid) falls further, across the
# chest (kfire2dead's top arm in 0.4 s: its shoulder turned 20.9 degrees in a frame)
HEADWARD_STILL_SECONDS = 0.6  # s: and the clip ends this long after it lands (the slaves' trunk rest eases in
# over the clip's last 0.5 s, slave_rest.EASE_FRAMES: kfire2dead's DI, its trunk turned while the arm swung
# down, slid its chest 3.35 cm and ended moving its right hand at 0.51 m/s)
EARLY_LONGER = 1.5  # an arm let go early (ArmsFall.early_s) falls this many times the lead longer (it lands
# half the lead later, within the check's limb_rest_lag_s of the trunk at rest: kfire2dead 0.2 s)
FALL_POWER = 1.8  # the fall's easing: smoothstep(s ** FALL_POWER), fast late, landing softly
# degrees: the clavicle's two, the shoulder's three and the elbow's first angles tried for a fallen arm (a
# grid: its best shapes are starts; the top arm of a body half on his side lies low only with the shoulder
# dropped)
ARM_GRID = ((-10.0, 40.0), (-25.0, 25.0), (-15.0, 20.0, 60.0, 100.0), (-30.0, 0.0, 30.0, 60.0, 90.0),
            (-60.0, 0.0, 60.0), (0.0, 45.0, 90.0))  # fmt: skip
# the wider grid of an arm kept from over the head (_Body.headward_cm): half on his side, kfire2dead's top arm
# reaches the ground only across his chest, the shoulder turned in past ARM_GRID's (28 -> 12 cm up)
HEADWARD_GRID = ((-10.0, 40.0), (-25.0, 25.0), (-15.0, 45.0, 75.0, 105.0, 135.0, 165.0),
                 (-60.0, -30.0, 0.0, 30.0, 60.0, 90.0), (-90.0, -45.0, 0.0, 45.0, 90.0),
                 (0.0, 50.0, 100.0))  # fmt: skip
MEAN_WEIGHT = 0.2  # of the arm nodes' mean height (besides the highest part's lowest node): lie flat
ARM_STARTS = 2  # the grid's best shapes that Powell starts from (with the arm's own pose)
SIDES = ("left", "right")
SIDE_ORDERS = (SIDES, SIDES[::-1])  # the arms fall one after the other: both tried
LEG_DOFS = ("hip", "knee", "ankle", "toes")
# degrees, per DOF of LEG_DOFS (hip: abduction, flexion, turn about the thigh; knee; ankle: pointing,
# eversion; toes): the first search's grid, the hip's first two about the leg's own pose, None its own angle
LEG_GRID = ((-8.0, 0.0, 8.0), (-8.0, 0.0, 8.0), (-45.0, -30.0, -15.0, 0.0), (0.0, 10.0, 20.0), (-50.0,),
            (0.0, 15.0, 30.0), (None,))  # fmt: skip
LEG_STEP = 8.0  # degrees: then a pattern search from the best, each DOF -step or +step, halving the step
LEG_STEP_MIN = 0.5  # ... down to this
LEG_CHECKS = 24  # the settle is checked at this many even steps of its progress (it is linear in the angles)
LEG_SLIDE_CM = 0.5  # cm: a leg node on the ground at two checks may be this far apart (its run on the
# ground began in the fall: the check judges the run's whole extent)


@dataclass(frozen=True)
class ArmsFall:
    """How a body on its back lets its arms fall: how far a fallen arm may reach past the shoulders toward
    the head (cm, ``DeathSpec.arms_headward_cm``; None: anywhere) and how long before the body is down they
    go (s, ``DeathSpec.arms_fall_early_s``: their fall lasts :data:`EARLY_LONGER` times that longer)."""

    headward_cm: float | None = None
    early_s: float = 0.0
    seconds: float | None = None  # s: an arm not laid anew falls this long (None: ARM_FALL_SECONDS)
    still_s: float | None = None  # s: the clip ends this long after the arms land (None: STILL_SECONDS)
    low_air: bool = False  # face down and propped: the arms held low in the air (dead_prone.lowered)
    # face down and propped: the legs laid as the chest comes down drag no node lifting off the ground
    # (_Body.lift_off, DeathSpec.legs_lift_off)
    legs_lift_off: bool = False


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
        self.q, self.root, self.rifle = q, root, rifle
        rnodes, rsegs = figs.nodes("rifle")
        rg = figs.kin["rifle"].segment_globals(np.zeros(figs.kin["rifle"].ndof), rifle)
        self.rifle_points = np.einsum("kij,kj->ki", rg[rsegs, :3, :], rnodes)
        self.points = self.heights(q)[1]
        self.planted = self.points[:, 1] <= CONTACT_HEIGHT_CM
        self.shoulders, self.leftward = _body_axes(self.kin, q, root)
        self.way_checked = False  # a fallen arm's search weighs how far its way lifts it
        # cm: how far a fallen arm's forearm and hand may reach past the shoulders toward the head (None:
        # anywhere; :meth:`_Arm.overhead`)
        self.headward_cm: float | None = None
        self.headward = _headward(self.kin, q, root)
        # a leg node on the ground stays there until it rises past the check's LIFT_OFF_CM (dead_legs; False:
        # once above CONTACT_HEIGHT_CM it is free): DeathSpec.legs_lift_off
        self.lift_off = False

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


def _body_axes(kin, q: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point between the shoulders and the body's left (horizontal, unit; zero unless he lies on his
    back: :data:`SUPINE`)."""
    s = kin.site_globals(q, root)[:, :3, 3]
    left, right = (s[kin.site_names.index(f"{side}_upper_arm.proximal")] for side in ("left", "right"))
    flat = (left - right) * np.array([1.0, 0.0, 1.0])
    norm = float(np.linalg.norm(flat))
    side = flat / norm if norm >= SUPINE * float(np.linalg.norm(left - right)) else np.zeros(3)
    return (left + right) / 2.0, side


def _headward(kin, q: np.ndarray, root: np.ndarray) -> np.ndarray:
    """The unit direction from the pelvis to the point between the shoulders (up the spine)."""
    s = kin.site_globals(q, root)[:, :3, 3]
    shoulders = sum(s[kin.site_names.index(f"{side}_upper_arm.proximal")] for side in ("left", "right")) / 2
    up = shoulders - kin.segment_globals(q, root)[kin.segment_names.index("lower_torso")][:3, 3]
    return up / np.linalg.norm(up)


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


class _Leg:
    """One leg of a face-down body, to roll out with its heel low: for many shapes at once (its hip, knee,
    ankle and toe angles), the check's ``rest_foot_cm`` (the higher of the heel site and the foot's lowest
    node) and how far the shape goes wrong (into the ground, or a node on the ground sliding)."""

    def __init__(self, body: _Body, side: str) -> None:
        kin = body.kin
        self.body, self.kin = body, kin
        self.idx = _dofs(kin, tuple(f"{side}_{j}" for j in LEG_DOFS))
        moved = [i for i, n in enumerate(kin.segment_names) if n.startswith(side) and _leg_segment(n)]
        self.nodes = np.flatnonzero(np.isin(body.segs, moved))
        self.foot = body.parts[self.nodes] == f"{side}_foot"
        self.foot_seg = kin.segment_names.index(f"{side}_foot")
        g = kin.segment_globals(body.q, body.root)[self.foot_seg]
        site = kin.site_globals(body.q, body.root)[kin.site_names.index(f"{side}_foot.heel")]
        self.heel = (np.linalg.inv(g) @ site)[:, 3]  # the heel in the foot's frame
        self.x0 = body.q[self.idx]
        self.start = body.points[self.nodes]
        self.planted = body.planted[self.nodes]
        self.floor = min(0.0, float(body.points[:, 1].min()))  # what lay that deep already is not counted

    def _shape(self, x: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
        q = np.repeat(self.body.q[None], len(x), axis=0)
        q[:, self.idx] = self.x0 + u * (x - self.x0)
        root = np.repeat(self.body.root[None], len(x), axis=0)
        g = self.kin.segment_globals(q, root)
        pts = np.einsum("mkij,kj->mki", g[:, self.body.segs[self.nodes], :3, :], self.body.nodes[self.nodes])
        heel = g[:, self.foot_seg, 1, :] @ self.heel
        return pts, heel

    def cost(self, x: np.ndarray) -> np.ndarray:
        """Per shape of ``x`` ``(m, dofs)``: heel height + :data:`PENALTY` per cm wrong + the move."""
        m = len(x)
        at, down = [np.repeat(self.start[None], m, axis=0)], [np.repeat(self.planted[None], m, axis=0)]
        for u in np.arange(1, LEG_CHECKS + 1) / LEG_CHECKS:
            pts, heel = self._shape(x, u)
            at.append(pts)
            down.append(pts[..., 1] <= CONTACT_HEIGHT_CM)
        wrong = np.maximum(0.0, self.floor - np.min([p[..., 1].min(axis=1) for p in at], axis=0))
        wrong += np.maximum(0.0, _slid(np.stack(at), np.stack(down)) - LEG_SLIDE_CM)
        high = np.maximum(heel, pts[:, self.foot, 1].min(axis=1))
        move = MOVE_COST * np.degrees(np.abs(x - self.x0)).sum(axis=1)
        return high + PENALTY * wrong + move


def _slid(at: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Per shape, the farthest (cm, horizontally) any node lies apart at two checks it is on the ground at;
    ``at`` ``(checks, m, k, 3)``, ``down`` ``(checks, m, k)``."""
    touching = down.any(axis=(0, 1))
    xz, down = at[..., touching, :][..., [0, 2]], down[..., touching]
    out = np.zeros(at.shape[1])
    for i in range(len(xz) - 1):
        d = np.hypot(*(xz[i + 1 :] - xz[i]).transpose(3, 0, 1, 2)) * (down[i + 1 :] & down[i])
        out = np.maximum(out, d.max(axis=(0, 2), initial=0.0))
    return out


def _leg_segment(name: str) -> bool:
    return name.split("_", 1)[1].startswith(("upper_leg", "lower_leg", "foot", "toes"))


def limp_leg(body: _Body, side: str) -> np.ndarray:
    """The ``side`` leg's hip, knee, ankle and toe angles that lay its heel lowest, into neither the ground
    nor sliding a node on the ground (checked at :data:`LEG_CHECKS` steps of the settle): the best of
    :data:`LEG_GRID` and the leg's own pose, then a pattern search from it (:data:`LEG_STEP`)."""
    leg = _Leg(body, side)
    grid = np.array(list(itertools.product(*LEG_GRID)), dtype=np.float64)  # None: nan
    grid = np.where(np.isnan(grid), leg.x0, np.radians(grid))
    grid[:, :2] += leg.x0[:2]
    return pattern_search(leg, leg.cost, grid)


def pattern_search(leg: _Leg, cost: Callable[[np.ndarray], np.ndarray], grid: np.ndarray) -> np.ndarray:
    """The lowest-``cost`` leg shape: the best of ``grid`` and the leg's own pose (within its limits), then
    a pattern search from it, each angle :data:`LEG_STEP` either way, halving the step."""
    lo, hi = leg.kin.lower[leg.idx], leg.kin.upper[leg.idx]
    shapes = np.clip(np.vstack([leg.x0[None], grid]), lo, hi)
    costs = cost(shapes)
    k = int(np.argmin(costs))
    best, best_cost = shapes[k], float(costs[k])
    around = np.vstack([np.eye(len(leg.idx)), -np.eye(len(leg.idx))])
    step = LEG_STEP
    while step >= LEG_STEP_MIN:
        shapes = np.clip(best + np.radians(step) * around, lo, hi)
        costs = cost(shapes)
        k = int(np.argmin(costs))
        if costs[k] < best_cost - 1e-6:
            best, best_cost = shapes[k], float(costs[k])
        else:
            step /= 2.0
    return best


def _leg_dofs(kin) -> np.ndarray:
    return _dofs(kin, tuple(f"{side}_{j}" for side in ("left", "right") for j in LEG_DOFS))


def _legs_path(
    body: _Body, t: np.ndarray, u: np.ndarray, free: float = 0.0, slack_feet: bool = False
) -> np.ndarray:
    """Both legs' angles (:func:`_leg_dofs` order) at ``t`` of the settle, turned out and laid down
    (:mod:`authoring.dead_legs`; a leg that cannot be lifted clear goes limp at progress ``u``; a leg point
    may rise before ``free``, the body still landing)."""
    from authoring import dead_legs

    return dead_legs.legs_path(body, t, u, free, slack_feet)


def _face_up(kin, q: np.ndarray, root: np.ndarray) -> bool:
    g = kin.segment_globals(q, root)[kin.segment_names.index("lower_torso")]
    return float(g[1, 2]) <= -FACE_UP


class _Arm:
    """One arm of a body on its back, to lay on the ground: how high its parts lie in a shape ``x`` of its
    clavicle, shoulder, elbow and wrist angles, and how far that shape goes wrong."""

    def __init__(self, body: _Body, side: str, clearance: float | None = None) -> None:
        self.body, self.side = body, side
        self.idx = _dofs(body.kin, tuple(f"{side}_{j}" for j in ARM_DOFS))
        parts = body.parts
        self.arm = np.array([str(p).startswith(side) and str(p).endswith(ARM_PARTS) for p in parts])
        arm_segs = np.unique(body.segs[self.arm])
        others = np.setdiff1d(np.unique(body.segs[~self.arm]), arm_segs)
        self.rest = SegmentHulls.build(body.nodes, body.segs, others)
        self.hulls = SegmentHulls.build(body.nodes, body.segs, arm_segs)
        self.lower = np.array([str(p) in (f"{side}_hand", f"{side}_forearm") for p in parts])
        self.limb = [parts == f"{side}{part}" for part in ARM_PARTS]
        self.hand = parts == f"{side}_hand"
        self.x0 = body.q[self.idx]
        p0, self.inside0 = self.into(self.x0)  # what lay that deep (or that low) already is not counted
        self.clearance = min(ARM_CLEARANCE, float(p0[self.arm, 1].min())) if clearance is None else clearance

    def pose(self, x: np.ndarray) -> np.ndarray:
        q = self.body.q.copy()
        q[self.idx] = x
        return q

    def into(self, x: np.ndarray) -> tuple[np.ndarray, float]:
        """The body's nodes in shape ``x`` and how deep (cm) the forearm and hand go into the rest of the
        body plus how deep the rifle goes into the arm."""
        g, p = self.body.heights(self.pose(x))
        d_body, _, _ = self.rest.depth(p[None, self.lower], g[None])
        d_rifle, _, _ = self.hulls.depth(self.body.rifle_points[None], g[None])
        return p, d_body + d_rifle

    def terms(self, x: np.ndarray) -> tuple[float, float, float]:
        """The highest part's lowest node (as the check sees it), the arm nodes' mean height, and cm wrong."""
        p, inside = self.into(x)
        low = float(p[self.arm, 1].min())
        wrong = max(0.0, self.clearance - low) + max(0.0, inside - self.inside0)
        wrong += self.body.misplaced(self.pose(x)) + self.astray(p) + self.overhead(p)
        if self.body.way_checked:  # its way down lifts no part of it (authoring.dead_arms)
            wrong += max(0.0, dead_arms.straight_rise(self, x) - dead_arms.RISE_OK_CM)
        return max(float(p[m, 1].min()) for m in self.limb), float(p[self.arm, 1].mean()), wrong

    def astray(self, p: np.ndarray) -> float:
        """cm the hand lies across the body's middle, on his back: a dead arm falls to its own side
        (kstow2dead's left forearm, over the chest, laid on the far side rose 40 cm on its way)."""
        hand = p[self.hand].mean(axis=0)
        across = float(np.dot(self.body.shoulders - hand, self.body.leftward))
        return max(0.0, across if self.side == "left" else -across)

    def overhead(self, p: np.ndarray) -> float:
        """cm the forearm and hand reach past the shoulders toward the head beyond the body's
        :attr:`_Body.headward_cm`: half on his side, kfire2dead's top arm lay lowest curled over his head,
        its elbow up by the head and the hand over the crown (not how a dead man's arm lies)."""
        if self.body.headward_cm is None:
            return 0.0
        reach = (p[self.lower] - self.body.shoulders) @ self.body.headward
        return max(0.0, float(reach.max()) - self.body.headward_cm)

    def cost(self, x: np.ndarray) -> float:
        high, mean, wrong = self.terms(x)
        move = MOVE_COST * float(np.degrees(np.abs(x - self.x0)).sum())
        return high + MEAN_WEIGHT * mean + PENALTY * wrong + move


def fallen_arm(body: _Body, side: str) -> np.ndarray:
    """The ``side`` arm's angles that lay it lowest, into neither the ground, the rest of the body nor the
    rifle, sliding nothing on the ground (from its own pose and the best of :data:`ARM_GRID`; an arm kept
    from over the head, :attr:`_Body.headward_cm`, from :data:`HEADWARD_GRID`'s best too, and no worse than
    its best start: bounded Powell's line searches can end above where they began, 19 -> 35)."""
    arm = _Arm(body, side)
    lo, hi = body.kin.lower[arm.idx], body.kin.upper[arm.idx]
    starts = [arm.x0, *_grid_starts(body.kin, side, arm.x0, arm.cost)]
    if body.headward_cm is None:
        return _minimise(arm.cost, starts, lo, hi)
    starts += _grid_starts(body.kin, side, arm.x0, arm.cost, HEADWARD_GRID)
    return min([_minimise(arm.cost, starts, lo, hi), *(np.clip(x, lo, hi) for x in starts)], key=arm.cost)


def _grid_starts(
    kin, side: str, x0: np.ndarray, cost: Callable[[np.ndarray], float], grid_deg: tuple = ARM_GRID
) -> list[np.ndarray]:
    """The :data:`ARM_STARTS` lowest arm shapes of ``grid_deg`` (:data:`ARM_GRID`; the wrist and the elbow's
    second angle as they are): a forearm standing up by the head may lie best beside or across the body."""
    base = kin.dof_slices[f"{side}_clavicle"].start
    grid = [kin.dof_slices[f"{side}_{j}"].start - base for j in ("clavicle", "shoulder", "elbow")]
    at = np.array([grid[0], grid[0] + 1, grid[1], grid[1] + 1, grid[1] + 2, grid[2]])
    shapes: list[tuple[float, int, np.ndarray]] = []
    for angles in itertools.product(*grid_deg):
        x = x0.copy()
        x[at] = np.radians(angles)
        shapes.append((cost(x), len(shapes), x))
    return [x for _, _, x in sorted(shapes, key=lambda t: t[:2])[:ARM_STARTS]]


def limp_target(figs: FigureSet, frames: ClipFrames) -> np.ndarray | None:
    """The limp shape the last frame of a body on its front settles into (the head dropped), or None if it
    does not lie on its front. The legs are left as they are: :func:`settle` lays them along their own path
    (:func:`_legs_path`), so searching their end here too was done twice."""
    q, root, rifle = frames.poses[-1], frames.roots[-1], frames.rifles[-1]
    body = _Body(figs, q, root, rifle)
    if not _face_down(body.kin, q, root):
        return None
    target = q.copy()
    target[_dofs(body.kin, HEAD_DOFS)] = dropped_head(body)
    return target


def _fallen(figs: FigureSet, body: _Body) -> tuple[np.ndarray, tuple[str, ...]]:
    """The pose of ``body`` (on his back) with both arms fallen, the lower of :data:`SIDE_ORDERS`, and the
    sides laid anew: with :attr:`_Body.headward_cm`, an arm that lies over the head so is laid again against
    the other where it lies (:func:`_relaid`)."""
    target = min((_fallen_arms(figs, body, order) for order in SIDE_ORDERS), key=lambda t: t[0])[1]
    return (target, ()) if body.headward_cm is None else _relaid(figs, body, target)


def _relaid(figs: FigureSet, start: _Body, target: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """``target`` with each arm that reaches over the head (:meth:`_Arm.overhead`) laid anew from its pose in
    ``start`` against the rest of ``target``, and those sides: the other arm lies as the usual search laid it
    (kfire2dead's bottom arm, laid anew with both arms, swept his upper arm 3.9 cm along the ground as he
    landed, and the turn that followed slid his belly 3.96 cm and a foot 3.31)."""
    sides: list[str] = []
    for side in SIDES:
        idx = _dofs(start.kin, tuple(f"{side}_{j}" for j in ARM_DOFS))
        q = target.copy()
        q[idx] = start.q[idx]
        body = _Body(figs, q, start.root, start.rifle)
        body.headward_cm = start.headward_cm
        body.way_checked = bool(body.leftward.any())
        arm = _Arm(body, side)
        if arm.overhead(arm.into(target[idx])[0]) > 0.0:
            target = target.copy()
            target[idx] = fallen_arm(body, side)
            sides.append(side)
    return target, tuple(sides)


def _fallen_arms(figs: FigureSet, start: _Body, order: tuple[str, str]) -> tuple[float, np.ndarray]:
    """Both arms of ``start``'s body fallen, the first of ``order`` first and the second against it where it
    lies: the higher arm's highest part (cm, as the check sees it) and the pose."""
    body = _Body(figs, start.q, start.root, start.rifle)
    body.way_checked = bool(body.leftward.any())  # on his back (half on his side, checked, kfire2dead's top
    # arm's lowest shapes lay over the head only, and it stayed 27 cm up: its way is bent afterwards instead)
    target = body.q.copy()
    for side in order:
        target[_dofs(body.kin, tuple(f"{side}_{j}" for j in ARM_DOFS))] = fallen_arm(body, side)
        body.q = target.copy()
    arms = [_Arm(body, side) for side in order]
    return max(arm.terms(arm.x0)[0] for arm in arms), target


def fall_easing(s: np.ndarray) -> np.ndarray:
    """A dropped limb's progress at ``s`` in [0, 1]: slow to start, fastest late, landing softly."""
    v = s**FALL_POWER
    return v * v * (3.0 - 2.0 * v)


def settle(
    frames: ClipFrames,
    soldier: Figure,
    rifle: Figure,
    arms_fall: bool = False,
    propped: bool = False,
    legs: bool = True,
    slack_feet: bool = False,
    arms: ArmsFall | None = None,
) -> ClipFrames:
    """``frames`` with the limp settle appended (see the module docstring); unchanged if not face down (or,
    with ``arms_fall``, face up). A prone death (``propped``) left propped on its arms brings its chest down
    (:mod:`authoring.dead_prone`; :func:`lowered_early`: as he is hit); a body on its back (``arms_fall``)
    lets its arms fall as it lands (:func:`_arms_fall`). A face-down body's legs are laid as it lands
    (:func:`_legs_land`); ``legs`` False: they stay as the physics laid them (``DeathSpec.legs_settle``);
    ``arms``: how the arms fall on his back, or go through the air propped (:class:`ArmsFall`; None: the
    defaults)."""
    figs = FigureSet({"body": soldier, "rifle": rifle})
    low_air, lift_off = arms is not None and arms.low_air, arms is not None and arms.legs_lift_off
    lowered = _lowered(figs, frames, slack_feet, low_air=low_air, lift_off=lift_off) if propped else None
    if lowered is not None:
        return _appended(frames, lowered)
    kin, last = figs.kin["body"], frames.poses[-1]
    if arms_fall and not _face_down(kin, last, frames.roots[-1]) and _face_up(kin, last, frames.roots[-1]):
        return _arms_fall(figs, frames, arms or ArmsFall())
    target = limp_target(figs, frames)
    if target is None:
        return frames
    n = round(SETTLE_SECONDS * frames.fps)
    s = np.arange(1, n + 1) / n
    still = np.ones(round(STILL_SECONDS * frames.fps))
    u = np.concatenate([s * s * (3.0 - 2.0 * s), still])
    poses = last[None] + u[:, None] * (target - last)[None]
    leg_dofs = _leg_dofs(kin)
    poses[:, leg_dofs] = last[leg_dofs]
    out = _appended(frames, poses)
    return _legs_land(figs, out, down_frame(figs, frames), len(frames.poses) - 1) if legs else out


def legs_landed_from(frames: ClipFrames, soldier: Figure, rifle: Figure, k0: int, end: int) -> ClipFrames:
    """``frames`` (settled without its legs, the physics ending at frame ``end``) with the legs laid as he
    lands (:func:`_legs_land`) from frame ``k0``, as his knees land (``DeathSpec.legs_land_from``), not
    once he is down: a leg may rise only until the check judges the rest from (:func:`checked_down`).
    Laid once he was down, stfire2dead's lifted legs rose 6.9 cm at the knee after it (rest_rise_cm)."""
    figs = FigureSet({"body": soldier, "rifle": rifle})
    if not _face_down(figs.kin["body"], frames.poses[end], frames.roots[end]):
        return frames  # (as settle: only a body on its front)
    return _legs_land(figs, frames, k0, end, checked_down(figs, frames) - LANDED_MARGIN)


def _legs_land(
    figs: FigureSet, frames: ClipFrames, k0: int, end: int, landed: int | None = None
) -> ClipFrames:
    """The legs of a face-down body lifted, turned out and laid down (:func:`_legs_path`, found on the
    physics' last frame ``end``) as it lands: from the frame it is down (``k0``, :func:`down_frame`) in
    :data:`LEGS_LAND_SECONDS`, the physics' own leg motion kept under it (appended after the physics, the
    feet moved 1.2 s after the trunk lay still: stfire2dead's ``limb_rest_lag_s`` 1.18). Until
    :data:`LANDED_MARGIN` frames before the check's rest frame (the pelvis, chest and head down within
    :data:`~authoring.quality_rest.DOWN_CM`; or until ``landed``) a leg may rise
    (:func:`authoring.dead_legs.leg_settle`'s ``free``)."""
    last = frames.poses[end]
    body = _Body(figs, last, frames.roots[end], frames.rifles[end])
    leg_dofs = _leg_dofs(body.kin)
    n = round(LEGS_LAND_SECONDS * frames.fps)
    k0 = min(k0, len(frames.poses) - 1 - n)  # laid by the end of the clip
    s = np.arange(1, n + 1) / n
    if landed is None:  # (the check's rest_rise_cm once judged from then)
        landed = _rest_frame(figs, frames, DOWN_CM) - LANDED_MARGIN
    path = _legs_path(body, s, smoothstep(s), min(1.0, max(0.0, (landed - k0) / n)))
    k = len(frames.poses) - k0 - 1
    shift = np.vstack([path, np.repeat(path[-1:], max(0, k - n), axis=0)])[:k] - last[leg_dofs]
    poses = frames.poses.copy()
    poses[k0 + 1 :, leg_dofs] += shift
    return ClipFrames(poses, frames.roots, frames.rifles, frames.fps)


def down_frame(figs: FigureSet, frames: ClipFrames) -> int:
    """The first frame from which the body is down, as the check sees it (``limb_rest_lag_s``: the pelvis,
    chest or belly and head within :data:`authoring.quality_rest.NEAR_CM` of where they finally lie); the
    last frame if it never is."""
    return _rest_frame(figs, frames, NEAR_CM)


def checked_down(figs: FigureSet, frames: ClipFrames) -> int:
    """The frame the check's ``rest_rise_cm`` judges from (:func:`authoring.quality_rest.down_frame`: the
    pelvis, chest or belly and head first within :data:`~authoring.quality_rest.NEAR_CM` of where they
    finally lie, the pelvis no longer rolling); the last frame if they never are."""
    k = quality_rest.down_frame(
        _torso_heights(figs, frames), turned=pelvis_turns(figs.kin["body"], frames.poses, frames.roots)
    )
    return len(frames.poses) - 1 if k is None else k


def _torso_heights(figs: FigureSet, frames: ClipFrames) -> dict[str, np.ndarray]:
    """Per frame, the heights (cm) of the pelvis', chest's, belly's and head's lowest nodes."""
    kin = figs.kin["body"]
    nodes, segs = figs.nodes("body")
    parts = figs.node_parts("body")
    y = np.einsum("nkj,kj->nk", kin.segment_globals(frames.poses, frames.roots)[:, segs, 1, :], nodes)
    return {p: y[:, parts == p].min(axis=1) for p in TORSO_PARTS if (parts == p).any()}


def _rest_frame(figs: FigureSet, frames: ClipFrames, near: float) -> int:
    """The first frame from which the pelvis, chest or belly and head stay within ``near`` (cm) of where
    they finally lie (:func:`authoring.quality_rest.rest_frame`); the last frame if they never do."""
    k = rest_frame(_torso_heights(figs, frames), near)
    return len(frames.poses) - 1 if k is None else k


def _arms_fall(figs: FigureSet, frames: ClipFrames, fall: ArmsFall) -> ClipFrames:
    """A body on its back lets its arms fall as it lands: from the frame it is down (:func:`down_frame`)
    each arm falls, in :data:`ARM_FALL_SECONDS`, to the shape :func:`fallen_arm` lays it in (found on the
    last frame's body with the arms as they were then), along a way bent so that no part of it rises
    (:mod:`authoring.dead_arms`), the physics' own arm motion fading out of it; the rest of the body goes on
    as the physics has it, and the clip ends still (:data:`STILL_SECONDS` after the arms land, or where the
    physics ended). Started after the physics had ended (1.5 s after he lay still), kfire2dead's top arm was
    held up in the air and lowered: a dead man holding up his arm. An arm laid anew from over the head
    (``fall.headward_cm``, :func:`_relaid`) falls in :data:`HEADWARD_FALL_SECONDS` from its pose as he came
    down. ``fall.early_s``: the arms go that long before he is down (their own motion until then), their
    fall :data:`EARLY_LONGER` times that longer; ``fall.seconds``: an arm not laid anew falls that long;
    ``fall.still_s``: the clip ends that long after the arms land.
    """
    kin = figs.kin["body"]
    k0 = down_frame(figs, frames)
    arms = _dofs(kin, tuple(f"{side}_{j}" for side in ("left", "right") for j in ARM_DOFS))
    held = frames.poses[-1].copy()
    held[arms] = frames.poses[k0, arms]  # the arms as they were when he came down
    body = _Body(figs, held, frames.roots[-1], frames.rifles[-1])
    body.headward_cm = fall.headward_cm
    target, relaid = _fallen(figs, body)
    early = min(k0, round(fall.early_s * frames.fps))
    ks = k0 - early  # the arms go from here
    lengths = {
        s: round(
            (HEADWARD_FALL_SECONDS if s in relaid else fall.seconds or ARM_FALL_SECONDS) * frames.fps
            + EARLY_LONGER * early
        )
        for s in SIDES
    }
    still = round((HEADWARD_STILL_SECONDS if relaid else fall.still_s or STILL_SECONDS) * frames.fps)
    extra = max(0, ks + max(lengths.values()) + still + 1 - len(frames.poses))
    out = _appended(frames, np.repeat(frames.poses[-1:], extra, axis=0))
    poses = out.poses.copy()
    for side, n in lengths.items():
        u = np.concatenate([fall_easing(np.arange(1, n + 1) / n), np.ones(len(out.poses) - ks - 1 - n)])
        arm = _Arm(body, side)
        x1 = target[arm.idx]
        c = dead_arms.control_pose(arm, x1, _minimise)
        x0 = out.poses[ks + 1 :, arm.idx].copy()
        if side in relaid:  # a relaid arm's own motion after he is down left out: kfire2dead's top arm, still
            # sinking 2 cm as its way rose over his chest, rose 3.5 cm
            x0[early:] = arm.x0
        poses[ks + 1 :, arm.idx] = dead_arms.bent(x0, c, x1, u)
    return ClipFrames(poses, out.roots, out.rifles, out.fps)


def _lowered(
    figs: FigureSet,
    frames: ClipFrames,
    slack_feet: bool = False,
    at: int = -1,
    level: bool = False,
    low_air: bool = False,
    lift_off: bool = False,
) -> np.ndarray | None:
    """The settle poses of a face-down body left propped on its arms (:mod:`authoring.dead_prone`) from
    its frame ``at`` (the rifle where it finally lies; ``level``: its arms lifted no higher than just clear;
    ``lift_off``: :attr:`_Body.lift_off`), then still; None if it is not."""
    from authoring import dead_prone

    q, root = frames.poses[at], frames.roots[at]
    body = _Body(figs, q, root, frames.rifles[-1])
    if not _face_down(body.kin, q, root):
        return None
    body.lift_off = lift_off
    n = round(SETTLE_SECONDS * frames.fps)
    t = np.arange(1, n + 1) / n
    legs = _legs_path(body, t, dead_prone.torso_progress(t), slack_feet=slack_feet)  # a limp leg goes as the
    # torso comes down
    poses = dead_prone.lowered(body, n, level, low_air)
    poses[:, _leg_dofs(body.kin)] = legs
    return np.concatenate([poses, np.repeat(poses[-1:], round(STILL_SECONDS * frames.fps), axis=0)])


def _appended(frames: ClipFrames, poses: np.ndarray) -> ClipFrames:
    """``frames`` and then ``poses``, the body and the rifle staying where they lie."""
    k = len(poses)
    return ClipFrames(
        np.concatenate([frames.poses, poses]),
        np.concatenate([frames.roots, np.repeat(frames.roots[-1:], k, axis=0)]),
        np.concatenate([frames.rifles, np.repeat(frames.rifles[-1:], k, axis=0)]),
        frames.fps,
    )


def lowered_early(
    frames: ClipFrames,
    soldier: Figure,
    rifle: Figure,
    k0: int,
    slack_feet: bool = False,
    level: bool = False,
) -> ClipFrames | None:
    """A propped face-down body's chest brought down (as :func:`settle` does) from frame ``k0`` of the
    physics ``frames`` on (:func:`_cut_short`; ``level``: ``DeathSpec.arms_lifted_level``); None if not face
    down there (the caller settles after the physics, as without ``DeathSpec.lowered_at``: the tail cut
    short and no settle at all, on main)."""
    figs = FigureSet({"body": soldier, "rifle": rifle})
    end = k0 + 1 + round((SETTLE_SECONDS + STILL_SECONDS) * frames.fps)  # the rifle too lies still from then
    # (prstow2dead's, rocking on the ground until 2.9 s: the pins eased a still arm back as the clip ended)
    frames = ClipFrames(frames.poses[:end], frames.roots[:end], frames.rifles[:end], frames.fps)
    lowered = _lowered(figs, frames, slack_feet, k0, level)
    return None if lowered is None else _cut_short(frames, lowered, k0)


def _cut_short(frames: ClipFrames, poses: np.ndarray, k0: int) -> ClipFrames:
    """The body of ``frames`` to frame ``k0``, then the settle ``poses`` found there, the root held; the
    rifle as the physics has it, then where it lies; as long as the longer. A prone death's physics leaves
    him propped on his elbows until the body and the rifle are still (prstow2dead: 2.9 s, the let-go rifle
    rocking on the ground): his chest comes down as he is hit instead."""
    m = max(k0 + 1 + len(poses), len(frames.poses))
    body = np.concatenate([frames.poses[: k0 + 1], poses])
    return ClipFrames(
        np.concatenate([body, np.repeat(body[-1:], m - len(body), axis=0)]),
        np.concatenate([frames.roots[: k0 + 1], np.repeat(frames.roots[k0 : k0 + 1], m - k0 - 1, axis=0)]),
        np.concatenate([frames.rifles, np.repeat(frames.rifles[-1:], m - len(frames.rifles), axis=0)]),
        frames.fps,
    )
