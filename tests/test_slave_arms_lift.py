"""A dying slave's arm in the ground comes out by the arm (authoring/slave_arms_lift.py), so the build's
lift of the whole body does not raise a trunk that already lies (issue 14: prfire2dead's DI pelvis rose
2.8 -> 6.2 cm at frames 60-75 as the master's hands came down)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring.build import BuildContext, slaving_context
from authoring.postures import segment_heights
from authoring.slave_arms_lift import lift_slave_arms
from authoring.slave_body import played_body, write_pose
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES


def test_an_arm_pushed_into_the_ground_comes_out_by_the_arm_alone() -> None:
    """Constructed: the committed DI prfire2dead slave's right clavicle turned down (3 degrees lower the
    arm 1.5 cm) over frames 60-84, after the release, until its palm is 2-3 cm in the ground."""
    master = load_channelset(CHANNELSETS / "prfire2dead.chset.env", use_cache=False)
    figs = slaving_context(BuildContext.load(FIGURES), "prfire2dead", master).figure_set  # as the build
    slave = load_channelset(CHANNELSETS / "prfire2dead_low.chset.env", use_cache=False)
    q, loc, stype = played_body(slave, figs)
    kin = figs.kin[stype]
    arm = ("right_upper_arm", "right_lower_arm", "right_palm")

    def lowest(q: np.ndarray, loc: np.ndarray) -> np.ndarray:
        h = segment_heights(kin, q, loc)
        return np.min([h[s] for s in arm], axis=0)

    n = len(q)
    u = np.sin(np.pi * np.clip((np.arange(n) - 60) / 24.0, 0.0, 1.0))
    pushed = q.copy()
    cl = kin.dof_slices["right_clavicle"].start + 1
    for _ in range(20):  # deeper until the arm is 2 cm in the ground at the middle
        if lowest(pushed, loc)[72] < -2.0:
            break
        pushed[:, cl] += np.radians(2.0) * u
    write_pose(slave, figs, stype, pushed, np.tile(np.eye(4), (n, 1, 1)))
    before = copy.deepcopy(slave)
    assert lowest(pushed, loc)[72] < -2.0
    lifted = lift_slave_arms(slave, figs)
    q1, loc1, _ = played_body(slave, figs)
    assert lifted.max() >= 2.0
    assert lowest(q1, loc1)[slave.release_frame :].min() >= -0.3  # out (the body lifts the rest)
    np.testing.assert_array_equal(slave.fig_pos, before.fig_pos)  # the body where it was
    moved = np.flatnonzero(np.abs(q1 - pushed).max(axis=1) > 1e-6)
    assert moved.min() >= slave.release_frame
    arms = ("clavicle", "shoulder", "elbow", "wrist")
    rest = [d for j, sl in kin.dof_slices.items() if not j.endswith(arms) for d in range(sl.start, sl.stop)]
    np.testing.assert_array_equal(q1[:, rest], pushed[:, rest])  # the arm alone turned
    assert np.degrees(np.abs(np.diff(q1 - pushed, axis=0)).max()) < 8.0  # eased: no one-frame turn (6.4)
