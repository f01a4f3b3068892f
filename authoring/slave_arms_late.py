"""A dying slave's arms leave its start posture late, once its body has lifted them off the ground (issue 14).

The DI's PRONE_FIRE node (the pose :func:`authoring.build.snap_endpoints` gives a slave's first frame) holds
the rifle some 4 cm further forward than prfire2dead's slave solve does; the snap fades that change out over
its first frames, so the right arm and the rifle swing back while the forearm still lies on the ground:
prfire2dead's DI right forearm dragged 5.4 cm (frames 0-9), its left forearm then leapt at the release
(1.65 m/s, frame 13). Here the arms (clavicles to wrists) keep the start pose for the first frames and then
catch up with the solve by a few frames past the release, while the trunk moves as solved: the hit lifts the
slave's chest and shoulders first, taking the forearms off the ground, and the arms swing back in the air.
The held rifle goes with the chest as it went at the arms' (lagging) time, so the palms stay on it; from
the release on it falls as recorded.
"""

from __future__ import annotations

import numpy as np

from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smoothstep
from authoring.slave_body import played_body
from peabody import quaternion
from server.motion.channelset import Channelset

ARMS = ("clavicle", "shoulder", "elbow", "wrist")  # the joints that lag (both sides)
CHEST = "upper_torso"  # the segment the clavicles hang from: the held rifle keeps its place in its frame


def arms_source(held: int, until: int) -> np.ndarray:
    """Per frame up to ``until`` the (fractional) frame the arms take their pose from: 0 up to ``held``,
    then smoothly catching up with the clip, reaching ``until`` at ``until``."""
    t = np.arange(until + 1, dtype=np.float64)
    return until * smoothstep(np.clip((t - held) / max(until - held, 1), 0.0, 1.0))


def lag_slave_arms(slave: Channelset, figures: FigureSet, held: int, past_release: int) -> np.ndarray:
    """Hold ``slave``'s arms at their first frame's pose for ``held`` frames and let them catch up with the
    clip ``past_release`` frames after its release (joint channels and the held rifle's placement, in place;
    see the module docstring); returns the source frame of the arms in each frame changed (none without a
    release or room)."""
    release = getattr(slave, "release_frame", None)
    until = (release or 0) + past_release
    if release is None or held <= 0 or until >= slave.nframes or held >= release:
        return np.zeros(0)
    q, loc, body = played_body(slave, figures)
    chest = figures.kin[body].segment_globals(q, loc)[:, figures.kin[body].segment_names.index(CHEST)]
    src = arms_source(held, until)
    i = np.minimum(np.floor(src).astype(int), until - 1)
    w = src - i
    cols = [c.column + k for c in slave.joint_channels() if c.name.endswith(ARMS) for k in range(c.width)]
    joints = slave.joint_data[:, cols].astype(np.float64)
    slave.joint_data[: until + 1, cols] = (joints[i] + w[:, None] * (joints[i + 1] - joints[i])).astype(
        slave.joint_data.dtype
    )
    for chan in slave.figure_channels():  # the held rifle: where it was in the chest's frame at that time
        if chan.protofiletype == body:
            continue
        held_in = np.linalg.inv(chest) @ slave.transforms(chan)
        pos = held_in[:, :3, 3]
        rot = quaternion.make_continuous(quaternion.from_matrix(held_in[:, :3, :3]))
        at = quaternion.to_transform(
            pos[i] + w[:, None] * (pos[i + 1] - pos[i]), quaternion.slerp(rot[i], rot[i + 1], w)
        )
        placed = chest[: until + 1] @ at
        k, n = chan.column, release + 1
        slave.fig_pos[:n, k] = placed[:n, :3, 3].astype(slave.fig_pos.dtype)
        slave.fig_quat[:n, k] = quaternion.from_matrix(placed[:n, :3, :3]).astype(slave.fig_quat.dtype)
    return src
