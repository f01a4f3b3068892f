"""Turning in place for the quality check (issue 14): how far a turn carries the soldier, whether a planted
foot pivots, and how a pivoting foot's slide is judged.

* ``turn_travel_cm`` (limit ``TRAVEL_LIMIT_CM``): a turn in place (a ``turn_*`` clip with an
  ``end_offset``), the horizontal length of its ``end_offset``: how far the figure ends from where it
  started. The server adds the move to the soldier's root offset, so every cm of it is a cm the figure
  stands off its entity. 10 cm: a drill facing movement (left face, about face) turns about the heel of one
  foot and the ball of the other, a hand's width apart under the body, and brings the feet together again;
  the body ends within about a foot's width of where it stood. The library's stepping turns travelled
  10-71 cm (branch turnpivot-s19).
* ``pivot_deg`` (information): the largest yaw (degrees) one foot turns through while it touches the
  ground (a run of ``PIVOT_MIN_FRAMES`` frames or more with a node below the contact height), with where.
  A foot that only turns in the air scores 0.
* A pivoting foot turns about the ball (or the heel) while the rest of it swings: :func:`pivot_slides`
  judges a foot node that touches the ground by its slide *about the foot's pivot* — the node of the same
  foot's sole (one that touches the ground during the run) that moves least over the node's run, its own
  slide included — when it lies within
  ``PIVOT_PATCH_CM`` of it (the forefoot round the ball: the toe tip is 6.7 cm ahead of the ball, the sole
  5 cm either side). A heel left on the ground while the foot turns about its ball (21 cm away) still
  slides, and so does a foot whose pivot point itself moves.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from authoring.body_parts import FOOT_PARTS, ContactRuns, ground_extent, true_runs
from server.motion.channelset import Channelset

TRAVEL_LIMIT_CM = 10.0
IN_PLACE_TURN_PREFIX = "turn_"  # turn_l45, turn_r180_low, ...: the standing turns in place
PIVOT_PATCH_CM = 9.0  # how far from its pivot a touching foot node may swing (the forefoot round the ball)
PIVOT_MIN_FRAMES = 3  # a foot on the ground this many frames bears weight
PIVOT_MIN_SLIDE_CM = 0.05  # runs sliding less need no second look


def turn_travel(cs: Channelset) -> dict[str, Any]:
    """``turn_travel_cm`` of a turn in place (None for every other clip)."""
    off = cs.end_offset
    if off is None or off[2] == 0.0 or not cs.name.split("/")[-1].startswith(IN_PLACE_TURN_PREFIX):
        return {"turn_travel_cm": None}
    return {"turn_travel_cm": round(float(np.hypot(off[0], off[1])), 3)}


def segment_yaw(segg: np.ndarray) -> np.ndarray:
    """Unwrapped yaw (radians, + = left about +Y) of segment globals ``(n, ..., 4, 4)`` over the frames: the
    heading of the segment's x axis on the ground (a foot pitching on its ball keeps it level)."""
    return np.unwrap(np.arctan2(-segg[..., 2, 0], segg[..., 0, 0]), axis=0)


def pivot_slides(
    runs: ContactRuns,
    pts: np.ndarray,
    parts: np.ndarray,
    yaw: np.ndarray,
    height: float,
    sole: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """The slides of ``runs`` (contact runs of mesh nodes ``pts`` ``(n, k, 3)``) with every foot node's
    judged about its foot's pivot (see the module docstring). ``parts``: each node's body part; ``yaw``:
    ``(n, k)`` the yaw (radians) of each node's segment; ``sole``: per foot part more points ``(n, m, 3)``
    its pivot may be (the ball and heel sites: a coarse mesh, DI.fig's, has no node at the ball)."""
    slides = runs.slide.copy()
    for r in np.flatnonzero(np.isin(parts[runs.node], FOOT_PARTS) & (runs.slide > PIVOT_MIN_SLIDE_CM)):
        k, a, b = int(runs.node[r]), int(runs.first[r]), int(runs.last[r]) + 1
        foot = pts[a:b, parts == parts[k]]
        if sole is not None and str(parts[k]) in sole:
            foot = np.concatenate([foot, sole[str(parts[k])][a:b]], axis=1)
        touching = (foot[..., 1] <= height).any(axis=0)  # the sole: points that touch during the run
        own = [ground_extent(foot[:, j][:, [0, 2]]) for j in np.flatnonzero(touching)]
        c = int(np.flatnonzero(touching)[int(np.argmin(own))])
        arm = pts[a:b, k][:, [0, 2]] - foot[:, c][:, [0, 2]]
        if np.hypot(*arm[0]) > PIVOT_PATCH_CM:
            continue
        turn = yaw[a:b, k] - yaw[a, k]
        cos, sin = np.cos(turn), np.sin(turn)  # take the foot's turn out: Ry(-turn) about the pivot
        back = np.stack([arm[:, 0] * cos - arm[:, 1] * sin, arm[:, 0] * sin + arm[:, 1] * cos], axis=1)
        slides[r] = min(slides[r], ground_extent(foot[:, c][:, [0, 2]] + back))
    return slides


def foot_pivots(
    pts: np.ndarray, parts: np.ndarray, foot_yaw: Mapping[str, np.ndarray], height: float
) -> dict[str, Any]:
    """``pivot_deg`` and ``pivot_where``: the most a foot turns (``foot_yaw``: part -> ``(n,)`` radians)
    while it touches the ground (any of its nodes in ``pts`` below ``height``)."""
    best, where = 0.0, None
    for part, yaw in foot_yaw.items():
        down: np.ndarray = np.asarray((pts[:, parts == part, 1] <= height).any(axis=1))
        for a, b in true_runs(down):
            if b - a < PIVOT_MIN_FRAMES:
                continue
            turn = float(np.degrees(np.ptp(yaw[a:b])))
            if turn > best:
                best, where = turn, f"{part}[{a}-{b - 1}]"
    return {"pivot_deg": round(best, 3), "pivot_where": where}


def turn_pivot_row(clips: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The summary's ``turn_pivot_deg`` row (information, no limit): the turn in place whose feet pivot
    least on the ground."""
    turns = [c for c in clips if c.get("turn_travel_cm") is not None and c.get("pivot_deg") is not None]
    least = min(turns, key=lambda c: c["pivot_deg"], default=None)
    return {
        "limit": "information: the least a turn in place turns a foot on the ground",
        "worst": None if least is None else least["pivot_deg"],
        "where": None if least is None else f"{least['name']} ({least['pivot_where']})",
        "failing": 0,
        "pass": True,
    }
