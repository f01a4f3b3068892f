"""A face-down dead body's legs roll out and the feet lie on their sides, heels down (issue 14).

The ragdoll leaves a face-down body on its toes, the ankles at soldier.fig's pointing limit (-50 deg), the
heels 19-22 cm up. A dead prone body's legs roll outward (hip external rotation), each foot lying on its
inner edge, heel low and turned in. Turned so where it lies, a leg rolls its thigh and drags its toes over
the ground (:func:`authoring.dead_settle.limp_leg` could lower the heels only 1-2 cm that way). So each leg
is **lifted, turned and laid down**: the shape that lays its heel lowest within the figure's limits, into
no ground (:func:`turned_leg`, the legs' angles searched freely: hip, knee, ankle, toes), reached on a path
(:func:`leg_path`) that first extends the hip (the knee and foot rise off the ground, :data:`LIFTS`),
turns the leg in the air and lowers it into place, so the toes leave the ground and the foot lands, nothing
skidding. A lift that would still slide a node on the ground (the thigh by the groin rolls) more than
:data:`LEG_SLIDE_CM` is tried smaller and larger (:data:`LIFTS`); a leg no lift clears keeps the limp
settle of :func:`authoring.dead_settle.limp_leg`.

soldier.fig's limits leave the heels 12.4-15.7 cm up (hip turned out 45 deg, foot everted 30 deg, ankle
pointed 50 deg, the knee bent so the foot rests on its inner edge; or turned in 40 deg on the outer edge):
the hip's 45 deg of outward turn keeps the foot off its side. A passive ankle range of 65 deg would give
11.6-12.9 cm, and that with the hip turned out 60 deg 9.3-10.6 cm (measured on ststow2dead, prstow2dead).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from authoring import dead_settle as ds
from authoring.body_parts import contact_runs
from authoring.easing import _smoothstep
from authoring.quality import CONTACT_HEIGHT_CM, THRESHOLDS

HIP_FLEX = 1  # of a leg's angles (ds.LEG_DOFS order): the hip's second bends it (negative: the knee rises)
# degrees, per leg angle: the target search's grid (hip abduction and flexion about the leg's own, None its
# own angle); the hip turned both ways (soldier.fig: -45 out .. 40 in), the knee bent so the foot lies
LEG_GRID = ((-8.0, 0.0, 8.0), (-5.0, 0.0, 5.0, 10.0, 15.0), (-45.0, -30.0, 0.0, 20.0, 40.0),
            tuple(float(k) for k in range(0, 41, 4)), (-50.0, -25.0), (-20.0, 0.0, 15.0, 30.0),
            (None, -40.0, 0.0))  # fmt: skip
STARTS = 6  # the grid's best shapes a pattern search starts from (the hip turned out or in: two valleys)
LIFTS = (6.0, 7.0, 5.0, 8.0, 4.0)  # degrees of hip extension that lift the leg clear, tried in this order
FEET_UP_MARGIN = 2.0  # cm: the lifted foot stays this far under the check's feet_up_cm (foot over pelvis)
LIFT_SPAN = 0.3  # of the settle: the leg rises over the first this much and comes down over the last
LEG_SLIDE_CM = 1.5  # cm: the most a leg node on the ground may slide over the settle (the check allows 3
# over a node's whole run on the ground; the thigh by the groin rolls a little as the hip turns)
PATH_STEPS = 48  # the path is checked at this many even steps of the settle


def turned_leg(leg: ds._Leg) -> np.ndarray:
    """The leg's angles that lay its heel lowest (the check's ``rest_foot_cm``), into no ground, the move
    small: the best of :data:`LEG_GRID`, then a pattern search (no slide counted: :func:`leg_path` lifts
    the leg clear)."""

    def cost(x: np.ndarray) -> np.ndarray:
        pts, heel = leg._shape(x, 1.0)
        high = np.maximum(heel, pts[:, leg.foot, 1].min(axis=1))
        wrong = np.maximum(0.0, leg.floor - pts[..., 1].min(axis=1))
        return high + ds.PENALTY * wrong + ds.MOVE_COST * np.degrees(np.abs(x - leg.x0)).sum(axis=1)

    grid = np.array(list(itertools.product(*LEG_GRID)), dtype=np.float64)
    grid = np.where(np.isnan(grid), leg.x0, np.radians(grid))
    grid[:, :2] += leg.x0[:2]
    grid = np.clip(grid, leg.kin.lower[leg.idx], leg.kin.upper[leg.idx])
    starts = grid[np.argsort(cost(grid), kind="stable")[:STARTS]]
    shapes = np.array([ds.pattern_search(leg, cost, x[None]) for x in starts])
    return shapes[int(np.argmin(cost(shapes)))]


def progress(t: np.ndarray, lift: float) -> tuple[np.ndarray, np.ndarray]:
    """At ``t`` in [0, 1] of the settle: how far the leg has turned (eased between the lift and the landing)
    and how far (radians) its hip is extended, up over the first :data:`LIFT_SPAN` and down over the last."""
    turn = _smoothstep((t - LIFT_SPAN / 2) / (1.0 - LIFT_SPAN))
    up = _smoothstep(np.minimum(t, 1.0 - t) / LIFT_SPAN)
    return turn, np.radians(lift) * up


def leg_path(leg: ds._Leg, target: np.ndarray, t: np.ndarray, lift: float) -> np.ndarray:
    """The leg's angles at ``t`` of the settle: lifted by ``lift`` degrees of hip extension, turned, laid."""
    turn, up = progress(t, lift)
    x = leg.x0[None] + turn[:, None] * (target - leg.x0)[None]
    x[:, HIP_FLEX] -= up
    return x


def path_faults(leg: ds._Leg, path: np.ndarray) -> tuple[float, float, float]:
    """Over ``path`` (from the leg's pose where it lies): the farthest (cm) a leg node slides while on the
    ground (the check's contact runs), how deep (cm) it goes below the floor, and how high (cm) the foot's
    lowest node rises above the pelvis' (the check's ``feet_up_cm``)."""
    pts = np.concatenate([leg.start[None], leg._shape(path, 1.0)[0]])
    slide = contact_runs(pts, CONTACT_HEIGHT_CM).slide.max(initial=0.0)
    deep = max(0.0, leg.floor - float(pts[..., 1].min()))
    body = leg.body
    pelvis = float(body.points[body.parts == "pelvis", 1].min(initial=0.0))
    return float(slide), deep, float(pts[:, leg.foot, 1].min(axis=1).max()) - pelvis


@dataclass
class LegSettle:
    """How one leg settles: to ``target``, lifted clear by ``lift`` degrees of hip extension, or (``lift``
    None) the limp settle, linear in the angles."""

    leg: ds._Leg
    target: np.ndarray
    lift: float | None

    def path(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The leg's angles at ``t`` of the settle (the limp settle at progress ``u``)."""
        if self.lift is None:
            return self.leg.x0[None] + u[:, None] * (self.target - self.leg.x0)[None]
        return leg_path(self.leg, self.target, t, self.lift)


def leg_settle(body: ds._Body, side: str) -> LegSettle:
    """The ``side`` leg turned (:func:`turned_leg`) with the first of :data:`LIFTS` that reaches it sliding
    no node on the ground more than :data:`LEG_SLIDE_CM`, into no ground, the foot not lifted past the check's
    ``feet_up_cm``; else the limp settle
    (:func:`authoring.dead_settle.limp_leg`)."""
    leg = ds._Leg(body, side)
    target = turned_leg(leg)
    t = np.arange(1, PATH_STEPS + 1) / PATH_STEPS
    for lift in LIFTS:
        slide, deep, up = path_faults(leg, leg_path(leg, target, t, lift))
        if slide <= LEG_SLIDE_CM and deep <= 0.0 and up <= THRESHOLDS["feet_up_cm"] - FEET_UP_MARGIN:
            return LegSettle(leg, target, lift)
    return LegSettle(leg, ds.limp_leg(body, side), None)


def legs_path(body: ds._Body, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Both legs' angles (:func:`authoring.dead_settle._leg_dofs` order) at ``t`` of the settle (a limp
    leg at progress ``u``)."""
    return np.hstack([leg_settle(body, side).path(t, u) for side in ("left", "right")])
