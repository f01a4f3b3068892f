"""A dead arm falls down, never up (issue 14): its way to the ground bent through an intermediate pose.

Eased straight from its angles to the fallen ones, an arm swings wherever the angles pass: kfire2dead's right
hand rose 18.6 cm over the head 1.2 s after he lay still, a forearm laid from over the chest to the far side
rose 40 cm (branch ``kstowarms14``). A path of the hand in space solved frame by frame by IK ran into the
shoulder's and forearm's twist limits (a shoulder leapt 15-110 deg a frame). So the way is kept in the
angles, where every pose is within the limits and nothing leaps, but bent: a quadratic Bezier from the
arm's pose through a control pose to the fallen one (:func:`bent`; a convex mix of poses within the limits
stays within them). The control pose is searched (Powell, from the straight way's middle) so that no part
of the arm (upper arm, forearm, hand: each its lowest node, as ``rest_rise_cm`` sees it) rises above its
lowest before, and the forearm and hand go into neither the rest of the body nor the ground
(:func:`path_cost`, checked at :data:`CHECKS` points). An arm whose straight way is fine keeps it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

RISE_OK_CM = 1.0  # cm: an arm whose straight way lifts no part more than this falls that way
PARTS = ("upper_arm", "forearm", "hand")  # each one's lowest node, as the check (quality_rest) sees it
CHECKS = 24  # the way is checked at this many even steps of its progress
QUICK_CHECKS = 8  # ... and at this many while a fallen shape is searched
PENALTY = 10.0  # per cm into the body or the ground (the rise counts 1 per cm)
BEND_COST = 0.002  # per degree the control pose lies off the straight way's middle: of two equal ways the
# straighter one


def bent(x0: np.ndarray, c: np.ndarray, x1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The quadratic Bezier from ``x0`` through control ``c`` to ``x1`` at progress ``u`` ``(n,)``."""
    u = u[:, None]
    return (1.0 - u) ** 2 * x0 + 2.0 * u * (1.0 - u) * c + u * u * x1


def rises(lows: np.ndarray) -> float:
    """cm the most any column of ``lows`` ``(n, parts)`` rises above its lowest before."""
    return float((lows - np.minimum.accumulate(lows, axis=0)).max(initial=0.0))


def _way(arm: Any, x0: np.ndarray, c: np.ndarray, x1: np.ndarray, u: np.ndarray) -> tuple[Any, Any, Any]:
    """Along the way (:func:`bent`) at ``u``: the segments' globals, the body's nodes and the lowest node
    of each of the arm's :data:`PARTS` ``(n, 3)``."""
    body = arm.body
    q = np.repeat(body.q[None], len(u), axis=0)
    q[:, arm.idx] = bent(x0, c, x1, u)
    g = body.kin.segment_globals(q, np.repeat(body.root[None], len(u), axis=0))
    p = np.einsum("nkij,kj->nki", g[:, body.segs, :3, :], body.nodes)
    lows = np.stack([p[:, body.parts == f"{arm.side}_{part}", 1].min(axis=1) for part in PARTS], axis=1)
    return g, p, lows


def straight_rise(arm: Any, x1: np.ndarray) -> float:
    """cm the most any part of ``arm`` rises on the straight way (in the angles) to ``x1``, checked at
    :data:`QUICK_CHECKS` points: what a fallen shape's search weighs (a bent way is searched only after)."""
    u = np.arange(QUICK_CHECKS + 1) / QUICK_CHECKS
    return rises(_way(arm, arm.x0, (arm.x0 + x1) / 2.0, x1, u)[2])


def path_cost(arm: Any, x0: np.ndarray, x1: np.ndarray) -> Callable[[np.ndarray], float]:
    """The cost of a control pose ``c`` of ``arm`` (an :class:`authoring.dead_settle._Arm`): the most any
    part rises on the way, plus :data:`PENALTY` per cm the forearm and hand go into the rest of the body
    (beyond how deep they lay at ``x0``, measured alike: the arm's own ``inside0`` counts the rifle too) or
    (beyond where the arm lay) the ground, plus :data:`BEND_COST` per degree of bend."""
    u = np.arange(CHECKS + 1) / CHECKS
    mid = (x0 + x1) / 2.0
    floor = min(0.0, float(arm.body.points[arm.arm, 1].min()))
    g0, p0, _ = _way(arm, x0, x0, x0, np.zeros(1))
    inside0, _, _ = arm.rest.depth(p0[:, arm.lower], g0)

    def cost(c: np.ndarray) -> float:
        g, p, lows = _way(arm, x0, c, x1, u)
        inside, _, _ = arm.rest.depth(p[:, arm.lower], g)
        wrong = max(0.0, inside - inside0) + max(0.0, floor - float(lows.min()))
        return rises(lows) + PENALTY * wrong + BEND_COST * float(np.degrees(np.abs(c - mid)).sum())

    return cost


def control_pose(arm: Any, x1: np.ndarray, minimise: Callable[..., np.ndarray]) -> np.ndarray:
    """The control pose of ``arm``'s way from its pose to ``x1``: the straight way's middle if it does not
    lift the arm (:data:`RISE_OK_CM`), else the lowest :func:`path_cost` that ``minimise`` (cost, starts,
    lower, upper) finds from it."""
    x0 = arm.x0
    cost = path_cost(arm, x0, x1)
    mid = (x0 + x1) / 2.0
    if cost(mid) <= RISE_OK_CM:
        return mid
    kin = arm.body.kin
    return minimise(cost, [mid, x0, x1], kin.lower[arm.idx], kin.upper[arm.idx])
