"""Easing a recorded clip in and out of its static postures by retiming it."""

from __future__ import annotations

import numpy as np
import pytest

from authoring import easing
from authoring.transitions import ClipFrames
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from ttes.paths import FIGURES


@pytest.fixture(scope="module")
def kins() -> tuple[FigureKinematics, FigureKinematics]:
    return FigureKinematics(read_figure(FIGURES / "soldier.fig")), FigureKinematics(
        read_figure(FIGURES / "AK_47.fig")
    )


def sliding_clip(kin: FigureKinematics, n: int = 49, speed: float = 150.0) -> ClipFrames:
    """The neutral soldier and his rifle gliding along +X at ``speed`` cm/s from the first frame to the last
    (a clip that starts and stops dead), the right elbow bending as he goes."""
    t = np.arange(n) / 60.0
    poses = np.tile(kin.neutral_pose(), (n, 1))
    elbow = kin.dof_slices["right_elbow"].start
    poses[:, elbow] = kin.clamp(poses)[:, elbow] + 0.5 * t / t[-1]
    roots = np.tile(np.eye(4), (n, 1, 1))
    roots[:, 0, 3] = speed * t
    roots[:, 1, 3] = 100.0
    rifles = roots.copy()
    rifles[:, 2, 3] = -30.0
    return ClipFrames(poses, roots, rifles)


def test_warp_keeps_the_ends_and_starts_at_rest():
    tau = easing.warp(61, 60.0, 0.2, 0.1)
    assert tau[0] == 0.0 and tau[-1] == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.diff(tau) > 0)
    rate = np.diff(tau) * 60.0
    assert rate[0] < 0.02 and rate[-1] < 0.05 and rate[30] > 1.0  # faster between the ramps
    np.testing.assert_allclose(easing.warp(61, 60.0, 0.0, 0.0), np.arange(61) / 60.0, atol=1e-12)


def test_ease_ends_slows_both_ends_and_keeps_the_path(kins):
    kin, rkin = kins
    clip = sliding_clip(kin)
    before = easing.end_speeds(kin, rkin, clip)
    assert min(before) > 1.0
    eased = easing.ease_ends(kin, rkin, clip)
    assert eased.poses.shape == clip.poses.shape
    assert max(easing.end_speeds(kin, rkin, eased)) <= easing.END_SPEED
    for a, b in ((eased.poses, clip.poses), (eased.roots, clip.roots), (eased.rifles, clip.rifles)):
        np.testing.assert_allclose(a[[0, -1]], b[[0, -1]], atol=1e-12)  # the key postures exactly
    x = eased.roots[:, 0, 3]
    assert np.all(np.diff(x) >= 0)  # the same path, only retimed: never back and forth
    elbow = kin.dof_slices["right_elbow"].start
    np.testing.assert_allclose(  # the elbow still bends in step with the glide
        np.interp(x, clip.roots[:, 0, 3], clip.poses[:, elbow]), eased.poses[:, elbow], atol=1e-9
    )


def test_ease_ends_leaves_a_clip_at_rest_alone(kins):
    kin, rkin = kins
    clip = sliding_clip(kin, speed=10.0)
    assert easing.ease_ends(kin, rkin, clip) is clip
    only_start = easing.ease_ends(kin, rkin, sliding_clip(kin), end=False)
    v = easing.site_speeds(kin, rkin, only_start)
    assert v[:3].max() <= easing.END_SPEED and v[-1] > 1.0


def test_eased_in_leaves_from_rest_and_keeps_the_speed_after(kins):
    """A recorded fall leaves its start posture from rest (prone deaths: 0.46 m/s over the first frames, the
    DI/M16 slaves 0.57-0.67); lengthened by half the ramp instead of played faster after it."""
    kin, rkin = kins
    clip = sliding_clip(kin, n=121)
    eased, times = easing.eased_in(clip, 0.25)
    assert len(eased.poses) == 121 + round(0.25 * 60.0 / 2.0) and len(times) == len(eased.poses)
    v = easing.site_speeds(kin, rkin, eased)
    assert easing.end_speeds(kin, rkin, clip)[0] > 1.0 and v[:3].max() <= 0.15  # from rest
    np.testing.assert_allclose(v[30:], 1.5, rtol=0.02)  # after the ramp: the recorded speed, 150 cm/s
    for a, b in ((eased.poses, clip.poses), (eased.roots, clip.roots), (eased.rifles, clip.rifles)):
        np.testing.assert_allclose(a[[0, -1]], b[[0, -1]], atol=1e-9)  # the start and the end as recorded
    assert times[0] == 0.0 and times[-1] == pytest.approx(120 / 60.0) and np.all(np.diff(times) > 0)
