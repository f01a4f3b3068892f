"""The terrain database: any OBJ / glTF / PLY mesh, in Performer axes, with its ground query and landmarks.

The 1994 stub read ``urban.flt`` with Performer's Flight loader; we read whatever trimesh reads. glTF files
are +Y up by their specification, so by default they are turned to Performer's +Z up (glTF's axes are Jack's:
``protocol.coords.JACK_TO_PERFORMER`` does it); other formats are taken as +Z up unless told (``up="y"``).
Landmarks (where soldiers start and walk, where key ``a`` adds one) come from a ``.json`` beside the mesh,
else from the mesh's bounds.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from client_stub.data_paths import DEFAULT_TERRAIN
from client_stub.stub.ground import GroundQuery
from protocol import coords


class TerrainError(ValueError):
    """A terrain file that cannot be read or holds no triangles."""


@dataclass
class Terrain:
    meshes: dict[str, trimesh.Trimesh]  # Performer axes, metres
    ground: GroundQuery
    landmarks: dict = field(default_factory=dict)
    source: str = ""

    @property
    def bounds(self) -> np.ndarray:
        return self.ground.bounds

    def landmark(self, name: str) -> np.ndarray:
        """A landmark's XY (``centre``, ``office``, ``fields``)."""
        return np.asarray(self.landmarks[name], np.float64)[:2]

    def height(self, xy: np.ndarray, z_from: np.ndarray | float = np.inf, default: float = 0.0) -> np.ndarray:
        """Ground height under points; ``default`` off the terrain."""
        h = self.ground.heights(xy, z_from)
        return np.where(np.isnan(h), default, h)


def default_landmarks(bounds: np.ndarray) -> dict:
    lo, hi = bounds[0, :2], bounds[1, :2]
    c = (lo + hi) / 2
    span = float(max(np.min(hi - lo), 1.0))
    return {
        "centre": c.tolist(),
        "office": (c + np.array([0.15 * span, -0.1 * span])).tolist(),
        "fields": (c + np.array([0.0, -0.35 * span])).tolist(),
        "square": {"centre": (c + np.array([0.0, 0.1 * span])).tolist(), "side": 0.08 * span},
        "circle": {"centre": (c + np.array([0.0, -0.25 * span])).tolist(), "radius": 0.05 * span},
        "groups": {
            "friendly": (c - 0.04 * span).tolist(),
            "opposing": (c + np.array([0.05 * span, 0.2 * span])).tolist(),
        },
        "extent": [*lo.tolist(), *hi.tolist()],
    }


def _rotation(up: str) -> np.ndarray:
    m = np.eye(4)
    if up == "y":
        m[:3, :3] = coords.JACK_TO_PERFORMER
    elif up != "z":
        raise TerrainError(f"up must be 'y' or 'z', not {up!r}")
    return m


def load_terrain(path: str | os.PathLike[str] = DEFAULT_TERRAIN, up: str | None = None) -> Terrain:
    """Read a terrain mesh file; ``up`` is its up axis (default: ``y`` for glTF, ``z`` otherwise)."""
    p = Path(path)
    if up is None:
        up = "y" if p.suffix.lower() in (".glb", ".gltf") else "z"
    rot = _rotation(up)
    try:
        scene = trimesh.load(p, force="scene")
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise TerrainError(f"{p}: cannot load terrain: {exc}") from None
    assert isinstance(scene, trimesh.Scene)  # force="scene"; load() is typed as any Geometry
    meshes: dict[str, trimesh.Trimesh] = {}
    for node in scene.graph.nodes_geometry:
        transform, geom_name = scene.graph[node]
        geom = scene.geometry.get(geom_name)
        if not isinstance(geom, trimesh.Trimesh) or not len(geom.faces):
            continue
        mesh = geom.copy()
        mesh.apply_transform(rot @ transform)
        meshes[str(node)] = mesh
    if not meshes:
        raise TerrainError(f"{p}: no triangles")
    vertices = np.concatenate([m.vertices for m in meshes.values()])
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes.values()])[:-1]
    faces = np.concatenate([m.faces + o for m, o in zip(meshes.values(), offsets, strict=True)])
    ground = GroundQuery(vertices, faces)
    sidecar = p.with_suffix(".json")
    marks = default_landmarks(ground.bounds)
    if sidecar.is_file():
        try:
            marks.update(json.loads(sidecar.read_text(encoding="utf-8")))
        except (OSError, ValueError) as exc:
            raise TerrainError(f"{sidecar}: bad landmarks: {exc}") from None
    return Terrain(meshes, ground, marks, str(p))


def terrain_from_mesh(mesh: trimesh.Trimesh, landmarks: dict | None = None) -> Terrain:
    """A terrain from one mesh already in Performer axes (tests, generated ground)."""
    ground = GroundQuery(mesh.vertices, mesh.faces)
    marks = default_landmarks(ground.bounds)
    marks.update(landmarks or {})
    return Terrain({"ground": mesh}, ground, marks, "<mesh>")
