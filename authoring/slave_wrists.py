"""The slave's wrists eased where they flick and the master's do not (issue 16, ``crawlarc_l135/l150``).

On a U-turn to his left the DI's left wrist holds the rifle's handguard at its joint limits (-70, -35
degrees): the slaving's frame-after-frame track pushes it off them and back, one frame out and in again
(-53, -61, -52 degrees at frames 261-263 of ``crawlarc_l135_low``) while the clavicle, shoulder and elbow
above it turn smoothly and the master's wrist is still: a 15.8-20.0 degree one-frame flick, whatever share
of the forearms' carry the pelvis takes (:data:`authoring.crawl_turn.LEFT_U_TURN_PELVIS_AHEAD`). So around
every frame where a wrist DOF of the slave flicks (the quality check's one-frame flick: the smaller of its
two second differences) by more than ``FLICK_DEG`` and the master's does not, the wrist's angles are smoothed
over the neighbouring frames (a Gaussian, faded in around the flick and out towards the clip's ends, as
:mod:`~authoring.slave_leaps` eases an arm): the palm, carried by the smooth arm, stays on the rifle.
"""

from __future__ import annotations

import numpy as np

from authoring.quality import one_frame_flicks
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import gaussian
from authoring.slave_body import played_body
from authoring.slave_leaps import leap_window
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

WRISTS = ("left_wrist", "right_wrist")
FLICK_DEG = 8.0  # a wrist DOF flicking this much in a frame ...
MASTER_MARGIN_DEG = 2.0  # ... and this much more than the master's is eased
SIGMA_FRAMES = 1.0  # the wrist's angles are smoothed over this many frames (Gaussian)


def flicks(poses: np.ndarray) -> np.ndarray:
    """Per frame and DOF ``(n, k)`` the one-frame flick (radians) of ``poses`` ``(n, k)``
    (:func:`authoring.quality.one_frame_flicks`; 0 at the ends)."""
    out = np.zeros_like(poses)
    out[1:-2] = one_frame_flicks(np.diff(poses, axis=0))
    return out


def eased(slave: np.ndarray, master: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One joint's angles ``slave`` ``(n, k)`` (radians) smoothed around the frames where they flick and
    the ``master``'s ``(n, k)`` do not, and per frame ``(n,)`` the share of the smoothing taken (0: as
    they were; always 0 at the clip's ends)."""
    mine, his = flicks(slave), flicks(master)
    at = ((mine > np.radians(FLICK_DEG)) & (mine > his + np.radians(MASTER_MARGIN_DEG))).any(axis=1)
    if not at.any():
        return slave, np.zeros(len(slave))
    w = leap_window(at | np.roll(at, 1), len(slave))  # (a flick at t is the turn from frame t to t+1)
    return slave + w[:, None] * (gaussian(slave, SIGMA_FRAMES) - slave), w


def ease_slave_wrists(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Smooth ``slave``'s wrists around the frames where they flick and ``master``'s do not (in place);
    returns per frame ``(n,)`` whether it was eased."""
    q, _, stype = played_body(slave, figures)
    mq, _, mtype = played_body(master, figures)
    skin, mkin = figures.kin[stype], figures.kin[mtype]
    touched = np.zeros(len(q), dtype=bool)
    for wrist in WRISTS:
        sl = skin.dof_slices[wrist]
        q[:, sl], w = eased(q[:, sl], mq[:, mkin.dof_slices[wrist]])
        touched |= w > 0.0
    if touched.any():
        bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
        slave.joint_data[:, bf.src] = skin.clamp(q)[:, bf.dst].astype(slave.joint_data.dtype)
    return touched
