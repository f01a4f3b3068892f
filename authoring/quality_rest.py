"""Resting parts do not rise after rest (issue 14): once a dead body's pelvis and chest are down, no foot,
heel or knee lifts off where it lay.

A settle that lifted each leg 4-8 deg of hip extension to turn it out (heels 19-22 -> 14-16 cm) raised the
lower legs ~15 cm a second after the body had landed (ststow2dead, 2.28-2.60 s): a dead man kicking. This
measures, from the first frame where the pelvis and the chest (or belly) are down (each within
:data:`DOWN_CM` of its height at the last frame, and staying so), how far each leg point rises above the
lowest it has been since (``rest_rise_cm``; the heel and knee sites, the lowest nodes of the foot and the
kneecap). Used by tests/test_quality_rest.py and the leg settle (:mod:`authoring.dead_legs`); not yet a
limit of ``ttes author check``: the physics' own rebounds in kfire2dead and kstow2dead rise 5.9 and 6.7 cm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.quality_frames import ClipFrames, FigureSet

DOWN_CM = 1.0  # cm: the pelvis and chest are down once within this of where they finally lie
RISE_LIMIT_CM = 3.0  # cm: the most a resting leg point may rise above the lowest it has been since rest
LEG_SITES = ("foot.heel", "lower_leg.knee")
LEG_PARTS = ("foot", "knee", "kneecap")
TORSO_PARTS = ("pelvis", "chest", "belly")


def _heights(cf: ClipFrames, figures: FigureSet) -> dict[str, np.ndarray]:
    """Per frame, the heights (cm) of the torso parts' lowest nodes and the legs' points."""
    body = max(cf.poses, key=lambda k: figures.kin[k].ndof)
    kin = figures.kin[body]
    nodes, segs = figures.nodes(body)
    parts = figures.node_parts(body)
    q, loc = cf.poses[body], cf.locations[body]
    y = np.einsum("nkj,kj->nk", kin.segment_globals(q, loc)[:, segs, 1, :], nodes)
    sites = kin.site_globals(q, loc)[:, :, 1, 3]
    out: dict[str, np.ndarray] = {}
    for name in TORSO_PARTS:
        if (parts == name).any():
            out[name] = y[:, parts == name].min(axis=1)
    for side in ("left", "right"):
        for p in LEG_PARTS:
            if (parts == f"{side}_{p}").any():
                out[f"{side}_{p}"] = y[:, parts == f"{side}_{p}"].min(axis=1)
        for s in LEG_SITES:
            if f"{side}_{s}" in kin.site_names:
                out[f"{side}_{s}"] = sites[:, kin.site_names.index(f"{side}_{s}")]
    return out


def rest_frame(h: dict[str, np.ndarray]) -> int | None:
    """The first frame from which the pelvis and chest (or belly) stay down (None: the body lacks them)."""
    torso = [h["pelvis"]] if "pelvis" in h else []
    chest = [h[p] for p in ("chest", "belly") if p in h]
    if not torso or not chest:
        return None
    low = np.minimum.reduce(chest)
    up = (torso[0] > torso[0][-1] + DOWN_CM) | (low > low[-1] + DOWN_CM)
    late = np.flatnonzero(up)
    return 0 if len(late) == 0 else int(late[-1]) + 1


def rise_after(h: dict[str, np.ndarray], start: int) -> tuple[float, str | None, int | None]:
    """From frame ``start`` on: the most (cm) any leg point of ``h`` rises above its lowest since then, which
    point and at which frame (0.0, None, None if none rises)."""
    best: tuple[float, str | None, int | None] = (0.0, None, None)
    for name, y in h.items():
        if name in TORSO_PARTS:
            continue
        tail = y[start:]
        rise = tail - np.minimum.accumulate(tail)
        k = int(np.argmax(rise))
        if rise[k] > best[0]:
            best = (float(rise[k]), name, start + k)
    return best


def rest_rise(cf: ClipFrames, figures: FigureSet) -> dict[str, Any]:
    """``rest_frame`` and, after it, the most (cm) any leg point rises above its lowest since then
    (``rest_rise_cm``), which point and at which frame."""
    h = _heights(cf, figures)
    start = rest_frame(h)
    row: dict[str, Any] = {"rest_frame": start, "rest_rise_cm": None, "rest_rise_part": None}
    row["rest_rise_frame"] = None
    if start is None:
        return row
    rise, part, frame = rise_after(h, start)
    row.update(rest_rise_cm=round(rise, 3), rest_rise_part=part, rest_rise_frame=frame)
    return row
