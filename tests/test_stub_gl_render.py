"""The moderngl stub renderer (headless runs): the same picture as pyrender's, one draw per kind and look
whatever the number of soldiers, and a blob shadow under each soldier."""

from __future__ import annotations

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # before OpenGL is first imported

from pathlib import Path

import numpy as np
import pytest
import trimesh

from client_stub.renderer import Renderer, StubBackend
from client_stub.stub.app import StubApp
from client_stub.stub.camera import look_at
from client_stub.stub.gl_render import GLStubRenderer, offscreen_renderer
from client_stub.stub.render import SKY, StubRenderer
from client_stub.stub.shadow import shadow_quads
from client_stub.stub.simsoldier import Force
from client_stub.stub.terrain import terrain_from_mesh
from protocol.entity import Appearance, WeaponState

W, H = 160, 120
POSE = look_at(np.array([0.0, -5.0, 1.2]), np.array([0.0, 0.0, 0.9]))


def flat_ground() -> trimesh.Trimesh:
    ground = trimesh.creation.box(extents=(100, 100, 2))
    ground.apply_translation((0, 0, -1))
    return ground


def two_soldiers(tmp_path: Path) -> StubApp:
    app = StubApp(terrain_from_mesh(flat_ground()), artic_dir=tmp_path)
    app.labels = False
    app.add_soldier((-1.2, 0.0), 180.0)  # friendly, facing the camera
    app.add_soldier((1.2, 0.0), 150.0, force=Force.OPPOSING, weapon=WeaponState.FIRING)
    app.frame(0.0)
    return app


def picture(app: StubApp, renderer: StubBackend) -> np.ndarray:
    """The soldiers alone (no terrain: the sky behind them), as ``renderer`` draws them."""
    app.renderer = renderer
    try:
        app.draw()
        renderer.overlay = None
        renderer.set_camera(POSE)
        return renderer.render()
    finally:
        renderer.close()


def figure_mask(img: np.ndarray) -> np.ndarray:
    return np.abs(img.astype(int) - np.round(np.array(SKY) * 255).astype(int)).sum(axis=2) > 30


def interior(mask: np.ndarray) -> np.ndarray:
    """``mask`` less its edge pixels (pyrender's antialiased edges are part sky)."""
    m = mask.copy()
    m[1:] &= mask[:-1]
    m[:-1] &= mask[1:]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    return m


def test_gl_draws_the_picture_pyrender_draws(tmp_path: Path) -> None:
    app = two_soldiers(tmp_path)
    gl = GLStubRenderer(W, H)
    gl.shadows = False  # without terrain they would hang in the sky
    fast = picture(app, gl)
    pr = StubRenderer(W, H)  # made after the moderngl context is gone: each EGL user on its own
    pr.shadows = False
    slow = picture(app, pr)
    a, b = figure_mask(fast), figure_mask(slow)
    assert b.sum() > 400  # two soldiers fill a fair part of the picture
    assert (a & b).sum() / (a | b).sum() > 0.8  # the same silhouettes (pyrender's are antialiased)
    both = interior(a) & interior(b)
    diff = np.abs(fast[both].astype(int) - slow[both].astype(int))
    assert np.median(diff) <= 12 and diff.mean() < 20  # the same colours and lighting, within a few levels
    for half in (slice(0, W // 2), slice(W // 2, W)):  # each soldier's uniform where pyrender has it
        np.testing.assert_allclose(
            fast[:, half][both[:, half]].mean(0), slow[:, half][both[:, half]].mean(0), atol=12
        )


def test_multisampling_smooths_the_same_picture(tmp_path: Path) -> None:
    app = two_soldiers(tmp_path)
    plain, smooth = GLStubRenderer(W, H), GLStubRenderer(W, H, samples=4)
    plain.shadows = smooth.shadows = False
    a, b = picture(app, plain), picture(app, smooth)
    ma, mb = figure_mask(a), figure_mask(b)
    assert (ma & mb).sum() / (ma | mb).sum() > 0.75  # the same figures; thin rifles and fingers differ most
    edges = ma ^ interior(ma)
    between = (b[edges].astype(int) - a[edges].astype(int)).any(axis=1).mean()
    assert between > 0.2  # edge pixels blend with the sky


def test_one_draw_per_kind_and_look_for_any_number_of_soldiers(tmp_path: Path) -> None:
    app = StubApp(terrain_from_mesh(flat_ground()), artic_dir=tmp_path)
    app.renderer = r = GLStubRenderer(64, 48)
    try:
        assert isinstance(r, Renderer) and isinstance(r, StubBackend)
        for k in range(61):
            app.add_soldier(
                (k % 10 * 2.0, k // 10 * 2.0), force=Force.OPPOSING if k % 3 == 0 else Force.FRIENDLY
            )
        app.frame(0.1)
        app.draw()
        opposing, friendly = (int(app.slot_kind[k]) for k in (0, 1))
        assert sorted(r.soldiers) == sorted(
            [(opposing, int(Force.OPPOSING)), (friendly, int(Force.FRIENDLY))]
        )
        assert r.soldiers[opposing, int(Force.OPPOSING)].count == 21
        assert r.soldiers[friendly, int(Force.FRIENDLY)].count == 40
        r.set_camera(look_at(np.array([9.0, -20.0, 10.0]), np.array([9.0, 5.0, 0.0])))
        r.render()
        assert r.triangles_drawn == sum(b.count * b.triangles for b in r.soldiers.values())  # no terrain set
    finally:
        r.close()


def test_blob_shadows_lie_under_the_soldiers(tmp_path: Path) -> None:
    app = StubApp(terrain_from_mesh(flat_ground()), artic_dir=tmp_path)
    stand = app.add_soldier((0.0, 0.0), 0.0)
    prone = app.add_soldier((5.0, 0.0), 90.0, appearance=Appearance.PRONE)
    for _ in range(20):
        app.frame(0.1)
    kind = app.kinds[int(app.slot_kind[stand])]
    quads = shadow_quads(kind.crowd.world(np.array([stand, prone])))
    assert quads.shape == (2, 4, 5)
    np.testing.assert_allclose(quads[..., 2], 0.04, atol=0.02)  # on the ground
    size = np.ptp(quads[..., :2], axis=1)  # (2, 2) x, y extent
    assert size[0].max() / size[0].min() < 1.6  # standing: about round, under his feet
    assert np.all(np.abs(quads[0, :, :2].mean(0) - app.soldiers.position[stand, :2]) < 0.4)
    assert size[1, 0] > 1.6 * size[1, 1] and size[1, 0] > 1.5  # prone facing east: long east-west


@pytest.mark.parametrize("backend", ["gl", "pyrender"])
def test_shadows_darken_the_ground_under_a_soldier(tmp_path: Path, backend: str) -> None:
    app = StubApp(terrain_from_mesh(flat_ground()), artic_dir=tmp_path)
    app.labels = False
    app.add_soldier((0.0, 0.0), 180.0)
    app.frame(0.0)
    overhead = look_at(np.array([0.0, -0.01, 8.0]), np.array([0.0, 0.0, 0.0]))
    frames = []
    for shadows in (False, True):
        r = offscreen_renderer(W, H, backend)
        r.shadows = shadows
        r.set_terrain(app.terrain.meshes)
        app.renderer = r
        app.draw()
        r.set_camera(overhead)
        frames.append(r.render().astype(int))
        r.close()
    darker = (frames[0] - frames[1]).sum(axis=2) > 30
    rows, cols = np.flatnonzero(darker.any(1)), np.flatnonzero(darker.any(0))
    assert darker.sum() > 100 and abs(rows.mean() - H / 2) < 12 and abs(cols.mean() - W / 2) < 12


def test_offscreen_renderer_names_its_back_ends() -> None:
    with pytest.raises(ValueError, match="gl, pyrender"):
        offscreen_renderer(32, 24, "vulkan")


@pytest.mark.parametrize("backend", ["gl", "pyrender"])
def test_stub_cli_renders_with_either_back_end(tmp_path: Path, backend: str) -> None:
    import imageio.v2 as imageio

    from ttes.cli import main

    out = tmp_path / "last.png"
    argv = ["stub", "--headless", "--renderer", backend, "--seconds", "0.4", "--fps", "5", "--size", "96x64",
            "--out", str(out), "--artic-dir", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    img = imageio.imread(out)
    assert img.shape == (64, 96, 3) and img.std() > 5
