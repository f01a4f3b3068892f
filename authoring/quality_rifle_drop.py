"""A dropped rifle falls by him and lies down (issue 14): how far it goes once let go, and how long it
stands on an end.

The review of session 17 found ststow2dead's let-go rifle landing 1.3-1.4 m from his hands (thrown: a rifle
a man shot standing lets go falls by him, may bounce once and tip), and kfire2dead's standing on its butt
for a second mid-fall, on every figure, its muzzle 50-67 cm up, leaning on nothing (45-58 degrees off
vertical: seen from the front it stands upright). The check passed both: the rifle went into neither the
ground nor the body, and lay at rest at the end.

* ``rifle_throw_m``: how far (m, ground plane) the rifle's centre (its ``grip`` site, by its centre of mass)
  lies at the clip's end from where it was at the release frame.
* ``rifle_upright_s``: the longest run of frames from the release (s) for which the rifle stands on an end:
  its lowest node within :data:`GROUND_CM` of the ground, its long axis (butt to muzzle) at least
  :data:`UPRIGHT_ELEVATION_DEG` above the horizontal, and its centre overhanging what its nodes touch (the
  ground and the body's hulls, as :func:`~authoring.quality_rifle_rest.rifle_rest` measures at the end)
  by more than :data:`~authoring.quality_rifle_rest.OVERHANG_LIMIT_CM`: held up by nothing, it must tip.
  One tipping over stands so for a few frames; one leaning on his body is held up.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.body_parts import SegmentHulls, true_runs
from authoring.quality_rifle_rest import OVERHANG_LIMIT_CM, rifle_rest
from server.motion.channelset import Channelset

# cm: the rifle's lowest node this near the ground stands on it (kfire2dead's DI slave's stood 4.7 cm up,
# on nothing, where its master's stood on the ground)
GROUND_CM = 6.0
UPRIGHT_ELEVATION_DEG = 30.0  # degrees: the rifle's long axis this far above the horizontal stands it up
THROW_LIMIT_M = 1.0  # m: the limit (quality.THRESHOLDS): every death <= 0.64 but the thrown 1.47-2.01
UPRIGHT_LIMIT_S = 0.2  # s: ... and <= 0.15 but kfire2dead's (0.42-0.9: it stood a second)


def standing(
    rifle_points: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray,
    hulls: SegmentHulls,
    seg_globals: np.ndarray,
) -> np.ndarray:
    """Per frame (``(n, k, 3)`` nodes, ``(n, 3)`` centres and butt-to-muzzle axes, ``(n, nseg, 4, 4)``
    segment globals): whether the rifle stands on an end (see the module docstring)."""
    elevation = np.degrees(np.arcsin(np.abs(axis[:, 1]) / np.maximum(np.linalg.norm(axis, axis=1), 1e-9)))
    out = (rifle_points[..., 1].min(axis=1) <= GROUND_CM) & (elevation >= UPRIGHT_ELEVATION_DEG)
    for f in np.flatnonzero(out):
        over = rifle_rest(rifle_points[f], centre[f], hulls, seg_globals[f], int(f))["rifle_rest_overhang_cm"]
        out[f] = over > OVERHANG_LIMIT_CM
    return out


def rifle_drop(
    cs: Channelset,
    rifle_points: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray | None,
    hulls: SegmentHulls,
    seg_globals: np.ndarray,
) -> dict[str, Any]:
    """``rifle_throw_m`` and ``rifle_upright_s`` (and where) of a clip whose rifle is let go
    (``release_frame``); nothing for any other, nor for a rifle without butt and muzzle (``axis`` None).
    Every frame's arrays, as :func:`standing` takes them."""
    release = cs.release_frame
    if release is None or axis is None:
        return {}
    throw = float(np.linalg.norm(centre[-1, [0, 2]] - centre[release, [0, 2]])) / 100.0
    up = standing(rifle_points[release:], centre[release:], axis[release:], hulls, seg_globals[release:])
    first, stop = max(true_runs(up), key=lambda run: run[1] - run[0], default=(0, 0))
    length = stop - first
    return {
        "rifle_throw_m": round(throw, 3),
        "rifle_throw_where": f"frames {release}-{cs.nframes - 1}",
        "rifle_upright_s": round(length / cs.fps, 3),
        "rifle_upright_where": f"frames {release + first}-{release + first + length - 1}" if length else None,
    }
