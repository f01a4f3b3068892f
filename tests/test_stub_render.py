"""Headless rendering: soldiers show up where the scene graph puts them, in their force's colours."""

from __future__ import annotations

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # before OpenGL is first imported

import json
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
import trimesh

from client_stub.renderer import Renderer
from client_stub.stub.app import StubApp
from client_stub.stub.camera import look_at
from client_stub.stub.headless import TOUR, Tour, run_headless
from client_stub.stub.render import FORCE_UNIFORMS, StubRenderer, uniform_colour
from client_stub.stub.simsoldier import Force
from client_stub.stub.terrain import terrain_from_mesh
from protocol.entity import Appearance, WeaponState

W, H = 200, 150
YFOV = 50.0


def grey_ground() -> trimesh.Trimesh:
    ground = trimesh.creation.box(extents=(100, 100, 2))
    ground.apply_translation((0, 0, -1))
    ground.visual = trimesh.visual.ColorVisuals(
        ground, face_colors=np.tile([128, 128, 128, 255], (len(ground.faces), 1))
    )
    return ground


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory):
    terrain = terrain_from_mesh(grey_ground())
    app = StubApp(terrain, artic_dir=tmp_path_factory.mktemp("artic"))
    app.labels = False  # these tests count uniform-coloured pixels; the yellow label text would add some
    app.add_soldier((-1.5, 0.0), 180.0)  # friendly, facing the camera
    app.add_soldier((1.5, 0.0), 180.0, force=Force.OPPOSING, weapon=WeaponState.FIRING)
    app.frame(0.0)
    app.renderer = StubRenderer(W, H, yfov_deg=YFOV)
    app.renderer.set_terrain(terrain.meshes)
    yield app
    app.renderer.close()


def project(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Pixel coordinates (column, row) of world points seen by a pyrender camera at ``pose``."""
    cam = (np.linalg.inv(pose) @ np.column_stack([points, np.ones(len(points))]).T).T
    f = (H / 2) / np.tan(np.radians(YFOV) / 2)
    return np.column_stack([W / 2 + f * cam[:, 0] / -cam[:, 2], H / 2 - f * cam[:, 1] / -cam[:, 2]])


def soldier_box(app: StubApp, slot: int, pose: np.ndarray) -> tuple[slice, slice]:
    """The screen rectangle the scene graph says soldier ``slot`` covers."""
    kind = app.kinds[app.slot_kind[slot]]
    world = kind.crowd.world(np.array([slot]))[0]
    pts = np.concatenate([(world[node] @ np.column_stack([g.vertices, np.ones(len(g.vertices))]).T).T[:, :3]
                          for g, node in kind.layout.geometry])  # fmt: skip
    px = project(pts, pose)
    c0, r0 = np.floor(px.min(axis=0)).astype(int)
    c1, r1 = np.ceil(px.max(axis=0)).astype(int)
    return slice(max(r0, 0), min(r1 + 1, H)), slice(max(c0, 0), min(c1 + 1, W))


def olive(img: np.ndarray) -> np.ndarray:
    """Pixels of the friendly uniform (olive drab: green >= red > blue; grey ground and blue sky are not)."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (g >= r - 6) & (g - b >= 10) & (r - b >= 5)


def maroon(img: np.ndarray) -> np.ndarray:
    """Pixels of the opposing uniform (maroon: red far above green, blue not below green; skin has b < g)."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r - g > 30) & (b >= g - 3)


def test_uniform_is_the_dominant_colour_and_forces_differ(scene: StubApp) -> None:
    kind = scene.kinds[scene.slot_kind[0]]
    np.testing.assert_allclose(uniform_colour(kind.layout), [0.33, 0.36, 0.22])
    assert FORCE_UNIFORMS[Force.OPPOSING] is not None
    assert scene.slot_kind[0] != scene.slot_kind[1]  # friendly M16, opposing AK-47: two kinds, shared bodies


def test_soldiers_are_visible_where_the_scene_graph_puts_them(scene: StubApp, tmp_path: Path) -> None:
    pose = look_at(np.array([0.0, -5.0, 1.2]), np.array([0.0, 0.0, 0.9]))
    scene.camera.view = scene.camera.view  # the app's camera is not used: we set the pose ourselves
    scene.draw()
    scene.renderer.set_camera(pose)
    img = scene.renderer.render()
    imageio.imwrite(tmp_path / "two.png", img)
    assert img.shape == (H, W, 3)
    fr = soldier_box(scene, 0, pose)
    op = soldier_box(scene, 1, pose)
    assert fr[1].stop <= W / 2 + 2 and op[1].start >= W / 2 - 2  # friendly on the left, opposing on the right
    mask_olive, mask_maroon = olive(img), maroon(img)
    inside = np.zeros((H, W), bool)
    inside[fr] = True
    inside[op] = True
    assert mask_olive[fr].sum() > 150 and mask_maroon[op].sum() > 150
    assert mask_maroon[fr].sum() < 5 and mask_olive[op].sum() < 5
    assert (mask_olive | mask_maroon)[~inside].sum() == 0  # nothing soldier-coloured anywhere else
    # the soldier is upright: his uniform spans most of his box's height
    rows = np.flatnonzero(mask_olive[fr].any(axis=1))
    assert rows.max() - rows.min() > 0.6 * (fr[0].stop - fr[0].start)


def test_poses_move_the_pixels(scene: StubApp) -> None:
    """Kneeling (offline pose) lowers the soldier's top on screen: the instance poses are re-uploaded."""
    pose = look_at(np.array([0.0, -5.0, 1.2]), np.array([0.0, 0.0, 0.9]))

    def top_row() -> int:
        scene.draw()
        scene.renderer.set_camera(pose)
        img = scene.renderer.render()
        return int(np.flatnonzero(olive(img).any(axis=1)).min())

    standing = top_row()
    scene.soldiers.set_appearance(0, Appearance.KNEEL)
    scene.frame(1.0)  # offline poses ease in over a fraction of a second
    kneeling = top_row()
    scene.soldiers.set_appearance(0, Appearance.UPRIGHT)
    scene.frame(1.0)
    assert kneeling > standing + 5 and top_row() == standing


def test_instancing_keeps_draw_calls_constant(tmp_path: Path) -> None:
    terrain = terrain_from_mesh(grey_ground())
    app = StubApp(terrain, artic_dir=tmp_path)
    app.renderer = StubRenderer(64, 48)
    try:
        app.add_soldier((0.0, 0.0))
        app.frame(0.0)
        app.draw()
        nodes = len(app.renderer.scene.mesh_nodes)
        for k in range(60):
            app.add_soldier((k % 10 * 2.0, k // 10 * 2.0))
        app.frame(0.1)
        app.draw()
        assert len(app.renderer.scene.mesh_nodes) == nodes
        meshes = next(iter(app.renderer.soldiers.values()))
        assert meshes.count == 61
        assert all(p.poses.shape == (61, 4, 4) for p in meshes.primitives())
        app.renderer.render()
        assert isinstance(app.renderer, Renderer)
    finally:
        app.renderer.close()


def test_headless_png_and_tour(scene: StubApp, tmp_path: Path) -> None:
    out = tmp_path / "last.png"
    scene.controller.current = 0
    summary = run_headless(scene, 0.4, out, fps=5, tour=False)
    assert summary["frames"] == 2 and summary["soldiers"] == 2 and not summary["server"]
    img = imageio.imread(out)
    assert img.shape == (H, W, 3) and img.std() > 5
    # the tour's times shrink with short runs, in order, each key once
    tour = Tour(TOUR[-1][0] / 4)
    pressed = [k for t in np.arange(0, 12, 0.05) for k in tour.due(float(t))]
    assert pressed == [k for _, keys in TOUR for k in keys]


def test_headless_cli_writes_a_video(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from ttes.cli import main

    out = tmp_path / "tour.mp4"
    code = main(["stub", "--headless", "--seconds", "0.6", "--fps", "5", "--size", "96x64", "--out", str(out),
                 "--artic-dir", str(tmp_path), "--json"])  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["frames"] == 3 and summary["soldiers"] == 10
    frames = [f for f in imageio.get_reader(out)]  # list() would ask len(): inf for ffmpeg
    assert len(frames) == 3 and frames[0].shape[:2] == (64, 96)


def test_cli_refuses_a_window_without_display_and_a_bad_terrain(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from ttes.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["stub"]) == 2 and "--headless" in capsys.readouterr().err
    bad = ["stub", "--headless", "--terrain", str(tmp_path / "none.glb"), "--out", str(tmp_path / "x.png")]
    assert main(bad) == 1 and "cannot load terrain" in capsys.readouterr().err


def test_the_tethered_camera_aims_at_the_figure_not_the_entity(tmp_path: Path) -> None:
    """Issue 16: the server sends a root offset (the figure trails its entity through a step); a camera aimed
    at the entity left the walking soldier at the frame's edge in `make demo`."""
    app = StubApp(terrain_from_mesh(grey_ground()), artic_dir=tmp_path)
    slot = app.add_soldier((0.0, 0.0))
    app.controller.current = slot
    app.camera.tether()
    app.frame(0.0)
    at_entity = app.camera_pose()
    kind = app.kinds[int(app.slot_kind[slot])]
    body = max(range(len(kind.layout.figures)), key=lambda f: kind.layout.figures[f].ndof)
    place = kind.crowd.placements[[slot]].copy()
    place[0, body, :3, 3] += app.soldiers.entity_matrices(np.array([slot]))[0, :3, :3].T @ [0.0, -1.0, 0.0]
    kind.crowd.set_placements(np.array([slot]), place)
    moved = app.camera_pose()
    # the whole camera moved with the figure (1 m along the world's -y), not just its aim
    np.testing.assert_allclose(moved[:3, 3] - at_entity[:3, 3], [0.0, -1.0, 0.0], atol=1e-6)
