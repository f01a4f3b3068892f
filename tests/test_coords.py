"""Jack (+Y up, heading 0 along −Z, cm) ↔ Performer (+Z up, heading 0 along +Y, m)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from protocol import coords

finite = st.floats(-1e4, 1e4, allow_nan=False)
vec3 = hnp.arrays(np.float64, (5, 3), elements=finite)
quats = hnp.arrays(np.float64, (5, 4), elements=st.floats(-1, 1)).filter(
    lambda q: (np.linalg.norm(q, axis=-1) > 0.1).all()
)


def test_axes_known_values() -> None:
    up, forward, right = np.eye(3)[1], -np.eye(3)[2], np.eye(3)[0]  # Jack
    assert np.allclose(coords.directions_jack_to_performer(up), [0, 0, 1])
    assert np.allclose(coords.directions_jack_to_performer(forward), [0, 1, 0])
    assert np.allclose(coords.directions_jack_to_performer(right), [1, 0, 0])
    assert np.allclose(coords.points_jack_to_performer([100.0, 200.0, -300.0]), [1.0, 3.0, 2.0])
    assert np.allclose(coords.points_performer_to_jack([1.0, 3.0, 2.0]), [100.0, 200.0, -300.0])
    assert np.isclose(np.linalg.det(coords.JACK_TO_PERFORMER), 1.0)  # a proper rotation: handedness kept


def test_compass_headings() -> None:
    assert np.allclose(
        coords.compass_to_direction([0.0, 90.0, 180.0, 270.0]),
        [[0, 1, 0], [1, 0, 0], [0, -1, 0], [-1, 0, 0]],
        atol=1e-12,
    )
    assert np.allclose(
        coords.direction_to_compass(np.array([[1.0, 0, 0], [0, -1.0, 0], [-1.0, 1.0, 5.0]])), [90, 180, 315]
    )
    # Jack yaw: right-handed about +Y from -Z; compass 90 (east, +X) is a yaw of -90 degrees
    yaw = coords.compass_to_jack_yaw(90.0)
    assert np.isclose(yaw, -np.pi / 2)
    forward_jack = np.array([-np.sin(yaw), 0.0, -np.cos(yaw)])  # R_y(yaw) applied to -Z
    assert np.allclose(coords.directions_jack_to_performer(forward_jack), coords.compass_to_direction(90.0))
    assert np.allclose(
        coords.jack_yaw_to_compass(coords.compass_to_jack_yaw([10.0, 350.0, 725.0])), [10, 350, 5]
    )


def test_heading_transform_faces_the_compass_heading() -> None:
    t = coords.heading_transform([0.0, 90.0], np.array([[1.0, 2.0, 0.0], [0.0, 0.0, 0.0]]))
    forward = t[:, :3, :3] @ np.array([0.0, 1.0, 0.0])
    assert np.allclose(forward, [[0, 1, 0], [1, 0, 0]], atol=1e-12)
    assert np.allclose(t[0, :3, 3], [1, 2, 0])


@given(vec3)
def test_points_round_trip(p: np.ndarray) -> None:
    assert np.allclose(coords.points_performer_to_jack(coords.points_jack_to_performer(p)), p, atol=1e-9)
    assert np.allclose(
        np.linalg.norm(coords.points_jack_to_performer(p), axis=-1), np.linalg.norm(p, axis=-1) / 100
    )


@given(quats, vec3)
def test_transforms_and_quaternions_agree(q: np.ndarray, t_cm: np.ndarray) -> None:
    """Converting a transform, or its quaternion and translation separately, gives the same motion."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    jack = coords.pose7_to_transform(t_cm, q)
    perf = coords.transforms_jack_to_performer(jack)
    pos, quat = coords.transform_to_pose7(perf)
    assert np.allclose(pos, coords.points_jack_to_performer(t_cm), atol=1e-9)
    qp = coords.quats_jack_to_performer(q)
    assert np.allclose(np.abs((quat * qp).sum(-1)), 1.0, atol=1e-9)
    # the converted transform moves converted points where the original moves the original points
    p = np.array([10.0, -20.0, 30.0])
    moved = (jack[:, :3, :3] @ p) + jack[:, :3, 3]
    assert np.allclose(
        perf[:, :3, :3] @ coords.points_jack_to_performer(p) + perf[:, :3, 3],
        coords.points_jack_to_performer(moved),
        atol=1e-9,
    )
    assert np.allclose(coords.transforms_performer_to_jack(perf), jack, atol=1e-9)
    assert np.allclose(coords.quats_performer_to_jack(qp), q)


@given(quats)
def test_matrix_quaternion_round_trip(q: np.ndarray) -> None:
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    back = coords.matrix_to_quat(coords.quat_to_matrix(q))
    assert np.allclose(np.abs((back * q).sum(-1)), 1.0, atol=1e-9)
    assert (back[..., 0] >= 0).all()


@pytest.mark.parametrize("angle", [0.0, np.pi / 2, np.pi, -np.pi / 3])
def test_matrix_to_quat_known_rotations(angle: float) -> None:
    c, s = np.cos(angle), np.sin(angle)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    q = coords.matrix_to_quat(rz)
    expected = np.array([np.cos(angle / 2), 0, 0, np.sin(angle / 2)])
    expected = expected if expected[0] >= 0 else -expected
    assert np.allclose(q, expected, atol=1e-12) or np.allclose(q, -expected, atol=1e-12)
