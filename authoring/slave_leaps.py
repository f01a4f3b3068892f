"""Slaved arms eased through the frames where their joint angles leap and the master's do not.

A shoulder's three DOFs turn about its first axis, then its middle axis, then the upper arm's own axis. With
the middle angle near 90 degrees the third axis lies within a few degrees of the first (soldier.fig and
DI.fig: 7 degrees), so turning the first angle one way and the third the other way hardly turns the arm:
the angles are near a pole, and tracked through it a small turn of the arm can take tens of degrees of both
in one frame. The slave's shoulders sit elsewhere than the master's, so his arm can pass the pole where the
master's does not (crawl2prstow with the elbows lifted: DI's right shoulder 33.8 degrees at frame 54 while
the upper arm turned 0.8 degrees; the master keeps his arm 15 degrees off the pole), and a wrist held at its
limits meanwhile lets go in one frame afterwards (29.9 degrees at frame 81).

So around every frame where an arm DOF of the slave moves more than ``LEAP_DEG`` and more than the master's
copied angle does (by ``MASTER_MARGIN_DEG``) while the arm's shoulder is near its pole (within
``NEAR_POLE_DEG``; elsewhere a leap is left to the slaving as it was), the arm's angles are smoothed over the
neighbouring frames (a Gaussian, faded in around the leap and out towards the clip's ends). Smoothing is
linear, so near the pole the sum of the first and third angles, which the arm's orientation pins, stays as it
was and only their free difference is spread out: the arm turns a few degrees at most. :func:`ease_leaps` only
eases; the caller puts the palms back on their goals.
"""

from __future__ import annotations

import numpy as np

from authoring.signal_shaping import gaussian
from peabody.fk import FigureKinematics
from peabody.rotations import axis_angle

LEAP_DEG = 12.0  # an arm DOF of the slave moving this much in a frame ...
MASTER_MARGIN_DEG = 5.0  # ... and this much more than the master's copied angle is a leap to ease
SIGMA_FRAMES = 5.0  # the arm's angles are smoothed over this many frames (Gaussian) ...
REACH_FRAMES = 15  # ... within this many frames of a leap (faded out to their edge)
NEAR_POLE_DEG = 20.0  # a leap counts where the shoulder's third axis is this near its first


def pole_distance(kin: FigureKinematics, joint: str, poses: np.ndarray) -> np.ndarray:
    """Per frame ``(n,)`` how far (degrees) a three-DOF joint's third axis lies from its first (or from
    its opposite): near 0, the first and third angles turn the limb about the same axis."""
    sl = kin.dof_slices[joint]
    a1, a2, a3 = (np.asarray(d.axis, np.float64) for d in kin.figure.joints[joint].dofs)
    turned = np.einsum("fij,j->fi", axis_angle(a2, poses[:, sl.start + 1]), a3)
    return np.degrees(np.arccos(np.clip(np.abs(turned @ a1), 0.0, 1.0)))


def leap_window(leaps: np.ndarray, n: int) -> np.ndarray:
    """1 at the leaping frames, fading out over ``REACH_FRAMES`` either side and to 0 at the clip's ends
    (they stay the frames solved alone, which every clip meeting at that posture shares)."""
    frames = np.arange(n)
    gap = np.min(np.abs(frames[:, None] - np.flatnonzero(leaps)[None, :]), axis=1)
    u = np.clip(1.0 - gap / REACH_FRAMES, 0.0, 1.0)
    ends = np.clip(np.minimum(frames, frames[::-1]) / (2.0 * SIGMA_FRAMES), 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u) * ends


def leap_frames(poses: np.ndarray, copied: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """Per frame ``(n,)`` whether one of ``dofs`` (indices) moves into it by more than ``LEAP_DEG`` and by
    ``MASTER_MARGIN_DEG`` more than the master's copied angle ``copied`` does."""
    step = np.abs(np.diff(poses[:, dofs], axis=0))
    master = np.abs(np.diff(copied[:, dofs], axis=0))
    big = (step > np.radians(LEAP_DEG)) & (step > master + np.radians(MASTER_MARGIN_DEG))
    return np.concatenate([[False], big.any(axis=1)])


def ease_leaps(
    kin: FigureKinematics, poses: np.ndarray, copied: np.ndarray, chains: tuple[tuple[str, ...], ...]
) -> np.ndarray:
    """``poses`` ``(n, ndof)`` with each chain of joints (an arm, with its ``*shoulder``) smoothed around the
    frames where one of its DOFs leaps near the shoulder's pole and the master's (``copied``, in the slave's
    DOFs) does not; the rest as it is."""
    out = np.array(poses, dtype=np.float64)
    n = len(out)
    if n < 3:
        return out
    for chain in chains:
        dofs = np.concatenate([np.arange(kin.dof_slices[j].start, kin.dof_slices[j].stop) for j in chain])
        pole = pole_distance(kin, next(j for j in chain if j.endswith("shoulder")), out) < NEAR_POLE_DEG
        leaps = leap_frames(out, copied, dofs) & (pole | np.roll(pole, 1))
        if not leaps.any():
            continue
        w = leap_window(leaps, n)[:, None]
        out[:, dofs] += w * (gaussian(out[:, dofs], SIGMA_FRAMES) - out[:, dofs])
    return kin.clamp(out)
