"""A let-go rifle lies on its side, not on its top (issue 14): its roll about the barrel.

The lead saw kfire2dead's let-go AK lie upside-down, sights and top cover on the ground and the magazine up,
on every figure: it came to rest on its side by the end, but lay rolled over its top 1.3-1.9 s into the
death (35 frames). The check passed it: a rifle on its top goes into neither the ground nor the body, and
its centre lies over what it touches.

A dropped AK or M16 comes to rest on a side (the flat of receiver and magazine) or, rarely, on magazine and
butt; it does not balance on its top. The rifles' cross-sections (their mesh nodes across the barrel, the
centre of mass by the ``grip``) have just these rests: on a side at 86-87 degrees of roll (a 20-26 cm face,
the centre well inside), on the magazine at 0, and on the top at 180 (a 1-2 cm face, the centre 12-15 cm
above it: a knife edge a few degrees of rock tip over). Every face between a side and the top (roll 90-119
degrees) holds the centre outside it: a rifle there rolls onto its side or its top. So a roll past
:data:`ROLL_LIMIT_DEG` is a rifle lying on its top.

* ``rifle_rest_roll_deg``: a clip that ends in DEAD with its rifle let go, the rifle's roll at the last
  frame (0 top up, 90 on a side, 180 top down; None while its barrel stands steeper than
  :data:`STEEP_DEG`, where it has no roll to speak of).
* ``rifle_top_down_s``: a clip whose rifle is let go, the longest run of frames from the release (s) for
  which it lies on the ground on its top: its lowest node within
  :data:`~authoring.quality_rifle_drop.GROUND_CM`, its barrel within :data:`LYING_DEG` of the horizontal and
  its roll past :data:`ROLL_LIMIT_DEG`. One rolling over its top passes there in a few frames.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.body_parts import true_runs
from authoring.quality_rifle_drop import GROUND_CM
from server.motion.channelset import Channelset

ROLL_LIMIT_DEG = 120.0  # degrees: the limit (quality.THRESHOLDS): past the last face that is not the top
TOP_DOWN_LIMIT_S = 0.2  # s: the limit: rolled over its top in passing, not lying there (kfire2dead 0.58)
STEEP_DEG = 75.0  # degrees: a barrel steeper than this has no roll (a rifle stood on an end)
LYING_DEG = 30.0  # degrees: a barrel within this of the horizontal lies (quality_rifle_drop's upright)


def rifle_roll(rotations: np.ndarray) -> np.ndarray:
    """The roll (degrees, 0-180) about the barrel of rifles with rotations ``(n, 3, 3)`` (world, their frame
    +Y up, barrel along -Z): the angle between the rifle's up and the world's up across the barrel; NaN
    where the barrel is steeper than :data:`STEEP_DEG`."""
    barrel = -rotations[:, :, 2]
    across = np.array([0.0, 1.0, 0.0]) - barrel[:, 1:2] * barrel  # the world's up, across the barrel
    length = np.linalg.norm(across, axis=1)
    cosine = np.einsum("ij,ij->i", rotations[:, :, 1], across) / np.maximum(length, 1e-9)
    roll = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    elevation = np.degrees(np.arcsin(np.clip(np.abs(barrel[:, 1]), 0.0, 1.0)))
    return np.where(elevation > STEEP_DEG, np.nan, roll)


def rifle_lie(
    cs: Channelset, ends_dead: bool, rotations: np.ndarray, rifle_points: np.ndarray
) -> dict[str, Any]:
    """``rifle_top_down_s`` (and, ``ends_dead``, ``rifle_rest_roll_deg``) of a clip whose rifle is let go
    (``release_frame``), from every frame's rifle rotations ``(n, 3, 3)`` and mesh nodes ``(n, k, 3)``
    (world); nothing for any other clip."""
    release = cs.release_frame
    if release is None:
        return {}
    roll = rifle_roll(rotations)
    barrel = -rotations[:, :, 2]
    lying = np.degrees(np.arcsin(np.clip(np.abs(barrel[:, 1]), 0.0, 1.0))) <= LYING_DEG
    down = lying & (rifle_points[..., 1].min(axis=1) <= GROUND_CM) & (np.nan_to_num(roll) > ROLL_LIMIT_DEG)
    first, stop = max(true_runs(down[release:]), key=lambda run: run[1] - run[0], default=(0, 0))
    at = f"frames {release + first}-{release + stop - 1}" if stop > first else None
    out: dict[str, Any] = {"rifle_top_down_s": round((stop - first) / cs.fps, 3), "rifle_top_down_where": at}
    if ends_dead:
        last = float(roll[-1])
        out["rifle_rest_roll_deg"] = None if np.isnan(last) else round(last, 3)
        out["rifle_rest_roll_where"] = f"frame {cs.nframes - 1}"
    return out
