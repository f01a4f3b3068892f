"""Lying on the ground, his feet lie there too (issue 14): ``ttes author check``'s ``lying_feet_raised_s``.

Session 21: crawl2prstow held both feet 8-15 cm up for about a second while he turned over on his belly
(0.53-1.5 s, the pelvis down on the ground), a "superman" pose a trainee notices; ``feet_up_cm`` measures a
foot against the pelvis (a scorpion, limit 20 cm) and ``lying_feet_up_cm`` only clips that start lying, so
both passed it.

* ``lying_feet_raised_s``: the longest run of frames (s) in which the pelvis' lowest mesh node is within
  :data:`LYING_PELVIS_CM` of the ground (he lies, on his belly, back or side) while *both* feet's lowest
  nodes are higher than :data:`FEET_RAISED_CM`. One foot up is a leg moving (judged by ``legs_rise_cm`` in
  a death); both held up is a pose. A falling body's legs come down within a few tenths of a second
  (kstow2dead: 0.27 s, stfire2dead 0.18 s), so :data:`RAISED_LIMIT_S` allows that and no more.

Comes with ``lying_feet_raised_where`` (the frames).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.body_parts import FOOT_PARTS, true_runs

LYING_PELVIS_CM = 5.0  # cm: the pelvis' lowest node this low, he lies on the ground
FEET_RAISED_CM = 4.0  # cm: both feet's lowest nodes above this, his feet are held up (prone at rest: 1.4-2.4)
RAISED_LIMIT_S = 0.4  # s: every shipped clip but crawl2prstow (0.93) <= 0.27


def lying_feet_raised(heights: np.ndarray, parts: np.ndarray, fps: float) -> dict[str, Any]:
    """``lying_feet_raised_s`` and where, for body mesh nodes ``heights`` ``(n, k)`` (cm above the ground) of
    body parts ``parts`` ``(k,)`` at ``fps``; None when the figure lacks a pelvis or feet."""
    if not {"pelvis", *FOOT_PARTS} <= set(parts):
        return {"lying_feet_raised_s": None, "lying_feet_raised_where": None}
    pelvis = heights[:, parts == "pelvis"].min(axis=1)
    lower_foot = np.min([heights[:, parts == f].min(axis=1) for f in FOOT_PARTS], axis=0)
    runs = true_runs((pelvis <= LYING_PELVIS_CM) & (lower_foot > FEET_RAISED_CM))
    a, b = max(runs, key=lambda r: r[1] - r[0], default=(0, 0))
    return {
        "lying_feet_raised_s": round((b - a) / fps, 4),
        "lying_feet_raised_where": f"frames {a}-{b - 1}" if b > a else None,
    }
