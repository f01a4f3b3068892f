"""Terrain: the generated village, loading meshes, vertical ray casts, soldiers following the ground."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from client_stub.stub.ground import GroundQuery
from client_stub.stub.simsoldier import Behaviour, SimSoldiers
from client_stub.stub.terrain import DEFAULT_TERRAIN, TerrainError, load_terrain, terrain_from_mesh
from client_stub.stub.terrain_gen import buildings, landmarks, relief, village_scene
from protocol.entity import Appearance


def brute_force_heights(
    vertices: np.ndarray, faces: np.ndarray, xy: np.ndarray, z_from: np.ndarray
) -> np.ndarray:
    """Möller–Trumbore for rays (x, y, z_from) -> -Z against every triangle: the reference answer."""
    tri = vertices[faces]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = np.array([0.0, 0.0, -1.0])
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    out = np.full(len(xy), np.nan)
    for i, (pt, z0) in enumerate(zip(xy, z_from, strict=True)):
        s = np.array([pt[0], pt[1], z0]) - tri[ok, 0]
        inv = 1.0 / det[ok]
        u = np.einsum("ij,ij->i", s, p[ok]) * inv
        q = np.cross(s, e1[ok])
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2[ok], q) * inv
        hit = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (t >= -1e-6)
        if hit.any():
            out[i] = z0 - t[hit].min()
    return out


@pytest.fixture(scope="module")
def village():
    return load_terrain()


def test_ground_query_agrees_with_ray_triangle_intersection(village) -> None:
    verts = np.concatenate([m.vertices for m in village.meshes.values()])
    offsets = np.cumsum([0] + [len(m.vertices) for m in village.meshes.values()])[:-1]
    faces = np.concatenate([m.faces + o for m, o in zip(village.meshes.values(), offsets, strict=True)])
    rng = np.random.default_rng(3)
    office = next(b for b in buildings() if b.name == "office")
    xy = np.concatenate(
        [
            rng.uniform(-90, 90, (40, 2)),
            rng.uniform([office.x - 14, office.y - 6], [office.x + 14, office.y + 6], (10, 2)),
        ]
    )
    z_from = np.concatenate(
        [np.full(25, 1e3), rng.uniform(-2.0, 8.0, 25)]
    )  # from the sky, and from under roofs
    got = village.ground.heights(xy, z_from)
    want = brute_force_heights(verts, faces, xy, z_from)
    np.testing.assert_allclose(got, want, atol=1e-6)
    on_roof = village.ground.heights(xy[40:])  # the office's flat roof, seen from above
    assert (on_roof > village.height(xy[40:], np.full(10, 2.0)) + 3.0).all()


def test_off_the_terrain_is_nan_and_height_defaults(village) -> None:
    far = np.array([[1e4, 0.0], [0.0, -1e4]])
    assert np.isnan(village.ground.heights(far)).all()
    assert (village.height(far, default=-5.0) == -5.0).all()


def test_soldiers_follow_a_sloped_ground() -> None:
    g = np.linspace(-60, 60, 25)
    x, y = np.meshgrid(g, g, indexing="ij")
    plane = lambda px, py: 0.1 * px + 0.05 * py + 2.0  # noqa: E731
    verts = np.column_stack([x.ravel(), y.ravel(), plane(x, y).ravel()])
    n = len(g)
    a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None]).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    terrain = terrain_from_mesh(trimesh.Trimesh(verts, faces, process=False))
    s = SimSoldiers(terrain)
    s.add((0.0, 0.0), 90.0, speed=1.5)  # walks east, uphill
    s.add((5.0, -5.0), 0.0, speed=1.0, behaviour=Behaviour.SQUARE, size=10.0)
    s.add((-10.0, 10.0), 0.0, speed=1.2, behaviour=Behaviour.CIRCLE, size=6.0)
    s.add((20.0, 0.0), 180.0, speed=-0.5, appearance=Appearance.PRONE)  # crawls backwards
    s.add((-20.0, 0.0), 0.0, speed=2.0, appearance=Appearance.KNEEL)  # kneeling: does not move
    for _ in range(40):
        s.step(0.25)
        p = s.position[: s.count]
        np.testing.assert_allclose(p[:, 2], plane(p[:, 0], p[:, 1]), atol=1e-9)
    np.testing.assert_allclose(s.position[0, :2], [15.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(s.position[3, :2], [20.0, 5.0], atol=1e-9)  # heading 180 (south), backwards
    np.testing.assert_allclose(s.position[4, :2], [-20.0, 0.0])
    np.testing.assert_allclose(np.linalg.norm(s.position[2, :2] - [-10.0, 10.0]), 6.0)
    ent = s.entity_matrices(np.arange(s.count))
    np.testing.assert_allclose(ent[:, :3, 3], s.position[: s.count])
    h = np.radians(s.heading[: s.count])
    np.testing.assert_allclose(ent[:, :3, 1], np.column_stack([np.sin(h), np.cos(h), np.zeros(5)]))


def test_square_and_circle_walkers_keep_to_their_paths() -> None:
    terrain = terrain_from_mesh(trimesh.creation.box(extents=(200, 200, 1)))
    s = SimSoldiers(terrain)
    s.add((0.0, 0.0), 0.0, speed=2.0, behaviour=Behaviour.SQUARE, size=8.0)
    s.add((0.0, 0.0), 0.0, speed=2.0, behaviour=Behaviour.CIRCLE, size=5.0)
    headings = set()
    for _ in range(32):  # one lap of the square: 4 sides x 8 m at 2 m/s = 16 s
        s.step(0.5)
        p = s.position[0, :2]
        assert np.isclose(np.abs(p).max(), 4.0)  # on the square's perimeter
        assert np.isclose(np.linalg.norm(s.position[1, :2]), 5.0)
        headings.add(round(float(s.heading[0])))
    assert headings == {0, 90, 180, 270}
    np.testing.assert_allclose(s.position[0, :2], [-4.0, -4.0], atol=1e-9)
    assert np.isclose(s.position[0, 2], 0.5)  # on top of the box


def test_village_is_reproducible_and_shipped_file_is_current(village) -> None:
    a, b = village_scene(), village_scene()
    for name in a:
        np.testing.assert_array_equal(a[name].vertices, b[name].vertices)
    assert DEFAULT_TERRAIN.stat().st_size < 2_000_000
    for name, mesh in a.items():
        shipped = village.meshes[name]
        assert len(shipped.faces) == len(mesh.faces), (
            f"{name}: stale village.glb; run `ttes stub make-terrain`"
        )
        np.testing.assert_allclose(
            np.sort(shipped.vertices, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-3
        )


def test_village_has_the_mout_site_features(village) -> None:
    plan = buildings()
    storeys = {b.storeys for b in plan}
    assert len(plan) >= 15 and storeys >= {1, 2, 3}
    office = next(b for b in plan if b.name == "office")
    assert office.storeys == 1 and office.w * office.d >= 300  # low and wide
    assert village.landmarks == {**village.landmarks, **landmarks()}
    # gentle relief: flat-ish village, a few metres over the fields, slopes of a few percent
    g = np.linspace(-140, 140, 57)
    x, y = np.meshgrid(g, g)
    z = relief(x, y)
    assert 2.0 < z.max() - z.min() < 15.0
    assert np.abs(np.gradient(z, g[1] - g[0])).max() < 0.12
    core = relief(np.linspace(-30, 30, 7), np.zeros(7))
    assert np.ptp(core) < 1.5  # the village core: a slope of about 2 %


def test_other_formats_and_up_axes(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(10, 20, 2))
    obj = tmp_path / "box.obj"
    box.export(obj)
    z_up = load_terrain(obj)
    assert np.isclose(z_up.height(np.array([[0.0, 9.0]]))[0], 1.0)
    y_up = load_terrain(obj, up="y")  # the same file read as +Y up: its 20 m side now stands vertically
    assert np.isclose(y_up.height(np.array([[0.0, 0.5]]))[0], 10.0)
    with pytest.raises(TerrainError):
        load_terrain(tmp_path / "absent.glb")
    with pytest.raises(TerrainError):
        load_terrain(obj, up="x")


@settings(max_examples=60)
@given(
    arrays(np.float64, (12, 3), elements=st.floats(-10, 10)),
    arrays(np.int64, (10, 3), elements=st.integers(0, 11)),
    arrays(np.float64, (15, 2), elements=st.floats(-11, 11)),
    st.floats(-12, 12),
    st.sampled_from([None, 0.5, 3.0]),
)
def test_ground_query_matches_brute_force_on_triangle_soups(
    verts: np.ndarray, faces: np.ndarray, xy: np.ndarray, z_from: float, cell: float | None
) -> None:
    q = GroundQuery(verts, faces, cell=cell)
    got = q.heights(xy, z_from)
    want = brute_force_heights(verts, faces, xy, np.full(len(xy), z_from))
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))  # the same rays hit something
    hit = ~np.isnan(got)
    np.testing.assert_allclose(got[hit], want[hit], atol=1e-6)


def test_ground_query_handles_walls_and_empty_meshes() -> None:
    wall = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 5.0]])
    q = GroundQuery(wall, np.array([[0, 1, 2]]))
    assert q.ntriangles == 0 and np.isnan(q.heights(np.array([[0.5, 0.0]]))).all()


def test_make_terrain_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from ttes.cli import main

    out = tmp_path / "v.glb"
    assert main(["stub", "make-terrain", "--out", str(out), "--json"]) == 0
    assert '"buildings": 20' in capsys.readouterr().out
    assert out.with_suffix(".json").is_file()
    assert load_terrain(out).meshes.keys() == {"ground", "streets", "buildings", "roofs", "windows", "trees"}
