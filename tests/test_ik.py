"""The authoring IK solver: reaching, priorities, joint limits, best effort, closed-form two-link chains."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from authoring.ik import Goal, decompose_rotation, rotation_log, solve, two_link
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from peabody.rotations import axis_angle

FIGURES = Path(__file__).resolve().parents[1] / "figures"
PALM = "right_palm.palmcenter"
ELBOW = "right_upper_arm.distal"
ANKLE = "left_foot.proximal"


@pytest.fixture(scope="module")
def kin() -> FigureKinematics:
    return FigureKinematics(read_figure(FIGURES / "DI.fig", load_psurfs=False))


def _pos(kin: FigureKinematics, site: str, q: np.ndarray) -> np.ndarray:
    return kin.site_global(site, q)[:3, 3]


def _random_poses(kin: FigureKinematics, n: int, seed: int, spread: float = 0.35) -> np.ndarray:
    """Poses within the limits, around the neutral pose."""
    rng = np.random.default_rng(seed)
    span = np.minimum(kin.upper - kin.lower, 2.0)
    q = kin.neutral_pose() + rng.uniform(-1, 1, (n, kin.ndof)) * spread * span / 2
    return np.clip(q, kin.lower, kin.upper)


def test_reaches_a_reachable_goal_within_a_millimetre(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    target = _pos(kin, PALM, q0) + np.array([10.0, 30.0, -25.0])
    q, report = solve(kin, q0, [Goal(PALM, target)])
    assert np.linalg.norm(_pos(kin, PALM, q) - target) < 0.1
    assert report.position_error.shape == (1,)
    assert report.position_error[0] < 0.1
    assert bool(report.converged)


def test_batch_of_frames_reaches_targets_made_by_fk(kin: FigureKinematics) -> None:
    """Targets produced by FK of poses within the limits are reachable; all frames solve in one call."""
    goal_poses = _random_poses(kin, 24, seed=1)
    g = kin.site_globals(goal_poses)
    sites = ["right_palm.palmcenter", "left_palm.palmcenter", "left_foot.heel"]
    targets = {s: g[:, kin.site_names.index(s), :3, 3] for s in sites}
    start = np.tile(kin.neutral_pose(), (24, 1))
    q, report = solve(kin, start, [Goal(s, targets[s]) for s in sites], iterations=100)
    assert q.shape == (24, kin.ndof)
    assert report.position_error.shape == (24, 3)
    assert report.max_position_error < 0.1
    got = kin.site_globals(q)
    for s in sites:
        assert np.abs(got[:, kin.site_names.index(s), :3, 3] - targets[s]).max() < 0.1


def test_higher_priority_goal_is_not_disturbed_by_a_conflicting_lower_one(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    palm_target = _pos(kin, PALM, q0) + np.array([0.0, 25.0, -20.0])
    elbow_target = _pos(kin, ELBOW, q0) + np.array([40.0, -30.0, 30.0])  # pulls the arm elsewhere
    goals = [Goal(PALM, palm_target, priority=1), Goal(ELBOW, elbow_target, priority=0)]
    q, report = solve(kin, q0, goals, iterations=150)
    assert report.position_error[0] < 0.1  # the important goal holds
    assert report.position_error[1] > 5.0  # the conflict is real
    # the lower goal still did what it could: closer than with the palm goal alone
    q_alone, _ = solve(kin, q0, goals[:1], iterations=150)
    assert np.linalg.norm(_pos(kin, ELBOW, q) - elbow_target) < np.linalg.norm(
        _pos(kin, ELBOW, q_alone) - elbow_target
    )
    # at equal priority the two compromise, so the palm goal is no longer met
    _, same = solve(kin, q0, [Goal(PALM, palm_target), Goal(ELBOW, elbow_target)], iterations=150)
    assert same.position_error[0] > 0.5


def test_joint_limits_are_respected(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    # the heel pulled up in front of the shin asks for knee hyperextension and extreme hip flexion
    heel = _pos(kin, "left_foot.heel", q0)
    q, _report = solve(kin, q0, [Goal("left_foot.heel", heel + np.array([0.0, 60.0, -80.0]))])
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)
    knee = q[kin.dof_slices["left_knee"]]
    assert knee[0] >= 0.0
    # random goals from random starts never leave the limits
    starts = _random_poses(kin, 16, seed=3, spread=0.9)
    rng = np.random.default_rng(4)
    targets = _pos(kin, PALM, kin.neutral_pose()) + rng.uniform(-60, 60, (16, 3))
    qb, _ = solve(kin, starts, [Goal(PALM, targets)], iterations=40)
    assert np.all(qb >= kin.lower) and np.all(qb <= kin.upper)


def test_unreachable_goal_gives_a_finite_best_effort_and_reports_the_residual(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    far = np.array([150.0, 320.0, -250.0])
    q, report = solve(kin, q0, [Goal(PALM, far)])
    assert np.all(np.isfinite(q))
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)
    d = np.linalg.norm(_pos(kin, PALM, q) - far)
    assert report.position_error[0] == pytest.approx(d, rel=1e-9)
    assert d < np.linalg.norm(_pos(kin, PALM, q0) - far) - 30.0  # it reached towards the goal
    assert not bool(report.converged)


def test_orientation_goal_and_orientation_only_goal(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    g0 = kin.site_global(PALM, q0)
    rot = axis_angle(np.array([0.0, 1.0, 0.0]), np.array(0.5)) @ g0[:3, :3]
    target = g0[:3, 3] + np.array([0.0, 20.0, -20.0])
    q, _report = solve(kin, q0, [Goal(PALM, target, rot)])
    g = kin.site_global(PALM, q)
    assert np.linalg.norm(g[:3, 3] - target) < 0.1
    assert np.linalg.norm(rotation_log(rot @ g[:3, :3].T)) < 2e-3
    head = "bottom_head.sight"
    h0 = kin.site_global(head, q0)
    turn = axis_angle(np.array([0.0, 1.0, 0.0]), np.array(0.4)) @ h0[:3, :3]
    q2, r2 = solve(kin, q0, [Goal(head, None, turn, joints=["neck", "head"])])
    assert r2.orientation_error[0] < 2e-3
    assert r2.position_error[0] == 0.0
    moved = np.flatnonzero(np.abs(q2 - q0) > 1e-9)
    allowed = set(range(kin.dof_slices["neck"].start, kin.dof_slices["head"].stop))
    assert set(moved.tolist()) <= allowed  # only the goal's joint chain moved


def test_zero_weight_switches_a_goal_off_per_frame(kin: FigureKinematics) -> None:
    q0 = np.tile(kin.neutral_pose(), (2, 1))
    target = _pos(kin, PALM, q0[0]) + np.array([0.0, 20.0, -20.0])
    q, report = solve(kin, q0, [Goal(PALM, target, weight=np.array([1.0, 0.0]))])
    assert report.position_error[0, 0] < 0.1
    np.testing.assert_array_equal(q[1], q0[1])  # frame 1 had nothing to do
    assert report.converged.tolist() == [True, True]


def test_root_dofs_let_the_pelvis_move(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    pelvis = "lower_torso.proximal"
    feet = [Goal(s, _pos(kin, s, q0)) for s in ("left_foot.heel", "right_foot.heel")]
    down = Goal(pelvis, _pos(kin, pelvis, q0) - np.array([0.0, 20.0, 0.0]))
    q, report = solve(kin, q0, [*feet, down], root_dofs=("ty",))
    assert report.root_location is not None
    assert report.root_location[1, 3] == pytest.approx(kin.figure.location[1, 3] - 20.0, abs=0.05)
    assert report.max_position_error < 0.1
    assert q[kin.dof_slices["left_knee"]][0] > 0.3  # the knees bent to keep the heels down
    with pytest.raises(ValueError, match="root DOF"):
        solve(kin, q0, feet, root_dofs=("yaw",))


def test_two_link_analytic_matches_the_iterative_solver(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    targets = _pos(kin, ANKLE, q0) + np.array([[0.0, 15.0, -10.0], [5.0, 25.0, 10.0], [-4.0, 8.0, 3.0]])
    qa, res = two_link(kin, np.tile(q0, (3, 1)), "left_hip", "left_knee", ANKLE, targets)
    assert res.max() < 1e-6
    knee = kin.dof_slices["left_knee"]
    for i, t in enumerate(targets):
        qi, rep = solve(kin, q0, [Goal(ANKLE, t, joints=["left_hip", "left_knee"])], tolerance=1e-4)
        assert rep.position_error[0] < 1e-3
        # the knee flexion of a hip-knee-ankle reach is unique; the hip's swivel is not
        assert qa[i, knee][0] == pytest.approx(qi[knee][0], abs=2e-3)
    # the elbow chain works too (elbow flexion is DOF 0 of the 2-DOF elbow)
    wrist = "right_lower_arm.distal"
    t = _pos(kin, wrist, q0) + np.array([0.0, 20.0, -15.0])
    qe, r = two_link(kin, q0, "right_shoulder", "right_elbow", wrist, t)
    assert float(r) < 1e-6
    assert np.all(qe >= kin.lower) and np.all(qe <= kin.upper)


def test_two_link_out_of_reach_stretches_towards_the_target(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    target = _pos(kin, ANKLE, q0) + np.array([0.0, -30.0, 0.0])  # below the straight leg
    q, res = two_link(kin, q0, "left_hip", "left_knee", ANKLE, target)
    assert float(res) == pytest.approx(30.0, abs=0.5)
    assert q[kin.dof_slices["left_knee"]][0] == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError):
        two_link(kin, q0, "left_knee", "left_hip", ANKLE, target)


def test_decompose_rotation_inverts_three_dof_joints(kin: FigureKinematics) -> None:
    rng = np.random.default_rng(7)
    for joint in ("left_hip", "right_shoulder", "upper_spine"):
        axes = np.array([d.axis for d in kin.figure.joints[joint].dofs])
        sl = kin.dof_slices[joint]
        angles = rng.uniform(kin.lower[sl] * 0.9, kin.upper[sl] * 0.9, (200, 3))
        angles = np.clip(angles, -1.4, 1.4)  # away from gimbal lock of the middle axis
        m = (
            axis_angle(np.broadcast_to(axes[0], (200, 3)), angles[:, 0])
            @ axis_angle(np.broadcast_to(axes[1], (200, 3)), angles[:, 1])
            @ axis_angle(np.broadcast_to(axes[2], (200, 3)), angles[:, 2])
        )
        back = decompose_rotation(m, axes, hint=angles + 0.05)
        np.testing.assert_allclose(back, angles, atol=1e-9)


def test_bad_goals_raise_documented_errors(kin: FigureKinematics) -> None:
    q0 = kin.neutral_pose()
    with pytest.raises(KeyError, match="no site"):
        solve(kin, q0, [Goal("left_palm.nowhere", np.zeros(3))])
    with pytest.raises(KeyError, match="no joint"):
        solve(kin, q0, [Goal(PALM, np.zeros(3), joints=["tail"])])
    with pytest.raises(ValueError, match="DOFs"):
        solve(kin, q0[:-1], [Goal(PALM, np.zeros(3))])
    with pytest.raises(ValueError, match="neither"):
        solve(kin, q0, [Goal(PALM)])
    with pytest.raises(ValueError, match="weights"):
        solve(kin, q0, [Goal(PALM, np.zeros(3), weight=-1.0)])


def test_soldier_goals_solve_on_the_cut_down_figure_and_leave_other_branches_alone() -> None:
    kin = FigureKinematics(read_figure(FIGURES / "soldier.fig", load_psurfs=False))
    q0 = kin.neutral_pose()
    q0[kin.dof_slices["left_index_pip"]] = 0.5  # a finger no goal depends on
    q0[kin.dof_slices["right_knee"]] = -0.2  # outside its limits: clipped like every DOF
    targets = kin.site_globals(q0)
    palm = targets[kin.site_names.index(PALM), :3, 3] + np.array([5.0, 20.0, -20.0])
    heel = targets[kin.site_names.index("left_foot.heel"), :3, 3]
    q, report = solve(kin, q0, [Goal(PALM, palm, priority=1), Goal("left_foot.heel", heel)])
    assert report.max_position_error < 0.1
    assert np.linalg.norm(kin.site_global(PALM, q)[:3, 3] - palm) < 0.1
    assert q[kin.dof_slices["left_index_pip"]][0] == 0.5
    assert q[kin.dof_slices["right_knee"]][0] == 0.0
    moved = {j for j, sl in kin.dof_slices.items() if np.any(q[sl] != np.clip(q0, kin.lower, kin.upper)[sl])}
    assert moved and all(not j.startswith(("left_index", "left_eye", "right_eye")) for j in moved)
