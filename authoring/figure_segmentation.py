"""Cut the MakeHuman skin into rigid Peabody segments and decimate them to a polygon budget.

Why: a Jack figure is a tree of rigid segments, each with its own psurf in its own frame. The skin is
one smooth mesh with blend weights, so every vertex goes to the segment of its dominant bone, every
quad to the segment most of its vertices belong to, and the long torso is sliced by height into the
vertebrae of the 17-joint spine.

Decimation runs per *group* of neighbouring segments (a whole torso, a whole hand) rather than per
segment: thin slices such as vertebra bands share their borders, so decimating them together and only
then handing each decimated triangle back to the segment of the nearest original face leaves no cracks
between them in the neutral pose.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from authoring.makehuman_mesh import MakeHumanBody

FINGER_NAMES = ("thumb", "index", "middle", "ring", "pinky")
SIDES = {"L": "left", "R": "right"}

# Bone-name prefixes of the MakeHuman "default" rig -> generic body part (sided parts get "left_"/"right_").
_PREFIX_PARTS: tuple[tuple[str, str], ...] = (
    ("neck", "neck"),
    ("upperleg", "upper_leg"),
    ("lowerleg", "lower_leg"),
    ("toe", "toes"),
    ("foot", "foot"),
    ("shoulder01", "upper_arm"),  # the deltoid swings with the arm
    ("upperarm", "upper_arm"),
    ("lowerarm", "lower_arm"),
    ("wrist", "palm"),
    ("metacarpal", "palm"),
    ("clavicle", "clavicle"),
)


def bone_part(bone: str, parents: Mapping[str, str]) -> str:
    """The body part a MakeHuman bone's skin belongs to ('torso', 'head', 'left_index2', ...)."""
    chain = [bone]
    while parents.get(chain[-1]):
        chain.append(parents[chain[-1]])
    if "head" in chain:  # the face rig (jaw, lips, eyelids) all rides on the head
        return "head"
    base, _, side = bone.partition(".")
    sided = SIDES.get(side)
    if base.startswith("finger"):  # fingerK-J: K = 1 (thumb) .. 5 (little), J = phalanx
        k, j = base[len("finger") :].split("-")
        return f"{sided}_{FINGER_NAMES[int(k) - 1]}{j}"
    for prefix, part in _PREFIX_PARTS:
        if base.startswith(prefix):
            return f"{sided}_{part}" if sided else part
    return "torso"  # root, pelvis, spine01-05, breasts


def face_parts(body: MakeHumanBody, parents: Mapping[str, str]) -> np.ndarray:
    """Part name per quad: the part of the majority of its four vertices (ties: lowest part name)."""
    bone_parts = np.array([bone_part(b, parents) for b in body.bone_names])
    names, vertex_part = np.unique(bone_parts[body.vertex_bone], return_inverse=True)
    per_face = vertex_part[body.quads]  # (m, 4)
    counts = np.zeros((len(per_face), len(names)), dtype=np.int64)
    np.add.at(counts, (np.repeat(np.arange(len(per_face)), 4), per_face.ravel()), 1)
    return names[np.argmax(counts, axis=1)]


@dataclass(frozen=True)
class SegmentMesh:
    """One segment's geometry in figure coordinates (neutral pose)."""

    vertices: np.ndarray  # (n, 3)
    faces: np.ndarray  # (f, 3) triangles
    caps: tuple[np.ndarray, ...] = ()  # polygons closing the cuts at its joints

    @property
    def polygon_count(self) -> int:
        return len(self.faces) + len(self.caps)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Simple cycles of border edges (edges used by one triangle), each in the triangles' edge direction.

    Where borders touch at a vertex (a pinch left by splitting), the walk splits off a cycle as soon as
    it comes back to a vertex already on its path, so every returned loop is simple.
    """
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    base = int(faces.max()) + 1
    keys = directed[:, 0] * base + directed[:, 1]
    border = directed[~np.isin(directed[:, 1] * base + directed[:, 0], keys)]
    border = border[np.lexsort((border[:, 1], border[:, 0]))]
    outgoing: dict[int, list[int]] = {}
    for a, b in border.tolist():
        outgoing.setdefault(a, []).append(b)
    loops: list[np.ndarray] = []
    for start in sorted(outgoing):
        while outgoing.get(start):
            path, index = [start], {start: 0}
            v = start
            while outgoing.get(v):
                v = outgoing[v].pop(0)
                if v in index:  # a cycle closes: split it off the path
                    cycle = path[index[v] :]
                    for u in cycle[1:]:
                        del index[u]
                    del path[index[v] + 1 :]
                    if len(cycle) >= 3:
                        loops.append(np.asarray(cycle, dtype=np.int64))
                else:
                    index[v] = len(path)
                    path.append(v)
    return loops


def _newell(points: np.ndarray) -> np.ndarray:
    nxt = np.roll(points, -1, axis=0)
    n = np.array(
        [
            ((points[:, 1] - nxt[:, 1]) * (points[:, 2] + nxt[:, 2])).sum(),
            ((points[:, 2] - nxt[:, 2]) * (points[:, 0] + nxt[:, 0])).sum(),
            ((points[:, 0] - nxt[:, 0]) * (points[:, 1] + nxt[:, 1])).sum(),
        ]
    )
    return n / max(np.linalg.norm(n), 1e-12)


def cap(vertices: np.ndarray, loop: np.ndarray) -> np.ndarray | None:
    """One polygon closing a border loop, facing outward, or None.

    The polygon starts at a corner from which a triangle fan stays inside it (every fan triangle turns
    the same way as the loop), so a renderer that fans psurf polygons from their first vertex draws it
    correctly; loops with no such corner are left open.
    """
    poly = loop[::-1]  # borders run along the faces' edges; the lid runs the other way round
    p = vertices[poly]
    n = _newell(p)
    # row k: the corners in order starting at k; fan triangles (k, k+i, k+i+1) must all turn along n
    order = (np.arange(len(p))[:, None] + np.arange(len(p))[None, :]) % len(p)
    rel = p[order] - p[:, None, :]
    turns = np.cross(rel[:, 1:-1], rel[:, 2:]) @ n
    good = np.flatnonzero(np.all(turns > 1e-9, axis=1))
    if len(good) == 0:
        return None
    return np.roll(poly, -int(good[0]))


def _with_caps(vertices: np.ndarray, faces: np.ndarray) -> SegmentMesh:
    caps = tuple(c for c in (cap(vertices, loop) for loop in boundary_loops(faces)) if c is not None)
    return SegmentMesh(vertices, faces, caps)


def _triangulate(quads: np.ndarray) -> np.ndarray:
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=0)


def _compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used, inverse = np.unique(faces.ravel(), return_inverse=True)
    return vertices[used], inverse.reshape(faces.shape)


def _nearest(points: np.ndarray, reference: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """Index of the nearest reference point for each point (brute force, chunked)."""
    out = np.empty(len(points), dtype=np.int64)
    for start in range(0, len(points), chunk):
        p = points[start : start + chunk]
        d = ((p[:, None, :] - reference[None, :, :]) ** 2).sum(axis=2)
        out[start : start + chunk] = np.argmin(d, axis=1)
    return out


def triangle_neighbours(faces: np.ndarray) -> np.ndarray:
    """(f, 3) index of the triangle across each edge (-1 on borders and non-manifold edges)."""
    a = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.sort(a, axis=1)
    key = key[:, 0] * (int(faces.max()) + 1) + key[:, 1]
    tri = np.tile(np.arange(len(faces)), 3)
    order = np.argsort(key, kind="stable")
    ks, ts = key[order], tri[order]
    out = np.full(len(a), -1, dtype=np.int64)
    pair = np.flatnonzero(ks[:-1] == ks[1:])
    single = np.ones(len(pair), dtype=bool)  # keep only edges shared by exactly two triangles
    if len(pair):
        single[1:] &= pair[1:] != pair[:-1] + 1
        single[:-1] &= pair[:-1] + 1 != pair[1:]
    pair = pair[single]
    out[order[pair]] = ts[pair + 1]
    out[order[pair + 1]] = ts[pair]
    return out.reshape(3, len(faces)).T


def smooth_labels(faces: np.ndarray, labels: np.ndarray, rounds: int = 4) -> np.ndarray:
    """A triangle whose neighbours across two or three edges share another label takes that label."""
    nb = triangle_neighbours(faces)
    out = labels.copy()
    for _ in range(rounds):
        lab = np.where(nb >= 0, out[np.maximum(nb, 0)], "")
        a, b, c = lab[:, 0], lab[:, 1], lab[:, 2]
        major = np.where((a == b) | (a == c), a, np.where(b == c, b, ""))
        change = (major != "") & (major != out)
        if not change.any():
            break
        out = np.where(change, major, out)
    return out


def decimate(vertices: np.ndarray, faces: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadric decimation to about ``target`` triangles (``fast-simplification``)."""
    import fast_simplification

    if target >= len(faces):
        return _compact(vertices, faces)
    v, f = fast_simplification.simplify(
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=np.int64),
        target_count=max(int(target), 4),
        agg=7.0,
    )
    return _compact(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))


def segment_meshes(
    body: MakeHumanBody,
    face_segment: np.ndarray,
    groups: Sequence[tuple[Sequence[str], int]],
    extra: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
    uncapped: Collection[str] = (),
) -> dict[str, SegmentMesh]:
    """Decimate each group of segments to its budget, then split it back into its segments.

    ``face_segment`` names the segment of every body quad; ``groups`` lists (segment names, triangle
    budget); ``extra`` adds standalone meshes (eyeballs) given as (vertices, quads) with a budget entry
    in ``groups`` under the same name. Cuts are closed with cap polygons except on ``uncapped``
    segments (thin slices such as vertebrae, whose cuts are hidden by their neighbours).
    """
    out: dict[str, SegmentMesh] = {}
    tris = _triangulate(body.quads)
    face_segment = np.asarray(face_segment, dtype=str)
    tri_segment = np.concatenate([face_segment, face_segment])
    extra = extra or {}
    for names, budget in groups:
        if len(names) == 1 and names[0] in extra:
            ev, eq = extra[names[0]]
            out[names[0]] = _with_caps(*decimate(ev, _triangulate(eq), budget))
            continue
        mask = np.isin(tri_segment, list(names))
        if not mask.any():
            raise ValueError(f"decimation group {list(names)} has no faces")
        gv, gf = _compact(body.vertices, tris[mask])
        labels = tri_segment[mask]
        if len(names) == 1:
            out[names[0]] = _with_caps(*decimate(gv, gf, budget))
            continue
        v, f = decimate(gv, gf, budget)
        # hand each decimated triangle back to the segment of the nearest original triangle, then let
        # stray triangles join their neighbours so the cuts run as clean loops
        owner = smooth_labels(f, labels[_nearest(v[f].mean(axis=1), gv[gf].mean(axis=1))])
        for name in names:
            sel = f[owner == name]
            if len(sel) == 0:
                raise ValueError(f"segment {name!r} lost all its faces when decimating {list(names)}")
            sv, sf = _compact(v, sel)
            out[name] = SegmentMesh(sv, sf) if name in uncapped else _with_caps(sv, sf)
    return out
