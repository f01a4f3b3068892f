"""The stub's keyboard (seed 002, 4.2) as a pure mapping: keys -> soldier requests and camera changes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from client_stub.stub.camera import (
    OVERHEAD_ELEVATION,
    TETHER_ELEVATION,
    CameraState,
    View,
    camera_pose,
    look_at,
)
from client_stub.stub.keys import KEY_HELP, StubController, help_text
from client_stub.stub.simsoldier import Behaviour, SimSoldiers
from client_stub.stub.terrain import terrain_from_mesh
from protocol.entity import Appearance, WeaponState


@pytest.fixture
def ctl() -> StubController:
    terrain = terrain_from_mesh(trimesh.creation.box(extents=(200, 200, 2)), {"office": [30.0, -20.0]})
    s = SimSoldiers(terrain)
    s.add((0.0, 0.0), 0.0)
    s.add((10.0, 0.0), 0.0, speed=1.0, behaviour=Behaviour.SQUARE)
    s.add((0.0, 10.0), 0.0, speed=1.0, behaviour=Behaviour.CIRCLE)
    s.requests()  # the initial requests went out
    return StubController(s, max_soldiers=5)


def one_request(ctl: StubController) -> np.ndarray:
    rows = ctl.soldiers.requests()
    assert len(rows) == 1, rows
    return rows[0]


@pytest.mark.parametrize(
    ("key", "appearance"),
    [("1", Appearance.DEAD), ("2", Appearance.UPRIGHT), ("3", Appearance.KNEEL), ("4", Appearance.PRONE)],
)
def test_posture_keys_change_the_current_soldiers_request(
    ctl: StubController, key: str, appearance: int
) -> None:
    if key == "2":
        ctl.handle("1")
        ctl.soldiers.requests()
    ctl.handle(key)
    row = one_request(ctl)
    assert row["index"] == 0 and row["appearance"] == appearance


def test_weapon_keys(ctl: StubController) -> None:
    ctl.handle("6")
    assert one_request(ctl)["weapon"] == WeaponState.FIRING
    ctl.handle("5")
    assert one_request(ctl)["weapon"] == WeaponState.DEPLOYED


def test_arrows_change_heading_and_velocity(ctl: StubController) -> None:
    ctl.handle("UP")
    row = one_request(ctl)
    np.testing.assert_allclose(row["velocity"], [0.0, 0.5, 0.0], atol=1e-7)  # heading 0 is north, +Y
    ctl.handle("RIGHT")
    row = one_request(ctl)
    assert row["heading"] == pytest.approx(10.0)
    np.testing.assert_allclose(
        row["velocity"], 0.5 * np.array([np.sin(np.radians(10)), np.cos(np.radians(10)), 0]), atol=1e-6
    )
    ctl.handle("LEFT")
    ctl.handle("LEFT")
    assert one_request(ctl)["heading"] == pytest.approx(350.0)
    for _ in range(3):
        ctl.handle("DOWN")
    row = one_request(ctl)  # -1.0 m/s: walking backwards, velocity against the heading
    assert np.dot(row["velocity"][:2], [np.sin(np.radians(350)), np.cos(np.radians(350))]) == pytest.approx(
        -1.0
    )


def test_next_and_previous_wrap_and_keys_follow_the_current_soldier(ctl: StubController) -> None:
    ctl.handle("p")
    assert ctl.current == 2
    ctl.handle("N")
    ctl.handle("n")
    assert ctl.current == 1
    ctl.handle("UP")  # takes soldier 1 off his square
    row = one_request(ctl)
    assert row["index"] == 1 and ctl.soldiers.behaviour[1] == Behaviour.USER
    assert row["velocity"][1] == pytest.approx(1.5, abs=1e-6)


def test_a_adds_soldiers_near_the_office_up_to_the_maximum(ctl: StubController) -> None:
    msg = ctl.handle("a")
    assert ctl.soldiers.count == 4 and ctl.current == 3 and "office" in (msg or "")
    assert np.linalg.norm(ctl.soldiers.position[3, :2] - [30.0, -20.0]) < 10.0
    row = one_request(ctl)
    assert row["index"] == 3 and row["appearance"] == Appearance.UPRIGHT
    ctl.handle("a")
    assert "maximum" in (ctl.handle("a") or "") and ctl.soldiers.count == 5
    assert "not implemented" in (ctl.handle("A") or "") and ctl.soldiers.count == 5


def test_camera_keys(ctl: StubController) -> None:
    cam = ctl.camera
    assert cam.view is View.BIRDS_EYE
    ctl.handle("u")
    assert cam.view is View.SOLDIER_CAM and cam.distance == 11.0  # 6 m by default, +5
    ctl.handle("D")
    ctl.handle("d")
    ctl.handle("d")
    assert cam.distance == 2.0  # never closer than 2 m
    ctl.handle("i")
    ctl.handle("j")
    ctl.handle("J")
    assert cam.azimuth == 350.0
    ctl.handle("o")
    assert cam.view is View.OVERHEAD and cam.elevation == OVERHEAD_ELEVATION
    for _ in range(10):  # "press [i] again until you are looking at him from the side"
        ctl.handle("i")
    assert cam.view is View.SOLDIER_CAM and cam.elevation == TETHER_ELEVATION
    assert ctl.soldiers.requests().size == 0  # camera keys send nothing


def test_views_and_fly(ctl: StubController) -> None:
    assert ctl.handle("f") == "view: fly"
    p0 = ctl.camera.fly_position.copy()
    ctl.handle("w")
    ctl.handle("r")
    np.testing.assert_allclose(ctl.camera.fly_position - p0, [0.0, 5.0, 2.0])
    ctl.handle("b")
    assert ctl.camera.view is View.BIRDS_EYE
    ctl.handle("v")
    assert ctl.camera.view is View.SOLDIER_CAM


def test_help_lists_every_seed_key(ctl: StubController) -> None:
    text = ctl.handle("?") or ""
    assert text == help_text()
    seed_keys = ["1", "2", "3", "4", "5", "6", "n or N", "p or P", "a", "A", "u or U", "d or D", "i or I"]
    seed_keys += ["j or J", "o or O", "Left, Right Arrows", "Up, Down Arrows", "?"]
    for key in seed_keys:
        assert any(k == key for k, _ in KEY_HELP), key


def test_tethered_camera_looks_at_the_soldier_from_behind() -> None:
    cam = CameraState(view=View.SOLDIER_CAM, distance=10.0, elevation=0.0)
    pose = camera_pose(cam, np.array([5.0, 5.0, 0.0]), 90.0, np.zeros((2, 3)))  # soldier faces east
    np.testing.assert_allclose(pose[:3, 3], [-5.0, 5.0, 1.0], atol=1e-9)  # 10 m west of him
    np.testing.assert_allclose(-pose[:3, 2], [1.0, 0.0, 0.0], atol=1e-9)  # looking east
    assert np.allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3))
    down = look_at(np.array([0.0, 0.0, 10.0]), np.zeros(3))
    np.testing.assert_allclose(-down[:3, 2], [0.0, 0.0, -1.0])
