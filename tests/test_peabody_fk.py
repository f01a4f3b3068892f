"""Forward kinematics: hand-computed figures, re-rooting, batches, joint paths, the pose layout."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from peabody import values as V
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.loader import load_text, read_figure
from peabody.model import Figure

DATA = Path(__file__).parent / "data" / "peabody"


def arm() -> Figure:
    return read_figure(DATA / "arm.fig", load_psurfs=False)


def pos(m: np.ndarray) -> np.ndarray:
    return m[:3, 3]


def test_pose_vector_layout() -> None:
    fk = FigureKinematics(read_figure(DATA / "slider.fig"))
    assert fk.joint_names == ["lift", "wrist"]
    assert fk.dof_slices == {"lift": slice(0, 1), "wrist": slice(1, 3)}
    assert fk.ndof == 3
    assert np.allclose(fk.lower, [0, -np.inf, -np.inf]) and np.allclose(fk.upper, [100, np.inf, np.inf])
    assert np.allclose(fk.neutral_pose(), [25, math.pi / 2, 0])
    assert fk.segment_names == ["rail", "carriage", "head"]
    assert fk.site_names == [
        "rail.top",
        "rail.origin",
        "carriage.mount",
        "carriage.tool",
        "head.base",
        "head.tip",
    ]
    assert fk.root_name == "rail.origin"


def test_two_link_arm_matches_hand_computation() -> None:
    fk = FigureKinematics(arm())
    for q1, q2 in [(0.0, 0.0), (0.3, 0.5), (-1.2, 2.0)]:
        hand = fk.site_global("lower.distal", np.array([q1, q2]))
        # base.bottom at the origin -> shoulder at (0, 10, 0); links of 30 and 20 cm rotating about z
        expect = (
            -30 * math.sin(q1) - 20 * math.sin(q1 + q2),
            10 + 30 * math.cos(q1) + 20 * math.cos(q1 + q2),
            0,
        )
        assert np.allclose(pos(hand), expect)
        assert np.allclose(hand[:3, :3], V.rot_z(q1 + q2 + math.pi / 2)[:3, :3])
        upper = fk.segment_global("upper", np.array([q1, q2]))
        assert np.allclose(upper, V.translation(0, 10, 0) @ V.rot_z(q1) @ V.translation(-2, 0, -2))
    base = fk.segment_global("base")
    assert np.allclose(base, V.translation(-10, 0, -10))


def test_prismatic_joint_and_arbitrary_axis() -> None:
    fk = FigureKinematics(read_figure(DATA / "slider.fig"))
    tip = fk.site_global("head.tip")  # neutral: lift 25 cm down from y=100, wrist R(y) 90deg
    assert np.allclose(pos(tip), (0, 75, -5))
    q = np.array([60.0, 0.0, math.pi])  # half turn about (1,0,1)/sqrt2 maps x to z
    assert np.allclose(pos(fk.site_global("head.tip", q)), (0, 40, 15))
    assert np.allclose(pos(fk.site_global("carriage.mount", q)), (0, 40, 0))


def test_rooting_at_a_non_base_site() -> None:
    fig = arm()
    fk0 = FigureKinematics(fig)
    q = np.array([0.4, 1.1])
    old = fk0.segment_globals(q)
    hand_old = fk0.site_global("lower.distal", q)
    fig.root = fig.site("lower.distal")
    fig.location = V.translation(5, 6, 7) @ V.rot_y(0.3)
    fk = FigureKinematics(fig)
    new = fk.segment_globals(q)
    # the hand sits at the figure location and the rest follows rigidly
    assert np.allclose(fk.site_global("lower.distal", q), fig.location)
    assert np.allclose(new, fig.location @ np.linalg.inv(hand_old) @ old)
    # hand-computed: base.bottom seen from the hand at the identity, pose zero
    fig.location = np.eye(4)
    bottom = FigureKinematics(fig).site_global("base.bottom", np.zeros(2))
    # with q = 0 the hand is at (0, 60, 0) rotated +90deg about z from the base, so base.bottom is
    # 60 cm along the hand's -x... : inverse of T(0,60,0) Rz(90)
    assert np.allclose(bottom, np.linalg.inv(V.translation(0, 60, 0) @ V.rot_z(math.pi / 2)))


def _reference_segment_globals(figure: Figure, q: np.ndarray) -> dict[str, np.ndarray]:
    """A deliberately naive single-pose FK straight from the model docstring."""
    fk = FigureKinematics(figure)
    values = {name: q[fk.dof_slices[name]] for name in figure.joints}
    root = figure.root
    assert root is not None and root.segment is not None
    out = {root.segment.name: figure.location @ np.linalg.inv(root.location)}
    pending = list(figure.joints.values())
    while pending:
        for joint in list(pending):
            s1, s2 = joint.site1, joint.site2
            d = V.dofs_matrix(joint.dofs, values[joint.name]) if joint.dofs else joint.displacement
            if s1.segment.name in out:  # type: ignore[union-attr]
                g1 = out[s1.segment.name] @ s1.location  # type: ignore[union-attr]
                out[s2.segment.name] = g1 @ d @ np.linalg.inv(s2.location)  # type: ignore[union-attr]
            elif s2.segment.name in out:  # type: ignore[union-attr]
                g2 = out[s2.segment.name] @ s2.location  # type: ignore[union-attr]
                out[s1.segment.name] = g2 @ np.linalg.inv(d) @ np.linalg.inv(s1.location)  # type: ignore[union-attr]
            else:
                continue
            pending.remove(joint)
    return out


@pytest.mark.parametrize("root", ["base.bottom", "upper.distal", "lower.proximal"])
def test_batched_equals_single_pose_and_reference(root: str) -> None:
    fig = arm()
    fig.root = fig.site(root)
    fig.location = V.xyz_matrix(0.1, 0.2, 0.3) @ V.translation(1, 2, 3)
    fk = FigureKinematics(fig)
    rng = np.random.default_rng(7)
    poses = rng.uniform(-2, 2, size=(4, 5, fk.ndof))
    batch = fk.segment_globals(poses)
    sites = fk.site_globals(poses)
    assert batch.shape == (4, 5, 3, 4, 4) and sites.shape == (4, 5, 6, 4, 4)
    for i in range(4):
        for j in range(5):
            ref = _reference_segment_globals(fig, poses[i, j])
            for k, name in enumerate(fk.segment_names):
                assert np.allclose(batch[i, j, k], ref[name])
                assert np.allclose(fk.segment_global(name, poses[i, j]), ref[name])
            for k, name in enumerate(fk.site_names):
                assert np.allclose(sites[i, j, k], fk.site_global(name, poses[i, j]))


def test_figure_with_reversed_multi_dof_and_constant_joints() -> None:
    fig = load_text(
        """figure chain {
          segment a { site s->location = trans(1, 0, 0); site r->location = xyz(0.2, 0, 0) * trans(0,0,0); }
          segment b { site p->location = trans(0, 2, 0); site q->location = xyz(0, 0.5, 0) * trans(0,0,3); }
             segment c { site p->location = trans(0, 0, 1); }
             joint ab { connect a.s to b.p; type = R(z) * T(x) * R(1, 2, 3) * R(-x); }
             joint bc { connect c.p to b.q; displacement = xyz(0.1, 0.2, 0.3) * trans(4, 5, 6); }
             root = c.p;
           }"""
    ).figures["chain"]
    fk = FigureKinematics(fig)
    poses = np.random.default_rng(1).uniform(-1, 1, size=(6, fk.ndof))
    batch = fk.segment_globals(poses)
    for i, q in enumerate(poses):
        ref = _reference_segment_globals(fig, q)
        for k, name in enumerate(fk.segment_names):
            assert np.allclose(batch[i, k], ref[name])


def test_root_location_per_pose() -> None:
    fk = FigureKinematics(arm())
    locs = np.stack([V.translation(i, 0, 0) for i in range(3)])
    out = fk.site_globals(np.zeros((3, 2)), root_location=locs)
    assert np.allclose(out[:, 0, :3, 3], [[0, 0, 0], [1, 0, 0], [2, 0, 0]])  # base.bottom is the root
    one_pose_many_places = fk.segment_globals(np.zeros(2), root_location=locs)
    assert one_pose_many_places.shape == (3, 3, 4, 4)


def test_joint_path() -> None:
    fk = FigureKinematics(arm())
    assert fk.joint_path("base.bottom", "lower.distal") == [("shoulder", True), ("elbow", True)]
    assert fk.joint_path("lower.distal", "base.shoulder") == [("elbow", False), ("shoulder", False)]
    assert fk.joint_path("upper.proximal", "upper.distal") == []
    with pytest.raises(KeyError):
        fk.joint_path("base.nowhere", "upper.distal")


def test_set_pose_clamp_and_site_global_setter() -> None:
    fig = arm()
    fk = FigureKinematics(fig)
    fk.set_pose(np.array([0.1, 0.2]))
    assert [d.value for j in fig.joints.values() for d in j.dofs] == [0.1, 0.2]
    assert np.allclose(fk.clamp(np.array([-5.0, 5.0])), [-math.pi / 2, math.radians(150)])
    target = V.translation(3, 4, 5)
    fig.location = fk.location_for_site_global("lower.distal", target)
    assert np.allclose(FigureKinematics(fig).site_global("lower.distal"), target)


def test_bad_pose_shapes_and_trees() -> None:
    fk = FigureKinematics(arm())
    with pytest.raises(ValueError, match="2 DOFs"):
        fk.segment_globals(np.zeros(3))
    fig = arm()
    fig.joints["elbow"].site2 = fig.site("base.bottom")  # base-upper-base: a loop, and lower cut off
    with pytest.raises(ValueError):
        FigureKinematics(fig)


def test_rigid_inverse() -> None:
    m = V.xyz_matrix(0.3, -0.2, 1.0) @ V.translation(4, 5, 6)
    assert np.allclose(rigid_inverse(m), np.linalg.inv(m))
    assert np.allclose(rigid_inverse(np.stack([m, m])), np.linalg.inv(m))
