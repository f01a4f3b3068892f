"""A dying man does not get up (issue 14): ``ttes author check``'s ``dying_rise_cm``.

Session 21: a physics variant of kstow2dead (legs laid) straightened the kneeling man up off his knee until
he nearly stood (the pelvis' lowest node 44 -> 58 cm, 1.0 s in) before he fell back, and no limit failed:
``trunk_rise_cm`` and ``legs_rise_cm`` judge only once the trunk or pelvis is down, and ``rest_rise_cm``
once the body is. A man shot falls from where he was hit; his hips and chest do not climb above it.

* ``dying_rise_cm``: in a clip that ends in DEAD, the most the pelvis' or the chest's lowest mesh node
  rises above its height in the first frame (:func:`dying_rise`, :data:`DYING_RISE_LIMIT_CM`). Every
  shipped death stays within 5.6 cm (crawl2dead's DI/M16 slaves: the chest 5.45/5.61 cm, the pelvis
  3.91/3.83, as the crawler's forearms give way; the soldier's deaths 0.0); the kstow2dead variant rose
  14.3 (pelvis) and 8.7 (chest).

Comes with ``dying_rise_part`` and ``dying_rise_where`` (the frame, the heights).
"""

from __future__ import annotations

from typing import Any

import numpy as np

RISE_PARTS = ("pelvis", "chest")  # body parts (authoring.body_parts) whose lowest nodes are judged
DYING_RISE_LIMIT_CM = 7.0  # cm: every shipped death <= 5.61 (crawl2dead_m16_low's chest); the variant 14.3


def dying_rise(heights: np.ndarray, parts: np.ndarray) -> dict[str, Any]:
    """``dying_rise_cm`` (the most the lowest node of a part of :data:`RISE_PARTS` rises above its first
    frame), the part and where, for body mesh nodes ``heights`` ``(n, k)`` (cm above the ground) of body
    parts ``parts`` ``(k,)``; None when the body has none of those parts."""
    best: tuple[float, str, int, float, float] | None = None
    for name in RISE_PARTS:
        mask = parts == name
        if not mask.any():
            continue
        y = heights[:, mask].min(axis=1)
        k = int(np.argmax(y - y[0]))
        rise = float(y[k] - y[0])
        if best is None or rise > best[0]:
            best = (rise, name, k, float(y[0]), float(y[k]))
    if best is None:
        return {"dying_rise_cm": None, "dying_rise_part": None, "dying_rise_where": None}
    rise, part, frame, first, top = best
    up = rise > 0
    return {
        "dying_rise_cm": round(max(rise, 0.0), 3),
        "dying_rise_part": part if up else None,
        "dying_rise_where": f"{part} at frame {frame}, {first:.1f} -> {top:.1f} cm" if up else None,
    }
