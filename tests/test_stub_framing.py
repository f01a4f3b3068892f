"""The demo frames its soldiers: ACTION CAM keeps the current soldier's group inside the picture and close,
labels name each soldier and his posture, ``?`` shows the keys."""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # before OpenGL is first imported


import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from client_stub.stub.action import posture_texts
from client_stub.stub.app import StubApp
from client_stub.stub.camera import ACTION_RADIUS_M, View, box_corners, clear_pose, frame_points, viewproj
from client_stub.stub.gl_render import GLStubRenderer
from client_stub.stub.keys import KEY_HELP
from client_stub.stub.live import populate_demo
from client_stub.stub.overlay import Label, Overlay, project_labels
from client_stub.stub.simsoldier import Force
from client_stub.stub.terrain import load_terrain
from protocol.entity import Appearance, WeaponState

W, H = 160, 120


def ndc(points: np.ndarray, pose: np.ndarray, yfov: float, aspect: float) -> np.ndarray:
    clip = np.column_stack([points, np.ones(len(points))]) @ viewproj(pose, yfov, aspect).T
    assert np.all(clip[:, 3] > 0.2)  # in front of the camera, beyond the near plane
    return clip[:, :3] / clip[:, 3:]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(-40, 40)] * 2, st.floats(-3, 8)), min_size=1, max_size=30).map(np.array),
    st.floats(20, 90),
    st.floats(0.5, 2.5),
)
def test_frame_points_keeps_every_point_in_the_picture(
    points: np.ndarray, yfov: float, aspect: float
) -> None:
    pose = frame_points(points, yfov, aspect)
    xy = ndc(points, pose, yfov, aspect)[:, :2]
    assert np.all(np.abs(xy) <= 0.85 + 1e-6)
    if np.ptp(points, axis=0).max() > 10:  # spread out: as close as that allows (some point near an edge)
        assert np.abs(xy).max() > 0.6


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory):
    app = StubApp(load_terrain(), artic_dir=tmp_path_factory.mktemp("artic"))
    populate_demo(app)
    app.renderer = GLStubRenderer(W, H)
    app.renderer.set_terrain(app.terrain.meshes)
    yield app
    app.renderer.close()


def drawn(app: StubApp, frames: int = 3) -> np.ndarray:
    for _ in range(frames):
        app.frame(0.1)
        app.draw()
        img = app.renderer.render()  # type: ignore[union-attr]
    return img


@pytest.mark.parametrize("current", [0, 2, 5])
def test_action_cam_frames_the_current_soldiers_group(demo: StubApp, current: int) -> None:
    demo.controller.current = current
    assert "ACTION CAM" in (demo.handle_key("x") or "")
    assert demo.camera.view is View.ACTION
    drawn(demo)
    r = demo.renderer
    assert r is not None
    pose = r.pose if isinstance(r, GLStubRenderer) else None
    assert pose is not None
    boxes = demo.figure_box[: demo.soldiers.count]
    group = np.linalg.norm(boxes.mean(1)[:, :2] - boxes[current].mean(0)[:2], axis=1) <= ACTION_RADIUS_M
    assert group.sum() >= 1
    for lo, hi in boxes[group]:  # every soldier of the group wholly inside the picture
        xy = ndc(box_corners(lo, hi), pose, r.yfov_deg, W / H)[:, :2]
        assert np.all(np.abs(xy) < 1.0)
    lo, hi = boxes[current]
    tall = np.ptp(ndc(box_corners(lo, hi), pose, r.yfov_deg, W / H)[:, 1]) * H / 2
    assert tall > (0.4 * H if group.sum() == 1 else 0.12 * H), tall  # not a speck; a lone soldier fills it


def test_action_cam_rises_over_what_hides_the_soldier() -> None:
    points = box_corners(np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.5, 1.8]))
    wall = lambda xy: np.where(xy[:, 1] < -2.0, 6.0, 0.0)  # noqa: E731 - a 6 m wall south of the soldier
    low, high = frame_points(points, 50.0, 4 / 3), clear_pose(points, 50.0, 4 / 3, wall)
    assert high[2, 2] > low[2, 2] + 0.2  # looks down more steeply ...
    sight = high[:3, 3] + np.linspace(0, 0.9, 19)[:, None] * (points.mean(0) - high[:3, 3])
    assert np.all(wall(sight[:, :2]) < sight[:, 2])  # ... over the wall


def test_labels_name_each_soldier_and_his_posture(demo: StubApp) -> None:
    demo.controller.current = 3  # friendly, kneeling and firing, beside the prone one
    demo.handle_key("x")
    with_labels = drawn(demo)
    r = demo.renderer
    assert r is not None and r.overlay is not None
    labels = {lb.name: lb for lb in r.overlay.labels}
    assert len(labels) == int(demo.soldiers.alive[: demo.soldiers.count].sum())
    assert labels["soldier 3"].posture == "kneel, firing" and labels["soldier 3"].current
    assert labels["soldier 4"].posture == "prone, firing" and not labels["soldier 4"].current
    assert labels["soldier 1"].posture.startswith("stand, walk 1.3 m/s")
    shown = project_labels(r.overlay.labels, r.viewproj(), W, H) if isinstance(r, GLStubRenderer) else []
    assert {"soldier 3", "soldier 4"} <= {lb.name for lb, _ in shown}
    demo.labels = False
    without = drawn(demo, 1)
    demo.labels = True
    (x, y) = next(p for lb, p in shown if lb.name == "soldier 3")
    above = (slice(max(int(y) - 12, 0), int(y)), slice(max(int(x) - 10, 0), int(x) + 10))
    assert np.abs(with_labels[above].astype(int) - without[above].astype(int)).max() > 60  # text drawn there


def test_question_mark_shows_and_hides_the_keys(demo: StubApp) -> None:
    assert demo.handle_key("?")  # the console still gets the list
    drawn(demo, 1)
    assert demo.renderer is not None and demo.renderer.overlay is not None
    assert demo.renderer.overlay.help == KEY_HELP
    assert any(k == "x" for k, _ in KEY_HELP)
    demo.handle_key("?")
    drawn(demo, 1)
    assert demo.renderer.overlay.help == ()


def test_labels_behind_the_camera_far_or_covered_are_left_out() -> None:
    pose = np.eye(4)  # at the origin looking down -Z (+Y up): a point at z = -10 is 10 m ahead
    vp = viewproj(pose, 50.0, W / H)
    labels = [
        Label("ahead", "stand", (0.0, 0.0, -10.0)),
        Label("behind", "stand", (0.0, 0.0, 10.0)),
        Label("far", "stand", (0.0, 0.0, -500.0)),
        Label("beside", "stand", (0.05, 0.0, -11.0)),  # would cover 'ahead'
    ]
    assert [lb.name for lb, _ in project_labels(labels, vp, W, H)] == ["beside", "ahead"]
    img = Overlay(labels).draw(np.zeros((H, W, 3), np.uint8), vp)
    assert img[: H // 2].any() and not img[H // 2 + 2 :].any()  # drawn above the anchor, once


def test_posture_text_says_gait_and_weapon(demo: StubApp) -> None:
    s = demo.soldiers
    slot = s.add((50.0, 50.0), 0.0, speed=3.5, appearance=Appearance.UPRIGHT, weapon=WeaponState.STOWED)
    assert posture_texts(s, np.array([slot])) == ["stand, run 3.5 m/s"]
    s.set_appearance(slot, Appearance.PRONE)
    s.set_weapon(slot, WeaponState.DEPLOYED)
    assert posture_texts(s, np.array([slot])) == ["prone, crawl 3.5 m/s, deployed"]
    demo.hide(slot)


def test_a_touring_action_cam_turns_from_force_to_force_and_cuts(tmp_path: Path) -> None:
    """The replay's default camera: ACTION CAM on a live soldier, the other force's every 10 s, cutting
    (not gliding over empty ground) to a group far away; a key hands the camera to the user."""
    app = StubApp(load_terrain(), artic_dir=tmp_path)
    friendly = [app.add_soldier((x, -20.0), 0.0) for x in (0.0, 3.0)]
    opposing = app.add_soldier((0.0, 40.0), 180.0, force=Force.OPPOSING)
    app.renderer = GLStubRenderer(W, H)
    try:
        app.camera.action_view()
        app.camera.action_tour = True
        app.hide(friendly[0])  # the current soldier (0) is gone: the tour takes a live one of his force
        seen = []
        for _ in range(25):
            app.frame(0.5)
            app.draw()  # the camera follows in draw
            seen.append(app.controller.current)
        assert seen[0] == friendly[1] and seen[-1] == opposing
        assert seen.index(opposing) == 19  # turned at 10 s
        assert app.camera.action is not None
        middle = (app.camera.action[:3] + app.camera.action[3:]) / 2
        assert np.linalg.norm(middle[:2] - app.soldiers.position[opposing, :2]) < 1.5  # cut, not gliding
        app.handle_key("n")
        assert not app.camera.action_tour
    finally:
        app.renderer.close()
