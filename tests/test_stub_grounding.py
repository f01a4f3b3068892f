"""A figure stands on the ground under the foot carrying it (client_stub.stub.grounding, issue 16 slopes)."""

from __future__ import annotations

import numpy as np

from client_stub.stub.grounding import feet_ground


def slope(xy: np.ndarray, top: np.ndarray) -> np.ndarray:
    """A 10 % slope up to the north (+y), through z = 0 at y = 0."""
    return 0.1 * np.asarray(xy)[:, 1]


def soles(left: tuple[float, float, float], right: tuple[float, float, float]) -> np.ndarray:
    """``(1, feet, points, 3)``: each foot's heel at a point, its ball 18 cm ahead (+y) at the same height."""
    feet = [[list(p), [p[0], p[1] + 0.18, p[2]]] for p in (left, right)]
    return np.array([feet], np.float64)


def flat(xy: np.ndarray, top: np.ndarray) -> np.ndarray:
    return np.zeros(len(xy))


def test_on_flat_ground_the_entity_keeps_its_height_whatever_the_pose() -> None:
    for pose in (soles((0, 0, 0), (0.3, 0.4, 0.12)), soles((0, 0, 0.1), (0.3, 0.4, 0.1))):
        assert feet_ground(pose, np.array([[0.0, 0.5, 0.0]]), flat) == [0.0]


def test_on_a_slope_the_foot_down_decides_and_a_flight_keeps_its_height() -> None:
    """The entity a metre up the slope (ground 10 cm): the figure is lowered until the left foot, down, stands
    on the ground under it (its ball, the end nearer the slope: the heel then 1.8 cm up); the right foot, 9 cm
    up in its swing, hardly counts. Both feet 10 cm up (a run's flight): the soles stay 10 cm up."""
    entity = np.array([[0.0, 1.0, 0.1]])
    z = feet_ground(soles((0, 0, 0.1), (0.3, 0.6, 0.25)), entity, slope)[0]  # placed at the entity's 10 cm
    assert abs(0.1 - entity[0, 2] + z - 0.018) < 1e-3  # the left ball (y 0.18) on the ground there: 1.8 cm
    z = feet_ground(soles((0, 0, 0.2), (0.0, 0.0, 0.2)), entity, slope)[0]
    assert abs(0.2 - entity[0, 2] + z - (0.018 + 0.1)) < 1e-3  # the balls 10 cm over the ground under them
