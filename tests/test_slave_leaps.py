"""Slaved arms eased through the pole of the shoulder's Euler angles (issue 14: DI's right shoulder leapt
33.8 degrees in a frame of crawl2prstow while the upper arm turned 0.8 degrees)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.slave_contacts import _landing
from authoring.slave_leaps import LEAP_DEG, ease_leaps, pole_distance
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from ttes.paths import FIGURES

ARM = ("right_clavicle", "right_shoulder", "right_elbow", "right_wrist")


@pytest.fixture(scope="module")
def kin() -> FigureKinematics:
    return FigureKinematics(read_figure(FIGURES / "DI.fig"))


def _leaping(kin: FigureKinematics, middle_deg: float) -> np.ndarray:
    """60 frames of the right shoulder at ``middle_deg`` whose first angle leaps 35 degrees at frame 30 and
    whose third angle leaps back (their sum kept)."""
    q = np.tile(kin.neutral_pose(), (60, 1))
    sl = kin.dof_slices["right_shoulder"]
    first = np.where(np.arange(60) < 30, 50.0, 15.0) + np.linspace(0.0, 5.0, 60)
    q[:, sl.start] = np.radians(first)
    q[:, sl.start + 1] = np.radians(middle_deg)
    q[:, sl.start + 2] = np.radians(60.0 - first)
    return q


def _upper_arm(kin: FigureKinematics, q: np.ndarray) -> np.ndarray:
    g = kin.segment_globals(q, np.broadcast_to(np.eye(4), (len(q), 4, 4)))
    return g[:, kin.segment_names.index("right_upper_arm"), :3, :3]


def test_a_leap_near_the_pole_is_spread_and_hardly_turns_the_arm(kin: FigureKinematics) -> None:
    q = _leaping(kin, 88.0)
    assert pole_distance(kin, "right_shoulder", q).max() < 10.0  # the third axis within 10 deg of the first
    copied = q.copy()
    copied[:, kin.dof_slices["right_shoulder"]] = q[:1, kin.dof_slices["right_shoulder"]]  # the master: still
    eased = ease_leaps(kin, q, copied, (ARM,))
    sl = kin.dof_slices["right_shoulder"]
    assert np.degrees(np.abs(np.diff(eased[:, sl], axis=0))).max() < LEAP_DEG / 2
    np.testing.assert_allclose(eased[:, sl.start] + eased[:, sl.start + 2], np.radians(60.0), atol=1e-9)
    rel = np.swapaxes(_upper_arm(kin, q), -1, -2) @ _upper_arm(kin, eased)
    turn = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)))
    assert turn.max() < 6.0  # the arm turns a few degrees where its angles moved up to 17
    np.testing.assert_array_equal(eased[[0, -1]], q[[0, -1]])  # the ends as slaved (shared at the nodes)


def test_a_leap_far_from_the_pole_or_in_the_master_too_is_left_alone(kin: FigureKinematics) -> None:
    far = _leaping(kin, 30.0)
    still = far.copy()
    still[:, kin.dof_slices["right_shoulder"]] = far[:1, kin.dof_slices["right_shoulder"]]
    np.testing.assert_array_equal(ease_leaps(kin, far, still, (ARM,)), kin.clamp(far))
    near = _leaping(kin, 88.0)
    np.testing.assert_array_equal(ease_leaps(kin, near, near, (ARM,)), kin.clamp(near))


def test_a_forearm_coming_down_for_good_is_followed_from_before_it_lands() -> None:
    master = np.concatenate([np.full(40, 6.0), np.linspace(6.0, 0.0, 10), np.zeros(10)])
    w = _landing(master)
    down = int(np.flatnonzero(master <= 1.3)[0])
    assert w[0] == 0.0 and np.all(w[down:] == 1.0) and np.all(np.diff(w) >= 0.0)
    assert 0.0 < w[down - 6] < 1.0  # eased in before touchdown
    assert not _landing(np.zeros(60)).any()  # down throughout (prone clips): the planted hold as before
    assert not _landing(master[::-1]).any()  # coming up
