"""A simulated death's skid along the ground is taken out of its root (authoring.planted)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.body_parts import DIRECTIONS, contact_runs, contact_slides
from authoring.planted import WORST_DIRECTIONS, _run_extents, _turned, ground_drift, least_worst_shift, plant
from authoring.postures import lowest_point
from authoring.transitions import ClipFrames
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from ttes.paths import FIGURES


@pytest.fixture(scope="module")
def soldier():
    return read_figure(FIGURES / "soldier.fig")


def _standing(soldier, n: int, step: np.ndarray, height: float = 0.0) -> ClipFrames:
    """The neutral pose standing ``height`` cm above the ground, moved by ``step`` (cm) every frame."""
    kin = FigureKinematics(soldier)
    pose = np.zeros(kin.ndof)
    root = np.eye(4)
    root[1, 3] -= float(lowest_point(kin, pose, root)) - height
    roots = np.repeat(root[None], n, axis=0)
    roots[:, :3, 3] += np.arange(n)[:, None] * step
    return ClipFrames(np.repeat(pose[None], n, axis=0), roots, roots.copy(), 60.0)


def test_a_body_skidding_on_the_ground_stays_put(soldier) -> None:
    clip = _standing(soldier, 12, np.array([0.8, 0.0, -0.5]))
    out = plant(clip, soldier)
    np.testing.assert_allclose(out.roots[:, :3, 3], clip.roots[:1, :3, 3].repeat(12, axis=0), atol=1e-9)
    np.testing.assert_allclose(out.rifles[:, :3, 3], out.roots[:, :3, 3], atol=1e-9)  # the rifle goes along
    np.testing.assert_array_equal(out.poses, clip.poses)


def test_a_body_off_the_ground_is_left_as_it_is(soldier) -> None:
    clip = _standing(soldier, 6, np.array([2.0, 0.0, 0.0]), height=3.0)
    np.testing.assert_array_equal(plant(clip, soldier).roots, clip.roots)


def test_the_drift_is_shared_out_over_the_parts_not_the_nodes() -> None:
    """One part with many nodes does not outweigh another with few; a part touching in one frame only, and
    vertical motion, count for nothing."""
    points = np.zeros((2, 5, 3))
    points[1, :4] += [1.0, -0.5, 0.0]  # "a": four nodes slide 1 cm (and sink a little)
    touching = np.array([[True] * 4 + [True], [True] * 4 + [True]])
    parts = np.array(["a", "a", "a", "a", "b"])  # "b": one node stays
    np.testing.assert_allclose(ground_drift(points, touching, parts), np.array([[0, 0, 0], [0.5, 0, 0]]))
    touching[0, 4] = False
    np.testing.assert_allclose(ground_drift(points, touching, parts)[1], [1.0, 0, 0])


def _slide(points: np.ndarray, shift: np.ndarray, node: int) -> float:
    """How far (cm, horizontal) one node moves over the frames, the body shifted by ``shift``."""
    xz = (points[:, node] + shift)[:, [0, 2]]
    return float(np.linalg.norm(xz - xz[0], axis=1).max())


def test_a_dragged_foot_does_not_skid_the_thigh_that_lies_still() -> None:
    """A thigh lies still while a foot drags 7.2 cm (kstow2dead: the mean drift slid the thigh 3.1 -> 4.5 cm):
    the mean shares the skid out (3.6 cm each), the least worst keeps the thigh put and leaves the foot to
    the legs' lift."""
    n = 10
    points = np.zeros((n, 2, 3))
    points[:, 1, 0] = 0.8 * np.arange(n)  # the foot drags along x
    parts = np.array(["left_thigh", "left_foot"])
    mean = -np.cumsum(ground_drift(points, np.ones((n, 2), dtype=bool), parts), axis=0)
    assert _slide(points, mean, 0) == pytest.approx(3.6)
    shift = least_worst_shift(points, parts)
    assert _slide(points, shift, 0) < 0.05
    np.testing.assert_array_equal(shift[:, 1], 0.0)  # along the ground only


def test_two_trunk_parts_share_their_relative_skid_evenly() -> None:
    """The chest drags 4 cm against the belly: neither slides more than half of it, and the correction moves
    no more than it must (none before the drag)."""
    n = 12
    points = np.zeros((n, 2, 3))
    points[2:, 1, 2] = np.minimum(0.4 * np.arange(1, n - 1), 4.0)  # the chest drags along z from frame 2
    shift = least_worst_shift(points, np.array(["belly", "chest"]))
    assert max(_slide(points, shift, 0), _slide(points, shift, 1)) == pytest.approx(2.0, abs=0.05)
    np.testing.assert_allclose(shift[:2], 0.0, atol=1e-9)


def test_a_body_spinning_on_the_ground_is_turned_back() -> None:
    """kfire2dead (kneelrest14): as he lands on his side his trunk spins about the vertical, belly and chest
    skidding opposite ways (3.3 and 3.7 cm after the least worst shift): no shift helps both; a turn about
    the vertical does (none at the first frame, at most WORST_TURN_STEP a frame)."""
    from authoring.planted import WORST_TURN_STEP, _turned

    n = 24
    spin = np.radians(0.3) * np.clip(np.arange(n) - 2, 0, 20)  # 6 degrees from frame 2 on
    points = np.zeros((n, 2, 3))
    points[:, 0, 0], points[:, 0, 2] = 30.0 * np.cos(spin), -30.0 * np.sin(spin)  # the belly ...
    points[:, 1] = -points[:, 0]  # ... and the chest, opposite it
    parts = np.array(["belly", "chest"])
    shift = least_worst_shift(points, parts)
    assert max(_slide(points, shift, 0), _slide(points, shift, 1)) > 3.0
    turned = least_worst_shift(points, parts, np.zeros(2))
    back = _turned(points, turned, np.zeros(2))
    none = np.zeros((n, 3))
    assert max(_slide(back, none, 0), _slide(back, none, 1)) < 0.2
    assert turned[0, 1] == 0.0
    assert np.abs(np.diff(turned[:, 1])).max() <= WORST_TURN_STEP + 1e-9


def test_a_turned_clip_keeps_its_first_frame_and_its_rifle_on_him(soldier) -> None:
    """least_worst_turned moves the whole figure (root and rifle) and leaves the first frame, a posture node,
    where it was; a body standing still is left still."""
    from authoring.planted import least_worst_turned

    clip = _standing(soldier, 8, np.array([0.0, 0.0, 0.0]))
    clip.rifles[:, :3, 3] += [5.0, 90.0, -10.0]
    out = least_worst_turned(clip, soldier)
    np.testing.assert_allclose(out.roots, clip.roots, atol=1e-9)
    np.testing.assert_allclose(out.rifles, clip.rifles, atol=1e-9)
    np.testing.assert_array_equal(out.poses, clip.poses)


def test_the_turn_may_measure_a_slide_as_the_check_does() -> None:
    """The least worst shift measures slides along WORST_DIRECTIONS (8); a drag between two of them reads
    shorter than along the check's 16 (kfire2dead's chest: 3.0 for the turn, 3.007 cm for the check, limit
    3). Asked to measure along the check's directions, the shift leaves each part's slide, as the check
    sees it, at half the drag."""
    n, angle = 12, np.pi / DIRECTIONS  # between two of the 8 directions
    drag = np.minimum(0.4 * np.arange(n), 4.0)
    points = np.zeros((n, 2, 3))
    points[:, 1, 0], points[:, 1, 2] = drag * np.cos(angle), drag * np.sin(angle)  # the chest drags 4 cm
    runs = contact_runs(points[:, 1:], 0.5)
    eight = _run_extents(points[:, 1:], runs, np.arange(1), np.zeros((n, 2)), WORST_DIRECTIONS)
    assert eight[0] == pytest.approx(4.0 * np.cos(angle))  # 3.92
    shift = least_worst_shift(points, np.array(["belly", "chest"]), directions=DIRECTIONS)
    seen, _ = contact_slides(_turned(points, shift, None), 0.5)
    assert seen.max() == pytest.approx(2.0, abs=1e-3)
