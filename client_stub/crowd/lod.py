"""Levels of detail for the crowd (DI-Guy's idea: 2,500 polygons near, 38 far), and their meshes.

Three levels, chosen per soldier by distance from the camera every frame:

* **near** — ``soldier.fig`` (69 segments, about 2,660 triangles), posed from the DI.fig joint angles the
  server sends: joints with the same name and DOF count copy their angles; DI.fig's ``belly`` is spread
  over the lumbar joints ``vl3..vl1`` and ``upper_spine`` over the twelve thoracic joints, ``eyes`` drives
  both eyes; fingers stay straight. (The 1994 system slaved the polybody to DI.fig by constraints; this
  is the cheap, approximate version a renderer can afford.)
* **mid** — ``DI.fig`` itself (21 segments with geometry, about 500 triangles) and the rifle as a box;
* **far** — an *impostor*: 2 triangles, a quad along the body's up axis (the figure root, so prone
  soldiers lie and dead ones fall) turned towards the eye, on which the fragment shader cuts out a
  soldier's silhouette (head, arms, torso, legs, boots). DI-Guy's farthest level had 38 polygons.

Each level is one mesh of all its body parts (plus the rifle), every vertex tagged with its *part*; the
renderer draws a level with one instanced draw call and per-instance part matrices (:mod:`.gl`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from client_stub.crowd.fk import FastFigure
from client_stub.stub.scene_graph import FigureGraph, SegmentGeometry

NEAR, MID, FAR = 0, 1, 2
LEVEL_NAMES = ("near", "mid", "far")
DEFAULT_NEAR_M = 10.0
DEFAULT_MID_M = 30.0
IMPOSTOR_COLOUR = (0.33, 0.36, 0.22)  # DI.fig's olive uniform
SKIN_COLOUR = (0.78, 0.6, 0.48)
RIFLE_BOX_COLOUR = (0.24, 0.2, 0.16)
# DI.fig joint -> soldier.fig joints sharing its angles (each gets 1/len of them)
SPREAD = {
    "belly": ("vl3", "vl2", "vl1"),
    "upper_spine": tuple(f"vt{k}" for k in range(12, 0, -1)),
    "eyes": (),  # both eyes copy it (see dof_map)
}


@dataclass
class LodModel:
    """One level's mesh: flat-shaded triangles, each vertex tagged with the part (body segment) it follows.

    ``parts`` are ``(figure, node)``: figure 0 is the body, 1 the rifle; node 0 is the figure DCS, ``k + 1``
    joint ``k``'s DCS (:meth:`FastFigure.local_nodes` order)."""

    name: str
    positions: np.ndarray  # (v, 3) float32, in the part's frame
    normals: np.ndarray  # (v, 3) float32
    colours: np.ndarray  # (v, 3) float32
    part: np.ndarray  # (v,) float32 part number
    parts: list[tuple[int, int]]

    @property
    def triangles(self) -> int:
        return len(self.positions) // 3

    def interleaved(self) -> np.ndarray:
        """(v, 10) float32: position, normal, colour, part (the vertex buffer layout of :mod:`.gl`)."""
        return np.ascontiguousarray(
            np.column_stack([self.positions, self.normals, self.colours, self.part]), np.float32
        )


def flat_triangles(geom: SegmentGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Un-indexed triangles of a segment: positions, flat normals, colours (3 vertices per triangle)."""
    tri = np.asarray(geom.triangles, np.int64)
    p = np.asarray(geom.vertices, np.float64)[tri]  # (t, 3, 3)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    if geom.vertex_colors is not None:
        col = np.asarray(geom.vertex_colors, np.float64)[tri][..., :3]
    else:
        diffuse = np.asarray(geom.diffuse, np.float64).reshape(-1, 3)
        attr = np.asarray(geom.triangle_attribute, np.int64)
        rgb = np.where(
            (attr < len(diffuse))[:, None], diffuse[np.clip(attr, 0, max(len(diffuse) - 1, 0))], 0.7
        )
        col = np.repeat(rgb[:, None], 3, axis=1)
    return p.reshape(-1, 3), np.repeat(n[:, None], 3, axis=1).reshape(-1, 3), col.reshape(-1, 3)


def box_geometry(
    geom: SegmentGeometry, colour: tuple[float, float, float] = RIFLE_BOX_COLOUR
) -> SegmentGeometry:
    """A segment as one 12-triangle box: full extent along its longest axis, the middle 60 % of its
    vertices across (so a rifle's magazine and sights do not make a slab of it)."""
    v = np.asarray(geom.vertices, np.float64)
    lo, hi = np.percentile(v, 20, axis=0), np.percentile(v, 80, axis=0)
    long = int(np.argmax(v.max(axis=0) - v.min(axis=0)))
    lo[long], hi[long] = v[:, long].min(), v[:, long].max()
    corners, tris = _box(lo, hi)
    return SegmentGeometry(
        geom.figure, geom.segment, corners, tris, np.zeros(len(tris), np.int64), np.array([colour])
    )


def figure_model(name: str, figures: list[FigureGraph], boxed: tuple[bool, ...] = ()) -> LodModel:
    """A level made of the segment geometry of ``figures`` (the body, then the rifle); figures flagged in
    ``boxed`` contribute their segments' bounding boxes instead (the mid level's rifle: 12 triangles, not
    the AK-47's 228)."""
    pos, nrm, col, part = [], [], [], []
    parts: list[tuple[int, int]] = []
    for f, fig in enumerate(figures):
        for geom, node in fig.segments:
            if geom is None or not len(geom.triangles):
                continue
            if f < len(boxed) and boxed[f]:
                geom = box_geometry(geom)
            p, n, c = flat_triangles(geom)
            part.append(np.full(len(p), len(parts), np.float32))
            parts.append((f, 0 if node < 0 else node + 1))
            pos.append(p)
            nrm.append(n)
            col.append(c)
    return LodModel(
        name,
        np.concatenate(pos).astype(np.float32),
        np.concatenate(nrm).astype(np.float32),
        np.concatenate(col).astype(np.float32),
        np.concatenate(part),
        parts,
    )


def body_bounds(body: FastFigure) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (lo, hi) of the body's geometry in the figure-DCS frame of the zero pose (for the impostor)."""
    nodes = body.local_nodes(np.zeros((1, body.ndof)), body.location[None])[0]
    root = nodes[0]
    inv_r = root[:, :3].T
    pts = []
    for geom, node in body.graph.segments:
        if geom is None or not len(geom.vertices):
            continue
        m = nodes[0 if node < 0 else node + 1]
        world = np.asarray(geom.vertices) @ m[:, :3].T + m[:, 3]
        pts.append((world - root[:, 3]) @ inv_r.T)
    allp = np.concatenate(pts)
    return allp.min(axis=0), allp.max(axis=0)


def _box(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corners and 12 outward (counter-clockwise) triangles of an axis-aligned box."""
    c = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return c, np.array([t for a, b, cc, d in quads for t in ((a, b, cc), (a, cc, d))], np.int64)


@dataclass(frozen=True)
class Impostor:
    """The far level: a silhouette billboard spanning the body from ``feet`` to ``head`` (metres along the
    root's up axis from the pelvis), ``halfwidth`` either side (:mod:`.gl` draws it: 2 triangles)."""

    feet: float
    head: float
    halfwidth: float = 0.3
    triangles: int = 2


def impostor_for(lo: np.ndarray, hi: np.ndarray) -> Impostor:
    """The impostor of a body whose zero-pose bounds in the figure-DCS frame are ``lo..hi``."""
    return Impostor(float(lo[2]), float(hi[2]), 0.3)


def dof_map(source: FigureGraph, target: FigureGraph) -> np.ndarray:
    """(target.ndof, source.ndof) matrix taking DI.fig pose vectors to soldier.fig ones (see the module)."""
    m = np.zeros((target.ndof, source.ndof), np.float32)
    for name, src in source.dof_slices.items():
        n = src.stop - src.start
        dst = target.dof_slices.get(name)
        if dst is not None and dst.stop - dst.start == n:
            m[dst, src] += np.eye(n, dtype=np.float32)
            continue
        if name == "eyes":
            for eye in ("left_eye", "right_eye"):
                d = target.dof_slices.get(eye)
                if d is not None and d.stop - d.start == n:
                    m[d, src] += np.eye(n, dtype=np.float32)
            continue
        spread = [target.dof_slices[j] for j in SPREAD.get(name, ()) if j in target.dof_slices]
        spread = [d for d in spread if d.stop - d.start == n]
        for d in spread:
            m[d, src] += np.eye(n, dtype=np.float32) / len(spread)
    return m


def choose_levels(
    distance: np.ndarray, near_m: float = DEFAULT_NEAR_M, mid_m: float = DEFAULT_MID_M
) -> np.ndarray:
    """(n,) level per soldier: NEAR within ``near_m``, MID within ``mid_m``, FAR beyond."""
    d = np.asarray(distance)
    return np.where(d < near_m, NEAR, np.where(d < mid_m, MID, FAR)).astype(np.int8)


def visible(points: np.ndarray, viewproj: np.ndarray, radius: float = 1.2) -> np.ndarray:
    """(n,) bool: may a sphere of ``radius`` around each point be in the view frustum? (A conservative test
    in clip space: the radius is added to each plane's slack, scaled by the projection's largest axis.)"""
    p = np.column_stack([points, np.ones(len(points))]) @ np.asarray(viewproj, np.float64).T
    w = p[:, 3]
    scale = float(np.abs(viewproj[:2, :3]).max()) * radius
    ok = w > -radius
    for axis in (0, 1):
        ok &= np.abs(p[:, axis]) <= w + scale
    ok &= p[:, 2] <= w + scale
    return ok
