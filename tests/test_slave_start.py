"""A dying slave leaves its start posture from rest (authoring/slave_start.py; issue 14: prstow2dead's DI,
laid by its spine, moved its head 0.59 m/s in its first frames, the check's end_speed limit 0.5)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from authoring.slave_start import ease_slave_start
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from ttes.paths import CHANNELSETS


@pytest.fixture(scope="module")
def slave() -> Channelset:
    return load_channelset(CHANNELSETS / "prfire2dead_low.chset.env", use_cache=False)


def test_a_slave_start_moving_at_once_leaves_from_rest_and_keeps_its_release(slave: Channelset) -> None:
    """Constructed: the committed DI prfire2dead slave, its root carried 1 cm a frame from its first frame
    to its release (a start at 0.6 m/s)."""
    cs = copy.deepcopy(slave)
    release = cs.release_frame
    assert release is not None and release > 6
    n = cs.nframes
    push = np.minimum(np.arange(n), release).astype(np.float32)  # cm, along x: moving from the first frame
    cs.fig_pos[:, :, 0] += push[:, None]
    before = copy.deepcopy(cs)
    src = ease_slave_start(cs, 0.08)
    assert src[0] == 0.0 and src[-1] == pytest.approx(release)
    assert (np.diff(src) > 0).all()  # played forward, only its timing changed
    x = cs.fig_pos[:, 0, 0] - slave.fig_pos[:, 0, 0]
    assert abs(np.diff(before.fig_pos[: release + 1, 0, 0] - slave.fig_pos[: release + 1, 0, 0])[0]) > 0.99
    steps = np.abs(np.diff(x[:4]))  # from rest: its speed rising over the first frames, never reached there
    assert steps[0] < 0.1 and (np.diff(steps) > 0).all() and steps.max() < 0.7
    np.testing.assert_array_equal(cs.joint_data[0], before.joint_data[0])  # the start posture as it was
    np.testing.assert_allclose(cs.joint_data[release:], before.joint_data[release:], atol=1e-6)  # and after
    np.testing.assert_allclose(cs.fig_pos[release:], before.fig_pos[release:], atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(cs.fig_quat, axis=-1), 1.0, atol=1e-5)


def test_a_slave_without_a_ramp_or_room_for_one_is_left_alone(slave: Channelset) -> None:
    cs = copy.deepcopy(slave)
    assert not len(ease_slave_start(cs, 0.0))
    assert not len(ease_slave_start(cs, 10.0))  # longer than its frames before the release
    np.testing.assert_array_equal(cs.joint_data, slave.joint_data)
    np.testing.assert_array_equal(cs.fig_pos, slave.fig_pos)
