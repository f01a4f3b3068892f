"""Pace a recorded clip so that its rifle turns no faster than a limit (getting down to crawl).

Going down onto the forearms the whole chest pitches 85 degrees in under half a second and the rifle in the
right hand swings with it from the kneeling carry round to the crawl's cradle: its butt-to-muzzle line
turned 24 degrees in 0.1 s (kstow2crawl; ststow2crawl 21), a flick of the weapon. Turning the rifle earlier
or along another path ran it 3-5 cm through the arms, which the recorded path keeps clear. So the path is
kept and only the timing changes: the clip is played through a time warp that lingers where the rifle turns
fast and plays the rest (the slow kneeling shuffle) a little faster, keeping the clip's duration and its
graph arc time. Every site follows its recorded path (feet and knees planted, palms on the rifle); the ends
are eased afterwards as any transition's (:func:`authoring.easing.ease_ends`).
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from authoring.easing import Frames, retime
from peabody.fk import FigureKinematics
from peabody.model import Figure

F = TypeVar("F", bound=Frames)

SPREAD_FRAMES = 6  # a slowed frame slows its neighbours this far either side (the check's 0.1 s window)
JOINT_STEP_DEG = 12.0  # a joint turns at most this per frame where the clip is sped up (the check: 20)
SMOOTH_FRAMES = 3.0  # then the rate is smoothed (Gaussian sigma, frames): no joint changes speed in a frame


def line_turns(rkin: FigureKinematics, rifles: np.ndarray) -> np.ndarray:
    """``(n - 1,)`` degrees the rifle's butt-to-muzzle line turns between consecutive frames of its
    placements ``rifles`` ``(n, 4, 4)``."""
    sites = rkin.site_globals(np.zeros((len(rifles), 0)), rifles)[..., :3, 3]
    names = [s.split(".", 1)[1] for s in rkin.site_names]
    line = sites[:, names.index("muzzle")] - sites[:, names.index("butt")]
    line /= np.linalg.norm(line, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", line[1:], line[:-1]), -1.0, 1.0)))


def _dwell(need: np.ndarray, floor: float) -> np.ndarray:
    """Output frames per source frame step: at least ``need`` (spread and smoothed), ``floor`` elsewhere."""
    spread = maximum_filter1d(np.maximum(need, floor), 2 * SPREAD_FRAMES + 1, mode="nearest")
    return np.asarray(gaussian_filter1d(spread, SMOOTH_FRAMES, mode="nearest"))


def paced_times(turns: np.ndarray, joints: np.ndarray, fps: float, limit: float) -> np.ndarray:
    """``(n,)`` source times (s) of the frames of a clip of ``n = len(turns) + 1`` frames (the same length)
    played so that the line turning ``turns`` (degrees per source frame step) turns at most about ``limit``
    degrees per second, and no frame step plays so fast that a joint turns more than :data:`JOINT_STEP_DEG`
    in it (``joints``: the fastest joint's degrees per step as recorded; kstow2crawl's folding knee, sped
    up 30 %, jumped and flicked past the check's limits); the identity where the line already turns
    slowly enough."""
    need = turns * fps / limit  # output frame steps each source step needs
    if need.max(initial=0.0) > 1.0:
        need = np.maximum(need, joints / JOINT_STEP_DEG)
    steps = len(turns)
    if need.max(initial=0.0) <= 1.0:
        return np.arange(steps + 1) / fps
    lo, hi = 0.0, 1.0  # the floor that keeps the duration: the rest of the clip plays 1/floor faster
    for _ in range(60):
        mid = (lo + hi) / 2.0
        lo, hi = (mid, hi) if _dwell(need, mid).sum() < steps else (lo, mid)
    dwell = _dwell(need, lo)
    dwell *= steps / dwell.sum()
    out_at = np.concatenate([[0.0], np.cumsum(dwell)])  # output frame of each source frame
    return np.interp(np.arange(steps + 1), out_at, np.arange(steps + 1)) / fps


def paced(figure: Figure, rkin: FigureKinematics, clip: F, limit: float) -> F:
    """``clip`` (of ``figure`` holding the rifle of ``rkin``) retimed so that its rifle's line turns at
    most about ``limit`` degrees per second (see :func:`paced_times`)."""
    rot = np.array([d.kind == "R" for j in figure.joints.values() for d in j.dofs])
    joints = np.degrees(np.abs(np.diff(clip.poses[:, rot], axis=0))).max(axis=1)
    return retime(clip, paced_times(line_turns(rkin, clip.rifles), joints, clip.fps, limit))
