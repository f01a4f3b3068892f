"""Pacing a clip so its rifle turns no faster than a limit (:mod:`authoring.rifle_pace`), on constructed
turn profiles: the fast swing is slowed, the clip keeps its length and ends, the rest plays faster but no
joint turns faster than the cap."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring.rifle_pace import JOINT_STEP_DEG, paced_times

FPS = 60.0


def _played(per_step: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Per output frame step, how much of ``per_step`` (per source step) the retimed clip plays."""
    total = np.concatenate([[0.0], np.cumsum(per_step)])
    return np.diff(np.interp(times * FPS, np.arange(len(total)), total))


def test_a_fast_swing_is_slowed_and_the_rest_sped_up() -> None:
    turns = np.full(84, 0.5)  # degrees per frame: 30 per second
    turns[50:70] = 4.0  # 240 degrees per second for a third of a second (kstow2crawl's swing)
    joints = np.full(84, 3.0)
    times = paced_times(turns, joints, FPS, 120.0)
    assert len(times) == 85 and times[0] == 0.0 and times[-1] == pytest.approx(84 / FPS)
    assert np.all(np.diff(times) > 0)  # it never stops nor goes back
    rate = _played(turns, times) * FPS
    assert rate.max() <= 120.0 * 1.1  # was 240
    fast = _played(joints, times)
    assert 3.0 < fast.max() <= JOINT_STEP_DEG  # the slow part plays faster, within the cap


def test_joints_already_fast_are_not_sped_past_the_cap() -> None:
    turns = np.full(84, 0.5)
    turns[60:75] = 4.0
    joints = np.full(84, 2.0)
    joints[10:16] = 11.0  # a knee folding fast: not sped up past the cap
    played = _played(joints, paced_times(turns, joints, FPS, 120.0))
    assert played.max() <= JOINT_STEP_DEG * 1.02  # about: the rate is smoothed


def test_a_rifle_that_turns_slowly_is_left_alone() -> None:
    turns = np.full(40, 1.5)  # 90 degrees per second
    times = paced_times(turns, np.full(40, 5.0), FPS, 120.0)
    np.testing.assert_array_equal(times, np.arange(41) / FPS)
