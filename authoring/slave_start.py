"""A dying slave leaves its start posture from rest: its frames up to the release retimed (issue 14).

Where a death lays its slave's trunk by the spine (:mod:`authoring.slave_spine`), the whole-body lift out of
the ground before the release (the hit presses the master's hips 1.7 cm down in his first 4 frames, and the
DI's belly, shaped otherwise, follows them 1.1 cm into the ground) is no longer met by the upper spine that
the forearm rest turned on a body lifted further: prstow2dead's DI head rose 0.6 cm in frame 2-3 while the
master's stays level, 0.59 m/s (the check's ``end_speed_m_s`` limit 0.5). As
:func:`authoring.easing.eased_in` does for a recorded fall, the slave's frames from its first to its release
frame are played through a time warp whose rate rises from 0 over a short ramp (:func:`authoring.easing.warp`,
smoothstep) and runs a little faster after it, so the release frame and everything after it stay as they
are (the clip keeps its length, the master's and the slave's release frames agree). The path of every site
is unchanged (the palms stay on the rifle, both sampled alike); only its timing before the release changes.
"""

from __future__ import annotations

import numpy as np

from authoring.easing import warp
from peabody import quaternion
from server.motion.channelset import Channelset


def ease_slave_start(slave: Channelset, ramp_s: float) -> np.ndarray:
    """Retime ``slave``'s frames before its release (joint angles, figure placements; in place) so that it
    leaves its first frame from rest over ``ramp_s``; returns the source frame (fractional) of each frame
    retimed (none without a release, a ramp or room for it)."""
    release = getattr(slave, "release_frame", None)
    if release is None or ramp_s <= 0.0 or release < 2 or ramp_s * slave.fps >= release:
        return np.zeros(0)
    src = warp(release + 1, slave.fps, ramp_s, 0.0) * slave.fps  # frame 0 and the release map onto themselves
    i = np.minimum(np.floor(src).astype(int), release - 1)
    w = src - i
    joints = slave.joint_data.astype(np.float64)
    slave.joint_data[: release + 1] = (joints[i] + w[:, None] * (joints[i + 1] - joints[i])).astype(
        slave.joint_data.dtype
    )
    pos = slave.fig_pos.astype(np.float64)
    slave.fig_pos[: release + 1] = (pos[i] + w[:, None, None] * (pos[i + 1] - pos[i])).astype(
        slave.fig_pos.dtype
    )
    quats = quaternion.make_continuous(slave.fig_quat.astype(np.float64))
    for k in range(quats.shape[1]):
        slave.fig_quat[: release + 1, k] = quaternion.slerp(quats[i, k], quats[i + 1, k], w).astype(
            slave.fig_quat.dtype
        )
    slave.fig_root[: release + 1] = slave.fig_root[np.rint(src).astype(int)]
    return src
