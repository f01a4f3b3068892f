"""The TIPS loader (seed 002, section 7; 1994's ``pftips.c++``): read ``.tips`` files into plain objects.

Reads both the 7.1 format (polygons over a node table) and the 7.3 alternate (geosets of triangle strips with
colour, normal and texture bindings), told apart at the first line after a segment's attributes
(``geoset`` starts the alternate). The file is line-oriented: a ``[COMMENT]`` is the rest of a line, vectors
and matrices are whole lines. Our readings of what the seed leaves open are those of the spitter
(``peabody/tips.py``, documented there): Jack units and axes (cm, +Y up), matrices in the row-vector
layout (translation in the fourth row; transposed here to column-vector), ``R|T ax ay az lower upper`` DOF
lines, ``JOINT #k`` naming a joint's place in the pose vector, qualified ``segment.site`` other-site names.

Every fault raises :class:`TipsError` with the file and line; nothing else escapes for any input text.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

MAX_DEPTH = 256  # nesting of segments along one chain: far above any figure, far below Python's stack
_JOINT_NUMBER = re.compile(r"#\s*(\d{1,6})")
_BINDINGS = {
    "off": "off",
    "pfgs_off": "off",
    "overall": "overall",
    "pfgs_overall": "overall",
    "per_vertex": "per_vertex",
    "pfgs_per_vertex": "per_vertex",
    "per_prim": "per_prim",
    "pfgs_per_prim": "per_prim",
}
_INDEXING = {"indexed": True, "pfgs_indexed": True, "not_indexed": False, "nonindexed": False, "flat": False}


class TipsError(ValueError):
    """A malformed ``.tips`` file: ``file``, ``line`` (1-based) and ``message``."""

    def __init__(self, message: str, file: str = "<tips>", line: int = 0) -> None:
        self.message = message
        self.file = file
        self.line = line
        super().__init__(f"{file}:{line}: {message}")


@dataclass
class TipsAttribute:
    ambient: np.ndarray  # (3,)
    diffuse: np.ndarray  # (3,)
    specular: np.ndarray  # (3,)
    texture: str | None = None


@dataclass
class TipsGeometry:
    """A segment's surface in its segment frame (Jack cm), as triangles over a vertex table.

    7.1 files also keep their polygons (``polygons``/``polygon_attribute``, node indices); 7.3 files carry
    per-vertex colours (RGBA) and normals when their bindings give them."""

    attributes: list[TipsAttribute]
    vertices: np.ndarray  # (n, 3) float64
    triangles: np.ndarray  # (t, 3) int64
    triangle_attribute: np.ndarray  # (t,) int64
    vertex_colors: np.ndarray | None = None  # (n, 4)
    vertex_normals: np.ndarray | None = None  # (n, 3)
    polygons: list[np.ndarray] | None = None
    polygon_attribute: np.ndarray | None = None
    strips: bool = False  # read from the 7.3 alternate format


@dataclass
class TipsDof:
    kind: str  # "R" (radians) or "T" (cm)
    axis: np.ndarray  # (3,) unit, joint frame
    lower: float = -math.inf
    upper: float = math.inf


@dataclass
class TipsJoint:
    name: str
    pose_index: int | None  # place in the figure's joint list (pose-vector order), from "JOINT #k"
    matrix: np.ndarray  # site1 -> site2 displacement at the current DOF values
    reverse: bool  # walked site2 -> site1
    dofs: list[TipsDof]
    othersite: str  # "segment.site" of the far side
    othersite_inverse: np.ndarray
    segment: TipsSegment
    rootjoint: bool = False


@dataclass
class TipsSite:
    name: str
    matrix: np.ndarray  # location in its segment
    joints: list[TipsJoint] = field(default_factory=list)


@dataclass
class TipsSegment:
    name: str | None  # None for the root segment (the format does not name it)
    geometry: TipsGeometry | None
    sites: list[TipsSite] = field(default_factory=list)


@dataclass
class TipsFigure:
    name: str
    filename: str
    location: np.ndarray  # global transform of the root site
    root_inverse: np.ndarray  # inverse of the root site's location in its segment
    root: TipsSegment

    def walk(self) -> list[tuple[TipsJoint, TipsSite, TipsJoint | None]]:
        """Every joint in traversal (depth-first) order with the site it hangs from and its parent joint
        (``None``: the root segment)."""
        out: list[tuple[TipsJoint, TipsSite, TipsJoint | None]] = []
        stack: list[tuple[TipsJoint, TipsSite, TipsJoint | None]] = [
            (j, s, None) for s in self.root.sites for j in s.joints
        ]
        stack.reverse()
        while stack:
            joint, site, parent = stack.pop()
            out.append((joint, site, parent))
            stack.extend([(c, s, joint) for s in joint.segment.sites for c in s.joints][::-1])
        return out

    def pose_order(self) -> list[TipsJoint]:
        """Joints in pose-vector order (``JOINT #k``; traversal order for files without the numbers)."""
        joints = [j for j, _, _ in self.walk()]
        if all(j.pose_index is not None for j in joints):
            return sorted(joints, key=lambda j: j.pose_index or 0)
        return joints


@dataclass
class TipsFile:
    figures: list[TipsFigure]
    filename: str = "<tips>"


class _Lines:
    """A cursor over the file's lines; every read names what it expected when it fails."""

    def __init__(self, text: str, filename: str) -> None:
        self.lines = text.splitlines()
        self.i = 0
        self.file = filename

    def error(self, message: str, line: int | None = None) -> TipsError:
        return TipsError(message, self.file, self.i if line is None else line)

    def remaining(self) -> int:
        return len(self.lines) - self.i

    def line(self, what: str) -> str:
        if self.i >= len(self.lines):
            raise TipsError(f"unexpected end of file: expected {what}", self.file, len(self.lines) + 1)
        text = self.lines[self.i]
        self.i += 1
        return text

    def peek_word(self) -> str:
        if self.i >= len(self.lines):
            return ""
        parts = self.lines[self.i].split()
        return parts[0].lower() if parts else ""

    def comment(self, what: str = "a comment line") -> str:
        return self.line(what)

    def text(self, what: str) -> str:
        value = self.line(what).strip()
        if not value:
            raise self.error(f"expected {what}, found an empty line")
        return value

    def count(self, what: str, per_item: int = 1, limit: int | None = None) -> int:
        """A non-negative integer starting the line (the rest is its comment), bounded by what is left."""
        parts = self.line(what).split(None, 1)
        if not parts:
            raise self.error(f"expected {what}, found an empty line")
        try:
            n = int(parts[0])
        except ValueError:
            raise self.error(f"expected {what} (an integer), found {parts[0]!r}") from None
        bound = self.remaining() // per_item if limit is None else limit
        if n < 0 or n > bound:
            raise self.error(f"{what} {n} out of range 0..{bound}")
        return n

    def flag(self, what: str) -> bool:
        return bool(self.count(what, limit=1))

    def floats(self, n: int, what: str, finite: bool = True) -> np.ndarray:
        parts = self.line(what).split()
        if len(parts) != n:
            raise self.error(f"expected {what} ({n} numbers), found {len(parts)} fields")
        return self._numbers(parts, what, finite)

    def _numbers(self, parts: list[str], what: str, finite: bool) -> np.ndarray:
        try:
            values = np.array([float(p) for p in parts], dtype=np.float64)
        except ValueError:
            raise self.error(f"expected {what}: not a number in {' '.join(parts)!r}") from None
        if np.isnan(values).any() or (finite and not np.isfinite(values).all()):
            raise self.error(f"{what} must be finite")
        return values

    def number_stream(self, n: int, what: str) -> np.ndarray:
        """``n`` numbers over as many whole lines as they take (7.3 vertex, colour and normal lists)."""
        out = np.empty(n, dtype=np.float64)
        got = 0
        while got < n:
            parts = self.line(what).split()
            if got + len(parts) > n:
                raise self.error(f"{what}: {got + len(parts)} numbers where {n} were expected")
            out[got : got + len(parts)] = self._numbers(parts, what, True)
            got += len(parts)
        return out

    def matrix(self, what: str) -> np.ndarray:
        rows = [self.floats(4, f"{what} row {k + 1}") for k in range(4)]
        return np.array(rows).T  # row-vector layout in the file

    def index(self, what: str, size: int) -> int:
        parts = self.line(what).split()
        if len(parts) != 1:
            raise self.error(f"expected {what} (one integer), found {len(parts)} fields")
        try:
            k = int(parts[0])
        except ValueError:
            raise self.error(f"expected {what}, found {parts[0]!r}") from None
        if not 0 <= k < size:
            raise self.error(f"{what} {k} out of range 0..{size - 1}")
        return k


def _attributes(r: _Lines) -> list[TipsAttribute]:
    n = r.count("number of attributes", per_item=4)
    out = []
    for k in range(n):
        ambient = r.floats(3, f"attribute {k} ambient colour")
        diffuse = r.floats(3, f"attribute {k} diffuse colour")
        specular = r.floats(3, f"attribute {k} specular colour")
        texture = r.text(f"attribute {k} texture file") if r.flag("texture flag") else None
        out.append(TipsAttribute(ambient, diffuse, specular, texture))
    return out


def _polygons(r: _Lines, attributes: list[TipsAttribute]) -> TipsGeometry:
    nnodes = r.count("number of nodes")
    nodes = np.array([r.floats(3, f"node {k}") for k in range(nnodes)]).reshape(nnodes, 3)
    nfaces = r.count("number of faces", per_item=3)
    polygons: list[np.ndarray] = []
    attr = np.zeros(nfaces, dtype=np.int64)
    for f in range(nfaces):
        attr[f] = r.count(f"face {f} attribute index", limit=max(len(attributes) - 1, 0))
        if not attributes:
            raise r.error("a face needs an attribute, but the geometry has none")
        nv = r.count(f"face {f} vertex count", per_item=1)
        r.floats(3, f"face {f} colour")
        textured = attributes[attr[f]].texture is not None
        vertices = np.empty(nv, dtype=np.int64)
        for v in range(nv):
            vertices[v] = r.index(f"face {f} vertex {v} node index", nnodes)
            if textured:
                r.floats(2, f"face {f} vertex {v} texture coordinate")
        polygons.append(vertices)
    tris, tri_attr = _fan(polygons, attr)
    return TipsGeometry(attributes, nodes, tris, tri_attr, polygons=polygons, polygon_attribute=attr)


def _fan(polygons: list[np.ndarray], attr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangle fans of the polygons (convex, as psurf faces are), vectorised over all of them."""
    sizes = np.array([len(p) for p in polygons], dtype=np.int64)
    keep = sizes >= 3
    if not keep.any():
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    flat = np.concatenate([p for p, k in zip(polygons, keep, strict=True) if k])
    sizes = sizes[keep]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    ntri = sizes - 2
    owner = np.repeat(np.arange(len(sizes)), ntri)
    local = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    first = flat[starts[owner]]
    tris = np.stack([first, flat[starts[owner] + local + 1], flat[starts[owner] + local + 2]], axis=1)
    return tris, attr[keep][owner]


def _binding(r: _Lines, what: str) -> str:
    word = r.text(what).split()[0].lower()
    if word not in _BINDINGS:
        raise r.error(f"unknown {what} {word!r}")
    return _BINDINGS[word]


def _bound_values(
    r: _Lines, binding: str, width: int, nverts: int, lengths: np.ndarray, what: str
) -> np.ndarray | None:
    if binding == "off":
        return None
    count = {"overall": 1, "per_prim": len(lengths), "per_vertex": nverts}[binding]
    values = r.number_stream(count * width, what).reshape(count, width)
    if binding == "overall":
        return np.repeat(values, nverts, axis=0)
    if binding == "per_prim":
        return np.repeat(values, lengths, axis=0)
    return values


def _strip_triangles(lengths: np.ndarray) -> np.ndarray:
    """Triangles of consecutive triangle strips (alternate windings flipped so all face the same way)."""
    ntri = np.maximum(lengths - 2, 0)
    if ntri.sum() == 0:
        return np.zeros((0, 3), np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    owner = np.repeat(np.arange(len(lengths)), ntri)
    k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    a = starts[owner] + k
    odd = (k % 2).astype(bool)
    first = np.where(odd, a + 1, a)
    second = np.where(odd, a, a + 1)
    return np.stack([first, second, a + 2], axis=1)


def _geosets(r: _Lines, attributes: list[TipsAttribute]) -> TipsGeometry:
    verts, tris, tri_attr, colors, normals = [], [], [], [], []
    have_colors = have_normals = False
    base = 0
    while True:
        word = r.text("'geoset' or 'endgeosets'").split()[0].lower()
        if word == "endgeosets":
            break
        if word != "geoset":
            raise r.error(f"expected 'geoset' or 'endgeosets', found {word!r}")
        attr = r.count("geoset attribute index", limit=max(len(attributes) - 1, 0))
        if not attributes:
            raise r.error("a geoset needs an attribute, but the geometry has none")
        nstrips = r.count("number of triangle strips")
        lengths = r.number_stream(nstrips, "strip lengths") if nstrips else np.zeros(0)
        if (lengths < 0).any() or (lengths != np.round(lengths)).any():
            raise r.error("strip lengths must be non-negative integers")
        lengths = lengths.astype(np.int64)
        nverts = int(lengths.sum())
        if nverts > 3 * r.remaining() + 3:
            raise r.error(f"{nverts} strip vertices cannot fit in the rest of the file")
        mode = r.text("indexing mode").lower().replace(" ", "_")
        if mode not in _INDEXING:
            raise r.error(f"unknown indexing mode {mode!r}")
        if _INDEXING[mode]:
            data = r.number_stream(4 * nverts, "indexed vertices").reshape(nverts, 4)
            idx = data[:, 0]
            if (idx < 0).any() or (idx != np.round(idx)).any():
                raise r.error("vertex indices must be non-negative integers")
            xyz = data[:, 1:]
        else:
            xyz = r.number_stream(3 * nverts, "vertices").reshape(nverts, 3)
        c = _bound_values(r, _binding(r, "color binding"), 4, nverts, lengths, "colours")
        n = _bound_values(r, _binding(r, "normal binding"), 3, nverts, lengths, "normals")
        texture = _binding(r, "texture binding")
        if texture != "off":
            _bound_values(r, texture, 2, nverts, lengths, "texture coordinates")
        if c is None:
            c = np.tile(np.append(attributes[attr].diffuse, 1.0), (nverts, 1))
        else:
            have_colors = True
        if n is None:
            n = np.zeros((nverts, 3))
        else:
            have_normals = True
        t = _strip_triangles(lengths) + base
        verts.append(xyz)
        colors.append(c)
        normals.append(n)
        tris.append(t)
        tri_attr.append(np.full(len(t), attr, np.int64))
        base += nverts
    return TipsGeometry(
        attributes,
        np.concatenate(verts) if verts else np.zeros((0, 3)),
        np.concatenate(tris) if tris else np.zeros((0, 3), np.int64),
        np.concatenate(tri_attr) if tri_attr else np.zeros(0, np.int64),
        vertex_colors=np.concatenate(colors) if have_colors else None,
        vertex_normals=np.concatenate(normals) if have_normals else None,
        strips=True,
    )


def _geometry(r: _Lines) -> TipsGeometry:
    attributes = _attributes(r)
    if r.peek_word() == "geoset":
        return _geosets(r, attributes)
    return _polygons(r, attributes)


def _dof(r: _Lines, what: str) -> TipsDof:
    parts = r.line(what).split()
    if len(parts) < 6 or parts[0] not in ("R", "T"):
        raise r.error(f"expected {what}: 'R|T ax ay az lower upper', found {' '.join(parts[:6])!r}")
    axis = r._numbers(parts[1:4], f"{what} axis", True)
    limits = r._numbers(parts[4:6], f"{what} limits", False)
    norm = float(np.linalg.norm(axis))
    if norm < 1e-9:
        raise r.error(f"{what}: zero axis")
    return TipsDof(parts[0], axis / norm, float(limits[0]), float(limits[1]))


def _segment(r: _Lines, name: str | None, depth: int) -> TipsSegment:
    if depth > MAX_DEPTH:
        raise r.error(f"segments nested deeper than {MAX_DEPTH}")
    geometry = _geometry(r) if r.flag("psurf flag") else None
    segment = TipsSegment(name, geometry)
    nsites = r.count("number of sites", per_item=7)
    for _ in range(nsites):
        njoints = r.count("number of joints", per_item=20)
        r.comment()
        site = TipsSite(r.text("site name"), np.eye(4))
        r.comment()
        site.matrix = r.matrix(f"site {site.name} matrix")
        for _ in range(njoints):
            site.joints.append(_joint(r, depth))
        segment.sites.append(site)
    return segment


def _joint(r: _Lines, depth: int) -> TipsJoint:
    rootjoint = r.flag("rootjoint flag")
    number = _JOINT_NUMBER.search(r.comment())
    matrix = r.matrix("joint matrix")
    reverse = r.flag("reverse joint flag")
    ndofs = r.count("number of DOFs", limit=16)
    dofs = [_dof(r, f"DOF {k}") for k in range(ndofs)]
    r.comment()
    name = r.text("joint name")
    r.comment()
    othersite = r.text("other site name")
    r.comment()
    inverse = r.matrix("other site inverse matrix")
    segment_name = othersite.rpartition(".")[0] or None
    child = _segment(r, segment_name, depth + 1)
    pose_index = int(number.group(1)) if number else None
    return TipsJoint(name, pose_index, matrix, reverse, dofs, othersite, inverse, child, rootjoint)


def parse_tips(text: str, filename: str = "<tips>") -> TipsFile:
    """Parse ``.tips`` text; :class:`TipsError` on any fault."""
    r = _Lines(text, filename)
    try:
        nfigures = r.count("number of figures", per_item=14)
        figures = []
        for _ in range(nfigures):
            r.comment()
            name = r.text("figure name")
            r.comment()
            fig_file = r.text("figure file name")
            r.comment()
            location = r.matrix("global position matrix")
            r.comment()
            root_inverse = r.matrix("root site inverse matrix")
            figure = TipsFigure(name, fig_file, location, root_inverse, _segment(r, None, 0))
            _check_pose_indices(r, figure)
            figures.append(figure)
    except RecursionError:  # pragma: no cover - MAX_DEPTH keeps well below the limit
        raise r.error("segments nested too deeply") from None
    return TipsFile(figures, filename)


def _check_pose_indices(r: _Lines, figure: TipsFigure) -> None:
    numbers = [j.pose_index for j, _, _ in figure.walk()]
    given = [n for n in numbers if n is not None]
    if given and (len(given) != len(numbers) or sorted(given) != list(range(len(numbers)))):
        raise r.error(f"figure {figure.name}: 'JOINT #k' numbers are not 0..{len(numbers) - 1}")


def load_tips(path: str | os.PathLike[str]) -> TipsFile:
    """``LoadTIPSFile``: read and parse a ``.tips`` file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise TipsError(f"not UTF-8 text: {exc.reason}", str(p), 0) from None
    except OSError as exc:
        raise TipsError(f"cannot read: {exc.strerror or exc}", str(p), 0) from None
    return parse_tips(text, str(p))
