"""Limbs pass through no other part of the body (issue 14): an arm goes into neither the legs, the other arm,
nor (forearm and hand) the trunk or head; a shin or foot into neither the trunk nor the other leg.

The review of session 16 saw soldier kstow2crawl and ststow2crawl draw the left knee up through the left arm
as he goes down onto both knees (0.40-0.47 s and 0.88-0.95 s): 5.4 and 5.1 cm deep for 7-8 frames (DI 3.9
and 4.1, M16 4.2 and 4.1), where no other clip of the library went deeper than 3.2 cm (DI crawl2prstow's
right hand against the face; the head on an upper arm in the crawl). The check measured the rifle's way into
the body, never a limb's.

``limb_through_cm``: the deepest any mesh node of a part goes inside the convex hull of a segment of a part
it must stay out of (:data:`OUT_OF`; parts as :func:`authoring.body_parts.part_of`), over every frame, with
``limb_through_where`` (``part in segment[frame]``). Neighbours (an upper arm at the chest, a thigh at the
pelvis) overlap where they join and are not judged. Judged (:data:`LIMB_THROUGH_LIMIT_CM`) since the two
crawl transitions raise the rifle, and so the left forearm, over the knee coming up (branch kneearm-s16).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.body_parts import SegmentHulls, part_of

LIMB_THROUGH_LIMIT_CM = 3.5  # cm: the library's deepest is 3.2 (DI crawl2prstow's right hand at the face)
TRUNK = ("chest", "belly", "pelvis")
ARM = ("upper_arm", "forearm", "hand")
LEG = ("thigh", "knee", "foot")  # knee: the shin (authoring.body_parts)
SIDES = ("left", "right")


def _out_of() -> dict[str, frozenset[str]]:
    """Per part whose hulls are judged: the parts whose nodes must stay out of it."""
    out: dict[str, set[str]] = {}

    def keep_out(nodes: str, hull: str) -> None:
        out.setdefault(hull, set()).add(nodes)

    for side in SIDES:
        for other in SIDES:
            for a in ARM:
                for g in LEG:  # arms and legs, both ways
                    keep_out(f"{side}_{a}", f"{other}_{g}")
                    keep_out(f"{other}_{g}", f"{side}_{a}")
        other = "right" if side == "left" else "left"
        for a in ARM:
            for b in ARM:
                keep_out(f"{side}_{a}", f"{other}_{b}")
        for g in LEG:
            for h in LEG:
                keep_out(f"{side}_{g}", f"{other}_{h}")
        for a in ("forearm", "hand"):
            for t in (*TRUNK, "head"):
                keep_out(f"{side}_{a}", t)
        for g in ("knee", "foot"):
            for t in TRUNK:
                keep_out(f"{side}_{g}", t)
        keep_out("head", f"{side}_upper_arm")
    return {k: frozenset(v) for k, v in out.items()}


OUT_OF = _out_of()


def part_hulls(nodes: np.ndarray, segs: np.ndarray, segment_names: list[str]) -> dict[str, SegmentHulls]:
    """Convex hulls of the segments of every judged part, from mesh nodes ``(k, 4)`` and their segments."""
    by_part: dict[str, list[int]] = {}
    for s in np.unique(segs):
        by_part.setdefault(part_of(segment_names[s]), []).append(int(s))
    return {p: SegmentHulls.build(nodes, segs, np.array(by_part[p])) for p in OUT_OF if p in by_part}


def _deepest(
    points: np.ndarray, hull_points: np.ndarray, hull: SegmentHulls, seg_globals: np.ndarray
) -> tuple[float, int, int, int]:
    """Deepest of ``points`` ``(n, k, 3)`` in ``hull``: depth, frame, segment and point. Only points within
    the box around the part's own nodes ``hull_points`` ``(n, h, 3)`` (its hulls lie within it) are tried."""
    lo, hi = hull_points.min(axis=1)[:, None], hull_points.max(axis=1)[:, None]
    near = ((points >= lo) & (points <= hi)).all(axis=2)
    frames, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if not len(frames):
        return 0.0, -1, -1, -1
    depth, f, seg, point = hull.deepest(points[frames][:, cols], seg_globals[frames])
    if seg < 0:
        return 0.0, -1, -1, -1
    return depth, int(frames[f]), seg, int(cols[point])


def limbs_through(
    points: np.ndarray,
    parts: np.ndarray,
    hulls: dict[str, SegmentHulls],
    seg_globals: np.ndarray,
    names: list[str],
) -> dict[str, Any]:
    """``limb_through_cm`` and ``limb_through_where`` for the mesh nodes ``points`` ``(n, k, 3)`` (world, as
    placed by ``seg_globals`` ``(n, nseg, 4, 4)``), their body ``parts`` ``(k,)`` (kneecaps count as shins)
    and the judged parts' ``hulls``; ``names``: the segment names."""
    parts = np.char.replace(parts.astype(str), "_kneecap", "_knee")
    best: tuple[float, str, int, int] = (0.0, "", -1, -1)
    for hull_part, hull in hulls.items():
        inside = np.flatnonzero(np.isin(parts, list(OUT_OF[hull_part])))
        own = parts == hull_part
        if not len(inside) or not own.any():
            continue
        depth, frame, seg, node = _deepest(points[:, inside], points[:, own], hull, seg_globals)
        if depth > best[0]:
            best = (depth, str(parts[inside[node]]), frame, seg)
    depth, part, frame, seg = best
    where = f"{part} in {names[seg]}[{frame}]" if seg >= 0 else None
    return {"limb_through_cm": round(depth, 3), "limb_through_where": where}
