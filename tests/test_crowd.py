"""`ttes crowd`: the batched FK, the levels of detail, the wire buffer, and images that show soldiers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from client_stub.crowd.app import CrowdConfig, CrowdRenderer, Figures, run_crowd
from client_stub.crowd.camera import FreeCamera
from client_stub.crowd.fk import FastFigure, entity_transforms, mul, to34, to44
from client_stub.crowd.gl import SKY, boxes_visible
from client_stub.crowd.lod import FAR, MID, NEAR, choose_levels, dof_map, visible
from client_stub.crowd.sources import CrowdState, WireBinding
from client_stub.link.buffer import UpdateBatch
from client_stub.renderer import Renderer
from client_stub.stub.artic import articulation, update_table_for
from client_stub.stub.scene_graph import Crowd, EntityLayout
from protocol import coords

W, H = 320, 180
SKY_RGB = np.round(np.array(SKY) * 255)


@pytest.fixture(scope="module")
def figures() -> Figures:
    return Figures.load()


def _non_sky(img: np.ndarray) -> np.ndarray:
    return np.abs(img.astype(np.int64) - SKY_RGB).sum(axis=2) > 12


def _olive(img: np.ndarray) -> np.ndarray:
    """Pixels of the soldiers' uniform: greenish, darker than the sky, green above blue."""
    f = img.astype(np.int64)
    r, g, b = f[..., 0], f[..., 1], f[..., 2]
    return (g >= b + 15) & (g >= r - 10) & (g < 200) & _non_sky(img)


# -- kinematics ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["mid", "near"])
def test_fast_fk_matches_the_scene_graph(figures: Figures, which: str) -> None:
    graph = getattr(figures, which)
    n = 12
    rng = np.random.default_rng(4)
    q = rng.uniform(-0.6, 0.6, (n, graph.ndof))
    place = np.broadcast_to(graph.location, (n, 1, 4, 4)).copy()
    place[:, 0, :3, 3] += rng.normal(0, 0.1, (n, 3))
    heading, position = rng.uniform(0, 360, n), rng.normal(0, 20, (n, 3))
    ref = Crowd(EntityLayout([graph]), n)
    rows = np.arange(n)
    ref.active[:] = True
    ref.set_dofs(rows, q)
    ref.set_placements(rows, place)
    ref.set_entity(rows, coords.heading_transform(heading, position))
    want = ref.world()[:, 1:]  # figure DCS and joint DCSs
    got = mul(
        entity_transforms(heading, position)[:, None], FastFigure(graph).local_nodes(q, to34(place[:, 0]))
    )
    assert np.abs(to44(got) - want).max() < 1e-4  # metres, float32


def test_dof_map_copies_shared_joints_and_spreads_the_spine(figures: Figures) -> None:
    di, soldier = figures.mid, figures.near
    m = dof_map(di, soldier)
    for name in ("waist", "left_hip", "right_knee", "left_shoulder", "neck", "head"):
        src, dst = di.dof_slices[name], soldier.dof_slices[name]
        assert np.array_equal(m[dst, src], np.eye(src.stop - src.start))
    belly = di.dof_slices["belly"]
    total = sum(m[soldier.dof_slices[j], belly] for j in ("vl3", "vl2", "vl1"))
    assert np.allclose(total, np.eye(3))  # the lumbar joints share the bend
    assert not m[:, di.dof_slices["spine_compression"]].any()
    # a leg pose puts soldier.fig's ankle where DI.fig's is (both bodies share the leg skeleton)
    q = np.zeros((1, di.ndof))
    q[0, di.dof_slices["left_hip"]] = (0.2, 0.8, 0.1)
    q[0, di.dof_slices["left_knee"]] = 1.1
    place = to34(di.location)[None]
    a = FastFigure(di).local_nodes(q, place)[0, 1 + di.joint_names.index("left_ankle")]
    b = FastFigure(soldier).local_nodes(q @ m.T, place)[0, 1 + soldier.joint_names.index("left_ankle")]
    assert np.linalg.norm(a[:, 3] - b[:, 3]) < 0.01


def test_levels_and_culling() -> None:
    assert choose_levels(np.array([1.0, 9.9, 10.0, 29.0, 30.0, 500.0])).tolist() == [
        NEAR, NEAR, MID, MID, FAR, FAR
    ]  # fmt: skip
    cam = FreeCamera(position=np.array([0.0, 0.0, 2.0]), heading=0.0, pitch=0.0)
    vp = cam.viewproj(16 / 9)
    pts = np.array([[0.0, 20.0, 1.0], [0.0, -20.0, 1.0], [300.0, 20.0, 1.0], [-9.0, 20.0, 1.0]])
    assert visible(pts, vp).tolist() == [True, False, False, True]  # ahead; behind; far right; just inside
    lo, hi = np.array([[-5.0, 10, 0], [-5.0, -30, 0]]), np.array([[5.0, 20, 3], [5.0, -20, 3]])
    assert boxes_visible(lo, hi, vp).tolist() == [True, False]


# -- the update stream into the state -----------------------------------------------------------------------
def test_wire_binding_binds_by_name_and_fills_the_state(figures: Figures) -> None:
    ours = update_table_for(articulation(figures.mid_tips), articulation(figures.rifle_tips))
    n = 6
    state = CrowdState.empty(n, figures.mid, figures.rifle)
    state.dirty[:] = False
    wb = WireBinding(ours)
    rng = np.random.default_rng(2)
    dofs = rng.uniform(-0.5, 0.5, (2, ours.ndofs))
    pos = rng.normal(0, 0.5, (2, ours.nfigures, 3))
    quat = rng.normal(size=(2, ours.nfigures, 4))
    quat /= np.linalg.norm(quat, axis=2, keepdims=True)
    batch = UpdateBatch(ours.table_id, np.array([40, 41]), dofs, pos, quat)
    assert wb.apply(state, ours, batch, np.array([1, 4])).tolist() == []  # nothing to pose offline
    assert state.dirty.tolist() == [False, True, False, False, True, False]
    assert np.allclose(state.dofs[[1, 4]], dofs[:, : figures.mid.ndof], atol=1e-6)
    assert np.allclose(state.placement[[1, 4], :, :, 3], pos[:, :2], atol=1e-6)
    want = coords.quat_to_matrix(quat[:, 0])
    assert np.allclose(state.placement[[1, 4], 0, :, :3], want, atol=1e-5)
    assert not state.rifle_from_palm[[1, 4]].any()
    # a table of other joint names (the synthetic server's chain figure) is posed offline instead
    from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable

    chain = UpdateTable(
        2, "DI.fig", "", (JointEntry("j0", (DofRange("R", -3.2, 3.2),)), FigureEntry("soldier"))
    )
    batch2 = UpdateBatch(
        2, np.array([3]), np.zeros((1, 1)), np.zeros((1, 1, 3)), np.array([[[1.0, 0, 0, 0]]])
    )
    assert wb.apply(state, chain, batch2, np.array([3])).tolist() == [3] and "offline" in wb.posing


# -- images -------------------------------------------------------------------------------------------------
def _line_of_soldiers(figures: Figures, distances: list[float]) -> CrowdState:
    n = len(distances)
    st = CrowdState.empty(n, figures.mid, figures.rifle)
    st.position[:, 0] = np.linspace(-1.5, 1.5, n) * np.asarray(distances) / 10
    st.position[:, 1] = distances
    st.heading[:] = 180.0  # facing the camera
    return st


def test_render_shows_soldiers_at_every_level(figures: Figures) -> None:
    cam = FreeCamera(position=np.array([0.0, 0.0, 1.6]), heading=0.0, pitch=-2.0)
    r = CrowdRenderer(figures, 3, W, H, 10.0, 40.0)
    try:
        r.show(_line_of_soldiers(figures, [6.0, 20.0, 70.0]))
        r.set_camera(cam.pose())
        img = r.render()
        assert r.counts == [1, 1, 1]  # one soldier drawn at each level
        assert isinstance(r, Renderer)
        assert img.shape == (H, W, 3)
        soldier = _non_sky(img)
        assert soldier.mean() > 0.01  # the near soldier alone covers a good part of the image
        assert _olive(img).sum() > 0.5 * soldier.sum()  # and they wear the olive uniform
        rows = np.flatnonzero(soldier.any(axis=1))
        assert rows.max() - rows.min() >= 40  # the near soldier stands about 60 pixels tall
        # turn the camera round: nothing drawn, nothing culled wrongly
        r.set_camera(FreeCamera(position=np.array([0.0, 0.0, 1.6]), heading=180.0, pitch=-2.0).pose())
        img = r.render()
        assert r.counts == [0, 0, 0]
        assert not _non_sky(img).any()
    finally:
        r.close()


def test_cli_renders_a_crowd_png(tmp_path, capsys) -> None:
    from ttes.cli import main

    png = tmp_path / "crowd.png"
    rc = main(
        ["crowd", "--headless", "--soldiers", "40", "--seconds", "0.5", "--size", f"{W}x{H}",
         "--terrain", "none", "--out", str(png), "--json"]
    )  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["soldiers"] == 40 and out["fps"] > 0 and out["source"] == "offline"
    assert sum(out["mean_drawn"].values()) > 10
    assert out["level_triangles"]["near"] > out["level_triangles"]["mid"] > out["level_triangles"]["far"]
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape == (H, W, 3)
    assert _non_sky(img).mean() > 0.02 and _olive(img).sum() > 200


def test_server_fed_crowd() -> None:
    stats = run_crowd(
        CrowdConfig(
            soldiers=8, seconds=1.5, width=W, height=H, source="server", spawn_server=True, terrain="none"
        )
    )
    assert (
        stats["source"] == "server" and stats["soldier_updates_received"] >= 8
    )  # at least one full update each
    img = stats["_image"]
    assert _non_sky(img).mean() > 0.01 and _olive(img).sum() > 100


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match=r"\.png or \.mp4"):
        run_crowd(CrowdConfig(soldiers=2, out="x.gif"))
    with pytest.raises(ValueError, match="near <= mid"):
        run_crowd(CrowdConfig(soldiers=2, near_m=50, mid_m=10))
