"""A dropped rifle at rest lies on something (issue 14): at the end of a death, the rifle he let go rests on
the ground or on his body, its weight over what holds it.

The review of session 16 found prstow2dead and prfire2dead (soldier, DI and M16) ending with the rifle
standing on its magazine or its muzzle, the butt 19-36 cm up and nothing under it, 5-13 cm clear of the body:
the settle lowered the arms it had leaned on and left it there, held up by nothing, for as long as he lies
DEAD. The check passed it: a rifle in the air goes into neither the ground nor the body.

``rifle_rest_overhang_cm``: at the clip's last frame, how far (cm, ground plane) the rifle's centre of mass
(its ``grip`` site, just behind the magazine well: the rifle figure has no masses) lies outside the support
its nodes touch: the 2D convex hull of the rifle nodes within :data:`TOUCH_CM` of the ground or of a body
segment's convex hull (hands included). A rifle lying on the ground or across his legs scores 0; one balanced
on an end scores the distance it would have to tip. No node touching anything: the centre's height (a rifle
in the air is at least that far from resting). Judged against :data:`OVERHANG_LIMIT_CM` since the prone
deaths' rifle falls again once the settle takes his arms from under it (:mod:`authoring.rifle_settle`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.body_parts import SegmentHulls
from server.motion.channelset import Channelset

TOUCH_CM = 2.0  # cm: a rifle node this near the ground or the body rests on it
OVERHANG_LIMIT_CM = 2.0  # cm: the limit (quality.THRESHOLDS); every death's rifle lies at 0


def _outside(p: np.ndarray, support: np.ndarray) -> float:
    """Distance (cm) of ``p`` ``(2,)`` outside the convex hull of ``support`` ``(s, 2)`` (0 inside); a
    degenerate support (a point, a line) is measured to its extent along its main direction."""
    from scipy.spatial import ConvexHull, QhullError

    if len(support) >= 3:
        try:
            hull = ConvexHull(support)
        except QhullError:  # collinear: a line
            pass
        else:
            if (hull.equations[:, :2] @ p + hull.equations[:, 2] <= 0.0).all():
                return 0.0
            edges = support[hull.simplices]  # (e, 2, 2)
            return float(min(_to_segment(p, a, b) for a, b in edges))
    centred = support - support.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0] if len(support) > 1 else np.array([1.0, 0.0])
    along = centred @ axis
    return _to_segment(p, support[int(np.argmin(along))], support[int(np.argmax(along))])


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    u = float(np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)) if ab @ ab > 0 else 0.0
    return float(np.linalg.norm(a + u * ab - p))


def rifle_rest(
    rifle_points: np.ndarray, centre: np.ndarray, hulls: SegmentHulls, seg_globals: np.ndarray, frame: int
) -> dict[str, Any]:
    """``rifle_rest_overhang_cm`` and ``rifle_rest_where`` for the rifle's mesh nodes ``(k, 3)`` (world) and
    its centre of mass ``(3,)`` at ``frame``, the body's ``hulls`` and that frame's segment globals
    ``(nseg, 4, 4)``."""
    on_ground = rifle_points[:, 1] <= TOUCH_CM
    on_body = hulls.clearance(rifle_points, seg_globals) <= TOUCH_CM
    held = on_ground | on_body
    overhang = _outside(centre[[0, 2]], rifle_points[held][:, [0, 2]]) if held.any() else float(centre[1])
    body = int((on_body & ~on_ground).sum())
    where = f"frame {frame}: {int(on_ground.sum())} nodes on the ground, {body} on the body"
    where += f", centre {centre[1]:.1f} cm up"
    return {"rifle_rest_overhang_cm": round(overhang, 3), "rifle_rest_where": where}


def dropped_rifle_rest(
    cs: Channelset,
    ends_dead: bool,
    rifle_points: np.ndarray,
    centre: np.ndarray,
    hulls: SegmentHulls,
    seg_globals: np.ndarray,
) -> dict[str, Any]:
    """:func:`rifle_rest` at the last frame of a clip that ends in DEAD with its rifle let go
    (``release_frame``); nothing for any other clip. ``rifle_points`` ``(n, k, 3)``, ``centre`` ``(n, 3)``
    and ``seg_globals`` ``(n, nseg, 4, 4)``: every frame's."""
    if not ends_dead or cs.release_frame is None:
        return {}
    last = cs.nframes - 1
    return rifle_rest(rifle_points[last], centre[last], hulls, seg_globals[last], last)
