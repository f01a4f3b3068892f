"""A face-down dead body's legs roll out and the feet lie on their sides, heels down (issue 14).

The ragdoll leaves a face-down body on its toes, the ankles at soldier.fig's pointing limit (-50 deg), the
heels 19-22 cm up. A dead prone body's legs roll outward (hip external rotation), each foot lying on its
inner edge, heel low and turned in. Turned so where it lies, a leg rolls its thigh and drags its toes over
the ground (:func:`authoring.dead_settle.limp_leg` could lower the heels only 1-2 cm that way).

The settle comes after the body has landed, so no leg may rise there (branch heels14b: lifted 4-8 deg of
hip extension to turn, the lower legs rose ~15 cm a second after ststow2dead landed, a dead man kicking):
each leg **rolls out with at most a small lift** (:data:`LIFTS`, 0-2 deg of hip extension), the hip's turn
ahead of the knee and ankle (:data:`LEADS`), to the shape that lays its heel lowest (:func:`turned_leg`, the
legs' angles searched freely: hip, knee, ankle, toes) **on that path**: no resting point (the heel and knee
sites, the foot's and kneecap's lowest nodes, as :mod:`authoring.quality_rest` sees them) rising more than
:data:`RISE_CM` above its lowest so far, no node on the ground sliding more than :data:`LEG_SLIDE_CM`, none
into the ground. The lift and lead that lay the heel lowest are kept; a leg none of them lays lower than
the limp settle of :func:`authoring.dead_settle.limp_leg` keeps that.

A leg laid **while the body is still landing** (:func:`authoring.dead_settle._legs_land`: from the frame
the trunk is down within 3 cm, before the check's rest frame, when the pelvis, chest and head are down
within 1 cm) may rise before that rest frame (``free``, the settle's progress then): it also tries
:data:`LANDING_LIFTS`, its rise judged from then on, and of the shapes that lay the heel about as low
(:data:`HEEL_TIE_CM`) the one sliding least. stfire2dead's rifle thrown clear of him left his toes dug in,
heels 21-24 cm up, that no lift of 2 degrees or less laid lower (branch stfire14-wip): a leg flopping over
as he lands, lifted 6 degrees, lays them 11.3 cm up.

A prone death's feet **go slack** (``slack_feet``, :attr:`authoring.deaths.DeathSpec.slack_feet`, on the
figure with the legs' passive range): besides those paths, each leg tries one on the ground (no lift) whose
knee, ankle pointing and toes go first (:data:`FEET_LEADS`), the toes lifting as the shin comes down, and
only then rolls out; lifted or rolled first, the toes dug in stop the shin.

soldier.fig's limits leave the heels 12.4-15.7 cm up (hip turned out 45 deg, foot everted 30 deg, ankle
pointed 50 deg, the knee bent so the foot rests on its inner edge), but reaching that needs the foot lifted
5-15 cm (heels14); rolled out within 2-3 cm they come to 15-19 cm (ststow2dead).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from authoring import dead_settle as ds
from authoring.body_parts import contact_runs
from authoring.quality import CONTACT_HEIGHT_CM, LIFT_OFF_CM, THRESHOLDS
from authoring.quality_rest import LEG_SITES, RISE_LIMIT_CM
from authoring.signal_shaping import smoothstep

HIP_FLEX = 1  # of a leg's angles (ds.LEG_DOFS order): the hip's second bends it (negative: the knee rises)
HIP_TURN = 2  # ... its third turns the leg about the thigh
FEET = (3, 4, 6)  # ... the knee, the ankle's pointing and the toes: what goes slack first (FEET_LEADS)
HIP_LEAD = 0.5  # of the settle: the hip's turn is done by then (rolled out first, the knee and ankle after)
LEADS = (HIP_LEAD, 0.75)  # ... each tried
# of the settle: a prone death's feet go slack first (dead_settle.settle's ``slack_feet``): the knee, the
# ankle and toes are done by then, each tried, the hip's turn (with its other angles) starting FEET_OVERLAP of
# it in
FEET_LEADS = (0.4, 0.6)
FEET_OVERLAP = 0.5
# degrees, per leg angle: the target search's grid (hip abduction and flexion about the leg's own, None its
# own angle); the hip turned both ways (soldier.fig: -45 out .. 40 in), the knee bent so the foot lies
LEG_GRID = ((-8.0, 0.0, 8.0), (-5.0, 0.0, 5.0, 10.0, 15.0), (-45.0, -30.0, 0.0, 20.0, 40.0),
            tuple(float(k) for k in range(0, 41, 4)), (-50.0, -25.0), (-20.0, 0.0, 15.0, 30.0),
            (None, -40.0, 0.0))  # fmt: skip
STARTS = 6  # the grid's best shapes a pattern search starts from (the hip turned out or in: two valleys)
# degrees of hip extension that lift the leg clear, each tried (its own target search) for the lowest heel:
# 2 lifts the foot ~3 cm
LIFTS = (0.0, 0.5, 1.0, 1.5, 2.0)
# degrees: also tried for a leg laid while the body is still landing (dead_settle._legs_land), lifted and
# turned before the trunk is down (the check's rest_rise_cm judges from then on)
LANDING_LIFTS = (4.0, 6.0)
# cm: of the shapes laid while he lands that lay the heel this near the lowest, the one whose nodes slide
# least (the check judges a thigh's whole run on the ground, the fall's own slide under the settle with it:
# stfire2dead's left thigh 3.16 cm with the first of them, 2.66 with the least sliding)
HEEL_TIE_CM = 0.5
RISE_CM = 2.1  # cm: the most a resting leg point (authoring.quality_rest) may rise above its lowest so far
# cm: the settle's path (checked finer) stays this far under the check's rest_rise limit: the fall's last
# bounce may have laid a point up to ~0.8 cm lower than where the physics leaves it (ststow2dead)
RISE_MARGIN = 0.8
SEARCH_STEPS = 12  # the path is checked at this many even steps while its target is searched
FEET_UP_MARGIN = 2.0  # cm: the lifted foot stays this far under the check's feet_up_cm (foot over pelvis)
LIFT_SPAN = 0.3  # of the settle: the leg rises over the first this much and comes down over the last
LEG_SLIDE_CM = 1.9  # cm: the most a leg node on the ground may slide over the settle (the check allows 2
# (feet) and 3 over a node's whole run on the ground; the thigh by the groin rolls a little as it turns)
PATH_STEPS = 48  # the path is checked at this many even steps of the settle


class _Rest:
    """A leg's resting points as :mod:`authoring.quality_rest` sees them (the heel and knee sites,
    the foot's and kneecap's lowest nodes): their heights for many shapes at once."""

    def __init__(self, leg: ds._Leg) -> None:
        kin, body = leg.kin, leg.body
        side = kin.segment_names[leg.foot_seg].split("_", 1)[0]
        g = kin.segment_globals(body.q, body.root)
        sg = kin.site_globals(body.q, body.root)
        names = [f"{side}_{s}" for s in LEG_SITES if f"{side}_{s}" in kin.site_names]
        self.segs = np.array([kin.segment_names.index(n.split(".", 1)[0]) for n in names])
        self.local = np.array(
            [
                (np.linalg.inv(g[k]) @ sg[kin.site_names.index(n)])[:, 3]
                for k, n in zip(self.segs, names, strict=True)
            ]
        )
        self.kneecap = body.parts[leg.nodes] == f"{side}_kneecap"
        self.leg = leg

    def shape(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The leg's nodes ``(m, k, 3)`` and its resting points' heights ``(m, p)`` in shapes ``x``; the heel
        site first."""
        leg = self.leg
        q = np.repeat(leg.body.q[None], len(x), axis=0)
        q[:, leg.idx] = x
        g = leg.kin.segment_globals(q, np.repeat(leg.body.root[None], len(x), axis=0))
        pts = np.einsum("mkij,kj->mki", g[:, leg.body.segs[leg.nodes], :3, :], leg.body.nodes[leg.nodes])
        sites = np.einsum("mkj,kj->mk", g[:, self.segs, 1, :], self.local)
        lows = [pts[:, leg.foot, 1].min(axis=1)]
        if self.kneecap.any():
            lows.append(pts[:, self.kneecap, 1].min(axis=1))
        return pts, np.column_stack([sites, *lows])


def _shapes_cost(leg: ds._Leg, rest: _Rest) -> Callable[[np.ndarray], np.ndarray]:
    """The heel's height where the leg lies in shapes ``x`` (the check's ``rest_foot_cm``), into no ground,
    no resting point higher than it lay by more than :data:`RISE_CM`, the move small."""
    y0 = rest.shape(leg.x0[None])[1][0]

    def cost(x: np.ndarray) -> np.ndarray:
        pts, ys = rest.shape(x)
        high = np.maximum(ys[:, 0], pts[:, leg.foot, 1].min(axis=1))
        wrong = np.maximum(0.0, leg.floor - pts[..., 1].min(axis=1))
        wrong += np.maximum(0.0, (ys - y0).max(axis=1) - RISE_CM)
        return high + ds.PENALTY * wrong + ds.MOVE_COST * np.degrees(np.abs(x - leg.x0)).sum(axis=1)

    return cost


def _path_cost(
    leg: ds._Leg, rest: _Rest, lift: float, lead: float, free: float = 0.0, feet: float = 0.0
) -> Callable[[np.ndarray], np.ndarray]:
    """As :func:`_shapes_cost` for the target shapes ``x``, judged over the whole path (:func:`leg_path`
    with ``lift``, at :data:`SEARCH_STEPS`): no resting point rises more than :data:`RISE_CM` above its
    lowest so far from progress ``free`` on (before it the body is still landing), no node on the ground
    slides more than :data:`LEG_SLIDE_CM`, none goes into the ground."""
    t = np.arange(1, SEARCH_STEPS + 1) / SEARCH_STEPS
    judged = np.concatenate([[0.0], t]) >= free
    pts0, y0 = rest.shape(leg.x0[None])

    def cost(x: np.ndarray) -> np.ndarray:
        m, steps = len(x), len(t)
        pts, ys = rest.shape(paths(leg, x, t, lift, lead, feet).reshape(m * steps, -1))
        at = np.concatenate(
            [np.repeat(pts0[None], m, axis=1), pts.reshape(m, steps, *pts.shape[1:]).transpose(1, 0, 2, 3)]
        )
        ys = np.concatenate([np.repeat(y0[None], m, axis=0), ys.reshape(m, steps, -1)], axis=1)
        wrong = np.maximum(0.0, leg.floor - at[..., 1].min(axis=(0, 2)))
        slid = [leg_slide(leg, at[:, i]) for i in range(m)]
        wrong += np.maximum(0.0, np.array(slid) - LEG_SLIDE_CM)
        after = ys[:, judged]
        wrong += np.maximum(0.0, (after - np.minimum.accumulate(after, axis=1)).max(axis=(1, 2)) - RISE_CM)
        high = np.maximum(ys[:, -1, 0], at[-1][:, leg.foot, 1].min(axis=1))
        return high + ds.PENALTY * wrong + ds.MOVE_COST * np.degrees(np.abs(x - leg.x0)).sum(axis=1)

    return cost


def leg_slide(leg: ds._Leg, pts: np.ndarray) -> float:
    """The farthest (cm) a node of ``leg`` slides on the ground over its positions ``pts`` ``(n, k, 3)``: the
    check's contact runs, with its lift-off rule where the body asks (:attr:`ds._Body.lift_off`: a node off
    the foot that came down stays on the ground until it rises past ``LIFT_OFF_CM``; crawl2dead's left
    thigh, rolled out at 1.0-1.8 cm, slid 2.3 cm in the settle)."""
    release = np.where(leg.foot, CONTACT_HEIGHT_CM, LIFT_OFF_CM) if leg.body.lift_off else None
    return float(contact_runs(pts, CONTACT_HEIGHT_CM, release).slide.max(initial=0.0))


def turned_leg(
    leg: ds._Leg,
    lift: float,
    lead: float = HIP_LEAD,
    rest: _Rest | None = None,
    free: float = 0.0,
    feet: float = 0.0,
) -> np.ndarray:
    """The leg's angles that lay its heel lowest (the check's ``rest_foot_cm``), into no ground, reached on
    :func:`leg_path` with ``lift`` no resting point rising more than :data:`RISE_CM` (from progress ``free``
    on) and nothing on the ground sliding: the best of :data:`LEG_GRID` where it lies, then a pattern search
    over the path."""
    rest = rest or _Rest(leg)
    grid = np.array(list(itertools.product(*LEG_GRID)), dtype=np.float64)
    grid = np.where(np.isnan(grid), leg.x0, np.radians(grid))
    grid[:, :2] += leg.x0[:2]
    grid = np.clip(grid, leg.kin.lower[leg.idx], leg.kin.upper[leg.idx])
    end_cost = _shapes_cost(leg, rest)
    starts = [
        ds.pattern_search(leg, end_cost, x[None])
        for x in grid[np.argsort(end_cost(grid), kind="stable")[:STARTS]]
    ]
    cost = _path_cost(leg, rest, lift, lead, free, feet)
    shapes = np.array([ds.pattern_search(leg, cost, x[None]) for x in starts])
    return shapes[int(np.argmin(cost(shapes)))]


def progress(
    t: np.ndarray, lift: float, lead: float = HIP_LEAD, feet: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """At ``t`` in [0, 1] of the settle: how far each of the leg's angles has gone ``(len(t), 7)`` (eased; the
    hip's turn ahead, done by ``lead`` of the way, so the leg rolls out before the knee bends and
    the foot everts) and how far (radians) its hip is extended, up over the first :data:`LIFT_SPAN` and
    down over the last."""
    turn = np.repeat(smoothstep(t)[:, None], len(ds.LEG_GRID), axis=1)
    turn[:, HIP_TURN] = smoothstep(t / lead)
    if feet > 0.0:  # the feet go slack first (the toes lifting as the shin comes down), then the leg rolls
        turn[:, : FEET[0]] = smoothstep((t - feet * FEET_OVERLAP) / (1.0 - feet * FEET_OVERLAP))[:, None]
        turn[:, FEET] = smoothstep(t / feet)[:, None]
    up = smoothstep(np.minimum(t, 1.0 - t) / LIFT_SPAN)
    return turn, np.radians(lift) * up


def paths(
    leg: ds._Leg, targets: np.ndarray, t: np.ndarray, lift: float, lead: float = HIP_LEAD, feet: float = 0.0
) -> np.ndarray:
    """The leg's angles ``(m, len(t), 7)`` at ``t`` of the settle to each of ``targets``: lifted by ``lift``
    degrees of hip extension, rolled out, laid."""
    turn, up = progress(t, lift, lead, feet)
    x = leg.x0[None, None] + turn[None] * (targets - leg.x0)[:, None, :]
    x[..., HIP_FLEX] -= up[None]
    return x


def leg_path(
    leg: ds._Leg, target: np.ndarray, t: np.ndarray, lift: float, lead: float = HIP_LEAD, feet: float = 0.0
) -> np.ndarray:
    """The leg's angles at ``t`` of the settle to ``target`` (:func:`paths`)."""
    return paths(leg, target[None], t, lift, lead, feet)[0]


def path_faults(leg: ds._Leg, path: np.ndarray) -> tuple[float, float, float]:
    """Over ``path`` (from the leg's pose where it lies): the farthest (cm) a leg node slides while on the
    ground (the check's contact runs), how deep (cm) it goes below the floor, and how high (cm) the foot's
    lowest node rises above the pelvis' (the check's ``feet_up_cm``)."""
    pts = np.concatenate([leg.start[None], leg._shape(path, 1.0)[0]])
    slide = leg_slide(leg, pts)
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
    lead: float = HIP_LEAD
    feet: float = 0.0  # the knee, ankle and toes go slack first, done by this of the settle (0: with the hip)

    def path(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The leg's angles at ``t`` of the settle (the limp settle at progress ``u``)."""
        if self.lift is None:
            return self.leg.x0[None] + u[:, None] * (self.target - self.leg.x0)[None]
        return leg_path(self.leg, self.target, t, self.lift, self.lead, self.feet)


def path_rise(rest: _Rest, path: np.ndarray, skip: int = 0) -> tuple[float, float]:
    """Over ``path`` (from the leg's pose where it lies; its first ``skip`` steps, the body still landing,
    not judged): the most (cm) a resting point rises above its lowest so far, and the check's
    ``rest_foot_cm`` of the leg at the end."""
    pts, ys = rest.shape(np.vstack([rest.leg.x0[None], path]))
    after = ys[skip:]
    rise = float((after - np.minimum.accumulate(after, axis=0)).max())
    return rise, max(float(ys[-1, 0]), float(pts[-1, rest.leg.foot, 1].min()))


def leg_settle(body: ds._Body, side: str, free: float = 0.0, slack_feet: bool = False) -> LegSettle:
    """The ``side`` leg turned (:func:`turned_leg`) with whichever of :data:`LIFTS` lays its heel lowest,
    no resting point rising more than :data:`RISE_CM` (from progress ``free`` on: before it the body is
    still landing, and a leg lifted while he lands also tries :data:`LANDING_LIFTS`), no node on the ground
    sliding more than :data:`LEG_SLIDE_CM`, into no ground; else (or if it lays the heel lower) the limp
    settle (:func:`authoring.dead_settle.limp_leg`)."""
    leg = ds._Leg(body, side)
    rest = _Rest(leg)
    t = np.arange(1, PATH_STEPS + 1) / PATH_STEPS
    skip = int(np.searchsorted(np.concatenate([[0.0], t]), free))
    limp = ds.limp_leg(body, side)
    best = LegSettle(leg, limp, None)
    best_heel = path_rise(rest, limp[None])[1]
    landing = free >= LIFT_SPAN
    found: list[tuple[float, float, LegSettle]] = []
    lifts = LIFTS + (LANDING_LIFTS if landing else ())
    tries = [(lift, lead, 0.0) for lift, lead in itertools.product(lifts, LEADS)]
    tries += [(0.0, 1.0, feet) for feet in (FEET_LEADS if slack_feet else ())]  # on the ground, slack first
    for lift, lead, feet in tries:
        target = turned_leg(leg, lift, lead, rest, free, feet)
        path = leg_path(leg, target, t, lift, lead, feet)
        slide, deep, up = path_faults(leg, path)
        rise, heel = path_rise(rest, path, skip)
        ok = slide <= LEG_SLIDE_CM and deep <= 0.0 and up <= THRESHOLDS["feet_up_cm"] - FEET_UP_MARGIN
        if ok and rise <= RISE_LIMIT_CM - RISE_MARGIN and heel < best_heel:
            found.append((heel, slide, LegSettle(leg, target, lift, lead, feet)))
    if not found:
        return best
    if not landing:  # the first of the lowest
        return min(found, key=lambda f: f[0])[2]
    low = min(h for h, _, _ in found) + HEEL_TIE_CM
    return min(((s, i, x) for i, (h, s, x) in enumerate(found) if h <= low), key=lambda f: f[:2])[2]


def legs_path(
    body: ds._Body, t: np.ndarray, u: np.ndarray, free: float = 0.0, slack_feet: bool = False
) -> np.ndarray:
    """Both legs' angles (:func:`authoring.dead_settle._leg_dofs` order) at ``t`` of the settle (a limp
    leg at progress ``u``), a rise before progress ``free`` not judged (:func:`leg_settle`)."""
    return np.hstack([leg_settle(body, side, free, slack_feet).path(t, u) for side in ("left", "right")])
