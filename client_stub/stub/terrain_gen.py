"""A generated village in the spirit of the seed's Quantico MOUT site (Figure 8; ``ttes stub make-terrain``).

The 1994 stub loaded ``urban.flt``, the Marine Corps' Quantico village. We do not have it, so we build a
small military-operations-on-urban-terrain site reproducibly (a fixed seed, no clock): gentle rolling
relief, a village on a flattened core with a main street, cross streets and a square, buildings of one to
three storeys (houses with pitched roofs, shops, a hotel, a church with a steeple), the **low office
building** east of the square (where key ``a`` adds soldiers), walls, trees, and open fields around.

Everything is built in Performer axes (metres, +Z up, +Y north, the village centre at the origin) and
written as binary glTF in glTF's own axes (+Y up, so ``(x, y, z)_glTF = (x, z, -y)_Performer``, which are
Jack's axes); ``client_stub.stub.terrain`` converts back. Landmarks (centre, office, walking paths, cameras)
go to a JSON sidecar next to the mesh.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from client_stub.data_paths import DEFAULT_TERRAIN

SEED = 1994
HALF = 150.0  # the terrain spans [-HALF, HALF]^2 metres
GRID = 3.0  # ground mesh spacing, metres
STOREY = 3.0
DEFAULT_OUT = DEFAULT_TERRAIN

GRASS = (0.36, 0.47, 0.23)
FIELD = (0.55, 0.55, 0.30)
DIRT = (0.50, 0.43, 0.32)
ROAD = (0.30, 0.30, 0.31)
WINDOW = (0.10, 0.12, 0.15)
WALLS = [(0.80, 0.74, 0.62), (0.70, 0.70, 0.68), (0.62, 0.38, 0.30), (0.85, 0.82, 0.74), (0.66, 0.58, 0.46)]
ROOFS = [(0.30, 0.30, 0.32), (0.55, 0.25, 0.20), (0.42, 0.36, 0.30)]
OFFICE_WALL = (0.78, 0.78, 0.80)
TRUNK = (0.35, 0.25, 0.16)
LEAVES = (0.20, 0.36, 0.16)


def relief(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Ground height (m): rolling fields (slopes of a few percent), flattened under the village."""
    rolling = (
        2.2 * np.sin(x / 47.0) * np.cos(y / 61.0) + 0.9 * np.sin((x + 2 * y) / 33.0) + 0.012 * x + 0.006 * y
    )
    r = np.hypot(x / 85.0, y / 75.0)
    w = np.clip((r - 0.6) / 0.5, 0.0, 1.0)
    w = w * w * (3 - 2 * w)  # smoothstep: 0 in the village core, 1 in the fields
    return 0.25 * rolling + 0.75 * w * rolling


@dataclass(frozen=True)
class Building:
    name: str
    x: float
    y: float
    w: float  # along x
    d: float  # along y
    storeys: int
    roof: str  # "flat" or "gable"
    wall: tuple[float, float, float]
    roof_colour: tuple[float, float, float]


def _coloured(mesh: trimesh.Trimesh, colour: tuple[float, float, float]) -> trimesh.Trimesh:
    rgba = np.array([*colour, 1.0]) * 255
    mesh.visual = trimesh.visual.ColorVisuals(
        mesh, face_colors=np.tile(rgba.astype(np.uint8), (len(mesh.faces), 1))
    )
    return mesh


def _box(lo: np.ndarray, hi: np.ndarray, colour: tuple[float, float, float]) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    box = trimesh.creation.box(extents=hi - lo)
    box.apply_translation((lo + hi) / 2)
    return _coloured(box, colour)


def _ground() -> trimesh.Trimesh:
    n = round(2 * HALF / GRID) + 1
    g = np.linspace(-HALF, HALF, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    z = relief(x, y)
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    rng = np.random.default_rng(SEED)
    r = np.hypot(x / 85.0, y / 75.0).ravel()
    base = np.where(r < 0.85, 0.0, 1.0)[:, None]
    fields = ((np.floor((x.ravel() + 300) / 42) + np.floor((y.ravel() + 300) / 36)) % 3 == 0)[:, None]
    colour = np.where(base > 0, np.where(fields, FIELD, GRASS), DIRT)
    colour = colour * (0.92 + 0.16 * rng.random((len(vertices), 1)))
    rgba = np.concatenate([np.clip(colour, 0, 1), np.ones((len(vertices), 1))], axis=1)
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=(rgba * 255).astype(np.uint8))
    return mesh


def _road(p0: tuple[float, float], p1: tuple[float, float], width: float) -> trimesh.Trimesh:
    """A straight road strip draped 6 cm over the relief, sampled every GRID/2 metres."""
    a, b = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.linalg.norm(b - a))
    n = max(int(np.ceil(length / (GRID / 2))), 1) + 1
    t = np.linspace(0.0, 1.0, n)[:, None]
    centre = a + t * (b - a)
    side = np.array([-(b - a)[1], (b - a)[0]]) / length * width / 2
    left, right = centre + side, centre - side
    xy = np.stack([left, right], axis=1).reshape(-1, 2)
    z = relief(xy[:, 0], xy[:, 1]) + 0.06
    vertices = np.column_stack([xy, z])
    k = np.arange(n - 1) * 2
    faces = np.concatenate([np.stack([k, k + 1, k + 3], 1), np.stack([k, k + 3, k + 2], 1)])
    return _coloured(trimesh.Trimesh(vertices, faces, process=False), ROAD)


def _gable(
    lo: np.ndarray, hi: np.ndarray, rise: float, colour: tuple[float, float, float]
) -> trimesh.Trimesh:
    """A gable roof prism over the box ``lo..hi`` (ridge along the longer side)."""
    (x0, y0, z0), (x1, y1, _) = lo, hi
    if x1 - x0 >= y1 - y0:
        ym = (y0 + y1) / 2
        pts = [
            (x0, y0, z0),
            (x1, y0, z0),
            (x1, y1, z0),
            (x0, y1, z0),
            (x0, ym, z0 + rise),
            (x1, ym, z0 + rise),
        ]
    else:
        xm = (x0 + x1) / 2
        pts = [
            (x0, y0, z0),
            (x1, y0, z0),
            (x1, y1, z0),
            (x0, y1, z0),
            (xm, y0, z0 + rise),
            (xm, y1, z0 + rise),
        ]
    return _coloured(trimesh.convex.convex_hull(np.array(pts)), colour)


def _windows(lo: np.ndarray, hi: np.ndarray, storeys: int) -> list[trimesh.Trimesh]:
    """Dark window panes 4 cm proud of every wall, two or more per storey."""
    out = []
    for s in range(storeys):
        zc = lo[2] + 0.8 + s * STOREY + 1.0
        if zc + 0.7 > hi[2]:
            break
        for axis in (0, 1):
            span = hi[axis] - lo[axis]
            count = max(int(span // 4.0), 1)
            centres = lo[axis] + (np.arange(count) + 0.5) * span / count
            other = 1 - axis
            for face in (lo[other] - 0.04, hi[other] + 0.04):
                for c in centres:
                    wlo, whi = np.zeros(3), np.zeros(3)
                    wlo[axis], whi[axis] = c - 0.6, c + 0.6
                    wlo[other], whi[other] = face - 0.02, face + 0.02
                    wlo[2], whi[2] = zc - 0.7, zc + 0.7
                    out.append(_box(wlo, whi, WINDOW))
    return out


def buildings() -> list[Building]:
    """The village plan: named landmarks, then houses along the streets (a seeded choice of sizes)."""
    rng = np.random.default_rng(SEED + 1)
    plan = [
        Building("office", 34.0, -22.0, 30.0, 14.0, 1, "flat", OFFICE_WALL, ROOFS[0]),
        Building("church", -30.0, 24.0, 12.0, 22.0, 3, "gable", WALLS[3], ROOFS[1]),
        Building("hotel", 20.0, 22.0, 18.0, 12.0, 3, "flat", WALLS[1], ROOFS[0]),
        Building("town_hall", -20.0, -20.0, 16.0, 12.0, 2, "flat", WALLS[2], ROOFS[0]),
    ]
    slots = [(-56, 14), (-44, 14), (-56, -14), (-44, -14), (44, 14), (56, 14), (66, -10), (52, 36),
             (-6, 40), (-6, -38), (8, -40), (-58, 34), (-40, -38), (20, 42), (60, 30), (-66, -2)]  # fmt: skip
    for k, (x, y) in enumerate(slots):
        w, d = rng.uniform(7.0, 11.0), rng.uniform(6.0, 9.0)
        storeys = int(rng.integers(1, 3))
        roof = "gable" if rng.random() < 0.6 else "flat"
        wall = WALLS[int(rng.integers(len(WALLS)))]
        plan.append(
            Building(f"house_{k}", float(x), float(y), w, d, storeys, roof, wall, ROOFS[int(rng.integers(3))])
        )
    return plan


def _building_meshes(
    b: Building,
) -> tuple[list[trimesh.Trimesh], list[trimesh.Trimesh], list[trimesh.Trimesh]]:
    xs = np.array([b.x - b.w / 2, b.x + b.w / 2])
    ys = np.array([b.y - b.d / 2, b.y + b.d / 2])
    gx, gy = np.meshgrid(np.linspace(xs[0], xs[1], 5), np.linspace(ys[0], ys[1], 5))
    ground = relief(gx, gy)
    base, top = float(ground.min()) - 0.3, float(ground.max()) + b.storeys * STOREY + 0.5
    lo, hi = np.array([xs[0], ys[0], base]), np.array([xs[1], ys[1], top])
    walls = [_box(lo, hi, b.wall)]
    roofs: list[trimesh.Trimesh] = []
    if b.roof == "gable":
        roofs.append(
            _gable(
                np.array([xs[0] - 0.3, ys[0] - 0.3, top]),
                np.array([xs[1] + 0.3, ys[1] + 0.3, top]),
                min(b.w, b.d) * 0.35,
                b.roof_colour,
            )
        )
    else:
        roofs.append(
            _box(
                np.array([xs[0] - 0.2, ys[0] - 0.2, top]),
                np.array([xs[1] + 0.2, ys[1] + 0.2, top + 0.4]),
                b.roof_colour,
            )
        )
    if b.name == "church":  # the steeple: the tallest thing in the village
        s = np.array([b.x - 2.5, ys[1] - 5.0, base])
        walls.append(_box(s, s + np.array([5.0, 5.0, top - base + 8.0]), b.wall))
        tip = _gable(
            s + np.array([-0.2, -0.2, top - base + 8.0]), s + np.array([5.2, 5.2, 0]), 6.0, b.roof_colour
        )
        roofs.append(tip)
    return walls, roofs, _windows(lo, hi, b.storeys)


def _trees(rng: np.random.Generator, count: int) -> list[trimesh.Trimesh]:
    out = []
    placed = 0
    while placed < count:
        x, y = rng.uniform(-HALF + 10, HALF - 10, 2)
        if abs(x) < 78 and abs(y) < 60:  # not in the village
            continue
        z = float(relief(np.array(x), np.array(y)))
        trunk = trimesh.creation.cylinder(radius=0.25, height=2.5, sections=6)
        trunk.apply_translation((x, y, z + 1.25))
        crown = trimesh.creation.cone(radius=2.0, height=5.0, sections=8)
        crown.apply_translation((x, y, z + 2.0))
        out += [_coloured(trunk, TRUNK), _coloured(crown, LEAVES)]
        placed += 1
    return out


def _walls() -> list[trimesh.Trimesh]:
    """Low garden walls along the south-west: cover for the kneeling and prone soldiers."""
    out = []
    for x0, y0, x1, y1 in [(-70, -30, -50, -30), (-70, -30, -70, -46), (-12, 30, -12, 50)]:
        lo = np.array([min(x0, x1) - 0.2, min(y0, y1) - 0.2, 0.0])
        hi = np.array([max(x0, x1) + 0.2, max(y0, y1) + 0.2, 0.0])
        zs = relief(np.array([lo[0], hi[0]]), np.array([lo[1], hi[1]]))
        lo[2], hi[2] = float(zs.min()) - 0.3, float(zs.max()) + 1.1
        out.append(_box(lo, hi, WALLS[1]))
    return out


def landmarks() -> dict:
    """Named places the stub uses (Performer metres): where soldiers start, walk, and where key ``a`` adds."""
    office = next(b for b in buildings() if b.name == "office")
    return {
        "centre": [0.0, 0.0],
        "office": [office.x, office.y - office.d / 2 - 4.0],  # in front of its south door
        "fields": [0.0, -110.0],
        "square": {"centre": [-2.0, 18.0], "side": 16.0},
        "circle": {"centre": [0.0, -75.0], "radius": 10.0},
        "groups": {"friendly": [-8.0, -8.0], "opposing": [10.0, 62.0]},
        "extent": [-HALF, -HALF, HALF, HALF],
    }


def _merge(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """One mesh of several (``trimesh.util.concatenate`` is typed as any Geometry; meshes give a mesh)."""
    merged = trimesh.util.concatenate(meshes)
    assert isinstance(merged, trimesh.Trimesh)
    return merged


def village_scene() -> dict[str, trimesh.Trimesh]:
    """The village's meshes by layer, Performer axes."""
    rng = np.random.default_rng(SEED + 2)
    roads = [
        _road((-95.0, 0.0), (95.0, 0.0), 8.0),
        _road((0.0, -120.0), (0.0, 70.0), 7.0),
        _road((-38.0, -45.0), (-38.0, 45.0), 6.0),
        _road((38.0, -45.0), (38.0, 45.0), 6.0),
        _road((-60.0, 30.0), (60.0, 30.0), 6.0),
        _road((-60.0, -32.0), (60.0, -32.0), 6.0),
        _road((-14.0, 10.0), (14.0, 10.0), 14.0),  # the square
    ]
    walls: list[trimesh.Trimesh] = []
    roofs: list[trimesh.Trimesh] = []
    windows: list[trimesh.Trimesh] = []
    for b in buildings():
        w, r, win = _building_meshes(b)
        walls += w
        roofs += r
        windows += win
    return {
        "ground": _ground(),
        "streets": _merge(roads),
        "buildings": _merge(walls + _walls()),
        "roofs": _merge(roofs),
        "windows": _merge(windows),
        "trees": _merge(_trees(rng, 40)),
    }


PERFORMER_TO_GLTF = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])


def write_village(out: str | os.PathLike[str] = DEFAULT_OUT) -> dict:
    """Write the village mesh (``.glb``) and its landmarks (``.json`` beside it); returns a summary."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    scene = trimesh.Scene()
    for name, mesh in village_scene().items():
        m = mesh.copy()
        m.apply_transform(PERFORMER_TO_GLTF)
        scene.add_geometry(m, geom_name=name, node_name=name)
    data = scene.export(file_type="glb")
    out.write_bytes(data)
    marks = landmarks()
    out.with_suffix(".json").write_text(json.dumps(marks, indent=1) + "\n", encoding="utf-8")
    triangles = sum(len(g.faces) for g in scene.geometry.values())
    return {"file": str(out), "bytes": len(data), "triangles": triangles, "buildings": len(buildings())}
