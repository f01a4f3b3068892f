"""A let-go rifle recorded again on its own (authoring.rifle_drop): it falls from where the hands let go of
it, flung the way it is tossed, and comes to rest lying on the ground."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.rifle_drop import LetGo, dropped
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from ttes.paths import FIGURES

pytest.importorskip("mujoco")


def _lowest(rifle, location: np.ndarray) -> float:
    kin = FigureKinematics(rifle)
    g = kin.segment_globals(np.zeros(kin.ndof), location)[0]
    nodes = np.asarray(rifle.segments["rifle"].psurf.nodes)
    return float((nodes @ g[1, :3] + g[1, 3]).min())


def test_a_let_go_rifle_falls_the_way_it_is_tossed_and_comes_to_rest_on_the_ground() -> None:
    rifle = read_figure(FIGURES / "AK_47.fig")
    start = np.eye(4)
    start[1, 3] = 100.0  # held level 1 m up, still
    let_go = LetGo(start, np.zeros(6), 20)
    fallen = dropped(rifle, let_go, np.zeros(3), 10, 60.0)
    flung = dropped(rifle, let_go, np.array([0.0, 0.0, -120.0]), 10, 60.0)  # toward -z (figure world)
    for path in (fallen, flung):
        assert len(path) >= 10
        assert abs(_lowest(rifle, path[-1])) <= 1.0  # lying on the ground, not in it
        speed = np.linalg.norm(np.diff(path[-3:, :3, 3], axis=0), axis=1) * 60.0 / 100.0
        assert speed.max() < 0.03  # still
    assert np.linalg.norm(fallen[-1, [0, 2], 3] - start[[0, 2], 3]) < 30.0  # dropped: it lies below the hands
    assert flung[-1, 2, 3] < fallen[-1, 2, 3] - 30.0  # flung: well on that way
