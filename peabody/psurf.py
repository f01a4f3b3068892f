"""Psurf text files (``.pss``, seed 000 chapter 8): read, write, and convert to/from trimesh.

Syntax (8.2), one or more concatenated *csurfs* (8.3), each::

    0 0 0, 0 1 0, 1 1 0      node triplets, optional commas; nodes are numbered from 1 in each csurf
    ;                        end of nodes
    1 2  2 3                 edge pairs (optional; usually empty)
    ;                        end of edges
    1 2 3 [attribute 1];     faces: 1-based node indices, counter-clockwise seen from outside;
    1 3 4;                   "[attribute n]" sets the current attribute index (default 0; it carries over)
    ;                        an empty face ends the csurf

Comments are ``{ ... }`` anywhere.  Face indices are local to their csurf and are resolved to the global
node table on reading; :attr:`Psurf.csurfs` keeps the per-csurf counts so writing reproduces the split.

Our one extension: before a csurf's nodes, ``[attribute 1 name "olive" diffuse (0.3, 0.4, 0.2)
ambient (...) specular (...)]`` defines entry 1 of the attribute table (``Psurf.attributes[1]``, a dict:
strings, numbers and number tuples).  Jack kept these colours in its attribute library instead.

Errors are :class:`PsurfError` (a :class:`~peabody.language.PeabodyError`, so a ``ValueError``)
carrying file, line and column.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from peabody.language import PeabodyError
from peabody.model import Psurf

if TYPE_CHECKING:
    import trimesh


class PsurfError(PeabodyError):
    """A located error in a ``.pss`` file."""


_TOKEN = re.compile(
    r"(?P<ws>\s+)"
    r"|(?P<comment>\{[^}]*\})"
    r"|(?P<num>[-+]?(?>(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?))"
    r"|(?P<punct>[;,\[\]()])"
    r"|(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
    r'|(?P<str>"[^"\n]*")'
    r"|(?P<bad>.)",
    re.S,
)
_INT = re.compile(r"\+?\d{1,9}")
MAX_ITEMS = 10_000_000


class _Reader:
    def __init__(self, text: str, filename: str) -> None:
        self.text = text
        self.file = filename
        toks: list[tuple[str, str, int]] = []
        for m in _TOKEN.finditer(text):
            kind = m.lastgroup
            if kind in {"ws", "comment"}:
                continue
            if kind == "bad":
                ch = m.group()
                msg = "unterminated comment" if ch == "{" else "unterminated string" if ch == '"' else None
                raise self.error(m.start(), msg or f"unexpected character {ch!r}")
            assert kind is not None
            toks.append((kind if kind != "punct" else m.group(), m.group(), m.start()))
        self.toks = toks
        self.i = 0

    def error(self, offset: int, message: str) -> PsurfError:
        line = self.text.count("\n", 0, offset) + 1
        col = offset - (self.text.rfind("\n", 0, offset) + 1) + 1
        return PsurfError(self.file, line, col, message)

    def peek(self) -> str:
        return self.toks[self.i][0] if self.i < len(self.toks) else "eof"

    def offset(self) -> int:
        return self.toks[self.i][2] if self.i < len(self.toks) else len(self.text)

    def take(self, kind: str, what: str) -> str:
        if self.peek() != kind:
            found = "end of file" if self.peek() == "eof" else repr(self.toks[self.i][1])
            raise self.error(self.offset(), f"expected {what}, found {found}")
        tok = self.toks[self.i]
        self.i += 1
        return tok[1]

    def index(self, what: str) -> int:
        off = self.offset()
        text = self.take("num", what)
        if not _INT.fullmatch(text):
            raise self.error(off, f"expected an integer {what}, found {text!r}")
        return int(text)


def _skip_commas_until(r: _Reader, stop: tuple[str, ...]) -> bool:
    """Skip separating commas; True while the next token is not one of ``stop``."""
    while r.peek() == ",":
        r.i += 1
    return r.peek() not in stop


def _read_nodes(r: _Reader, nodes: list[float]) -> int:
    """A component's node coordinates up to ';' (appended to ``nodes``); returns its node count."""
    start = len(nodes)
    while _skip_commas_until(r, (";",)):
        off = r.offset()
        text = r.take("num", "a node coordinate or ';'")
        v = float(text)
        if not np.isfinite(v):
            raise r.error(off, f"node coordinate {text!r} is not finite")
        nodes.append(v)
        if len(nodes) > MAX_ITEMS:
            raise r.error(off, "too many nodes")
    if (len(nodes) - start) % 3:
        raise r.error(r.offset(), f"node coordinates come in triplets; found {len(nodes) - start} numbers")
    r.i += 1
    return (len(nodes) - start) // 3


def _node_index(r: _Reader, what: str, base: int, count: int) -> int:
    """A 1-based node index of this component (``what``: "edge" or "face") as a 0-based index of the psurf."""
    off = r.offset()
    k = r.index(f"node index in {'an' if what == 'edge' else 'a'} {what}")
    if not 1 <= k <= count:
        raise r.error(off, f"{what} node {k} is outside 1..{count}")
    return base + k - 1


def _read_edges(r: _Reader, edges: list[int], base: int, count: int) -> None:
    """A component's edges (node index pairs) up to ';', appended to ``edges``."""
    while _skip_commas_until(r, (";",)):
        edges.append(_node_index(r, "edge", base, count))
    if (len(edges) // 2 * 2) != len(edges):
        raise r.error(r.offset(), "edge node indices come in pairs")
    r.i += 1


def _face_attribute(r: _Reader, has_verts: bool) -> int:
    """``[attribute n]`` after a face's vertices (just before its ';'): the attribute of this face and the
    faces after it."""
    off = r.offset()
    r.i += 1
    word = r.take("name", "'attribute'")
    if word != "attribute":
        raise r.error(off, f"expected [attribute n], found {word!r}")
    attribute = r.index("attribute index")
    r.take("]", "']'")
    if r.peek() != ";":
        raise r.error(r.offset(), "expected ';' after the face's [attribute n]")
    if not has_verts:
        raise r.error(off, "an attribute needs a face")
    return attribute


def _read_faces(
    r: _Reader, faces: list[np.ndarray], face_attr: list[int], base: int, count: int, attribute: int
) -> int:
    """A component's faces, each ending in ';', up to an empty face (';') or the end of the text; returns
    the attribute in force after them."""
    while True:
        verts: list[int] = []
        while _skip_commas_until(r, (";", "eof")):
            if r.peek() == "[":
                attribute = _face_attribute(r, bool(verts))
            else:
                verts.append(_node_index(r, "face", base, count))
        if r.peek() == "eof":
            if verts:
                raise r.error(r.offset(), "expected ';' to end the face")
            return attribute
        off = r.offset()
        r.i += 1
        if not verts:
            return attribute
        if len(verts) < 3:
            raise r.error(off, f"a face needs at least 3 vertices, found {len(verts)}")
        faces.append(np.array(verts, dtype=np.int64))
        face_attr.append(attribute)
        if len(faces) > MAX_ITEMS:
            raise r.error(off, "too many faces")


def parse_psurf(text: str, filename: str = "<string>") -> Psurf:
    """Parse ``.pss`` text (see the module docstring) into a :class:`Psurf` with 0-based indices."""
    r = _Reader(text, filename)
    nodes: list[float] = []
    edges: list[int] = []
    faces: list[np.ndarray] = []
    face_attr: list[int] = []
    attributes: list[dict] = []
    csurfs: list[tuple[int, int, int]] = []
    attribute = 0
    while r.peek() != "eof":  # one component surface: [attribute definitions] nodes; edges; faces;
        base = len(nodes) // 3
        n_edges0, n_faces0 = len(edges) // 2, len(faces)
        while r.peek() == "[":  # attribute definitions (our extension)
            _attribute_definition(r, attributes)
        count = _read_nodes(r, nodes)
        _read_edges(r, edges, base, count)
        attribute = _read_faces(r, faces, face_attr, base, count, attribute)
        csurfs.append((count, len(edges) // 2 - n_edges0, len(faces) - n_faces0))
    if not csurfs:
        raise r.error(0, "empty psurf")
    return Psurf(
        nodes=np.array(nodes, dtype=np.float64).reshape(-1, 3),
        faces=faces,
        face_attributes=np.array(face_attr, dtype=np.int64),
        attributes=attributes,
        filename=filename,
        edges=np.array(edges, dtype=np.int64).reshape(-1, 2) if edges else None,
        csurfs=csurfs if len(csurfs) > 1 else [],
    )


def _attribute_definition(r: _Reader, attributes: list[dict]) -> None:
    off = r.offset()
    r.take("[", "'['")
    word = r.take("name", "'attribute'")
    if word != "attribute":
        raise r.error(off, f"expected [attribute n ...], found {word!r}")
    n_off = r.offset()
    n = r.index("attribute index")
    if n > 4096:
        raise r.error(n_off, "attribute index too large")
    entry: dict = {}
    while r.peek() != "]":
        key = r.take("name", "an attribute key or ']'")
        kind = r.peek()
        if kind == "str":
            entry[key] = r.take("str", "a string")[1:-1]
        elif kind == "num":
            entry[key] = float(r.take("num", "a number"))
        elif kind == "(":
            r.i += 1
            vals: list[float] = []
            while r.peek() != ")":
                if r.peek() == ",":
                    r.i += 1
                    continue
                vals.append(float(r.take("num", "a number or ')'")))
            r.i += 1
            entry[key] = tuple(vals)
        else:
            r.take("str", f"a value for {key!r}")
    r.i += 1
    while len(attributes) <= n:
        attributes.append({})
    attributes[n] = entry


def read_psurf(path: str | os.PathLike[str]) -> Psurf:
    """``readpsurf`` for text files; ``Psurf.filename`` is the resolved path."""
    p = Path(path).resolve()
    data = p.read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise PsurfError(str(p), line, col, "not UTF-8 text") from None
    return parse_psurf(text, str(p))


# --- writing ------------------------------------------------------------------------------------------------


def _num(x: float) -> str:
    s = f"{x:.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _attr_value(v: object) -> str:
    if isinstance(v, str):
        return '"' + v.replace('"', "'") + '"'
    if isinstance(v, int | float | np.floating | np.integer):
        return _num(float(v))
    if isinstance(v, tuple | list | np.ndarray):
        return "(" + ", ".join(_num(float(x)) for x in v) + ")"
    return '"' + str(v).replace('"', "'") + '"'


def format_psurf(psurf: Psurf, comment: str | None = None) -> str:
    """``fwritepsurf``: the ``.pss`` text, one block per csurf, indices 1-based."""
    out: list[str] = []
    if comment:
        out.append("{ " + comment.replace("}", ")") + " }\n")
    nodes = np.asarray(psurf.nodes, dtype=np.float64).reshape(-1, 3)
    attrs = psurf.face_attributes
    csurfs = psurf.csurfs or [(len(nodes), 0 if psurf.edges is None else len(psurf.edges), len(psurf.faces))]
    node0 = edge0 = face0 = 0
    current = 0
    for ci, (nn, ne, nf) in enumerate(csurfs):
        if ci == 0:
            for i, entry in enumerate(psurf.attributes):
                if entry:
                    pairs = " ".join(f"{k} {_attr_value(v)}" for k, v in entry.items() if k.isidentifier())
                    out.append(f"[attribute {i} {pairs}]\n".replace(" ]", "]"))
        out.extend(f"{_num(x)} {_num(y)} {_num(z)}\n" for x, y, z in nodes[node0 : node0 + nn])
        out.append("; {end of nodes}\n")
        if psurf.edges is not None and ne:
            out.extend(f"{a - node0 + 1} {b - node0 + 1}\n" for a, b in psurf.edges[edge0 : edge0 + ne])
        out.append("; {end of edges}\n")
        for fi in range(face0, face0 + nf):
            verts = np.asarray(psurf.faces[fi])
            if verts.size and (verts.min() < node0 or verts.max() >= node0 + nn):
                raise ValueError(f"face {fi} uses nodes outside its csurf {ci}")
            line = " ".join(str(int(v) - node0 + 1) for v in verts)
            a = 0 if attrs is None else int(attrs[fi])
            if a != current:
                line += f" [attribute {a}]"
                current = a
            out.append(line + ";\n")
        out.append(";\n")
        node0, edge0, face0 = node0 + nn, edge0 + ne, face0 + nf
    return "".join(out)


def write_psurf(psurf: Psurf, path: str | os.PathLike[str], comment: str | None = None) -> None:
    Path(path).write_text(format_psurf(psurf, comment), encoding="utf-8")


# --- geometry helpers ---------------------------------------------------------------------------------------


def _flat_faces(psurf: Psurf) -> tuple[np.ndarray, np.ndarray]:
    """All face vertices in one array, and each face's start offset (plus a final end)."""
    sizes = np.fromiter((len(f) for f in psurf.faces), dtype=np.int64, count=len(psurf.faces))
    flat = np.concatenate(psurf.faces).astype(np.int64) if psurf.faces else np.zeros(0, dtype=np.int64)
    starts = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=starts[1:])
    return flat, starts


def psurf_edges(psurf: Psurf) -> np.ndarray:
    """``(e, 2)`` unique undirected edges implied by the faces (``psurfedges``), sorted."""
    flat, starts = _flat_faces(psurf)
    if flat.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    nxt = np.roll(flat, -1)
    ends = starts[1:] - 1
    nxt[ends] = flat[starts[:-1]]  # close each polygon
    pairs = np.sort(np.stack([flat, nxt], axis=1), axis=1)
    return np.unique(pairs, axis=0)


def transform_psurf(psurf: Psurf, m: np.ndarray) -> Psurf:
    """``transformpsurf``: a copy with nodes mapped by the 4x4 ``m`` (topology shared)."""
    m = np.asarray(m, dtype=np.float64)
    nodes = psurf.nodes @ m[:3, :3].T + m[:3, 3]
    return Psurf(
        nodes=nodes,
        faces=psurf.faces,
        face_attributes=psurf.face_attributes,
        attributes=psurf.attributes,
        filename=psurf.filename,
        edges=psurf.edges,
        csurfs=list(psurf.csurfs),
    )


def fan_triangles(psurf: Psurf) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangulation: ``(t, 3)`` node indices and, per triangle, the polygon it came from."""
    flat, starts = _flat_faces(psurf)
    sizes = np.diff(starts)
    counts = np.maximum(sizes - 2, 0)
    face_of = np.repeat(np.arange(len(sizes)), counts)
    first = starts[:-1][face_of]
    k = np.arange(len(face_of)) - np.repeat(np.cumsum(counts) - counts, counts)
    tris = (
        np.stack([flat[first], flat[first + k + 1], flat[first + k + 2]], axis=1)
        if len(face_of)
        else (np.zeros((0, 3), dtype=np.int64))
    )
    return tris, face_of


def psurf_to_trimesh(psurf: Psurf) -> trimesh.Trimesh:
    """A triangle mesh (fan-triangulated polygons); ``metadata["psurf_face"]`` maps triangles to polygons
    and face colours come from the attributes' ``diffuse`` entries when present."""
    import trimesh

    tris, face_of = fan_triangles(psurf)
    mesh = trimesh.Trimesh(vertices=np.asarray(psurf.nodes), faces=tris, process=False)
    mesh.metadata["psurf_face"] = face_of
    if psurf.attributes and psurf.face_attributes is not None and len(tris):
        colours = np.full((len(psurf.attributes), 4), 200, dtype=np.uint8)
        for i, entry in enumerate(psurf.attributes):
            diffuse = entry.get("diffuse") if entry else None
            if diffuse is not None and len(diffuse) >= 3:
                colours[i, :3] = np.clip(np.asarray(diffuse[:3], dtype=np.float64) * 255.0, 0, 255)
        attr = np.clip(np.asarray(psurf.face_attributes)[face_of], 0, len(colours) - 1)
        visual = mesh.visual
        assert isinstance(visual, trimesh.visual.ColorVisuals)  # a new mesh without texture
        visual.face_colors = colours[attr]
    return mesh


def psurf_from_trimesh(
    mesh: trimesh.Trimesh,
    attributes: list[dict] | None = None,
    face_attributes: np.ndarray | None = None,
    filename: str | None = None,
) -> Psurf:
    """A psurf of the mesh's triangles (nodes in cm, the mesh's units assumed)."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    fa = np.zeros(len(faces), dtype=np.int64) if face_attributes is None else np.asarray(face_attributes)
    return Psurf(
        nodes=np.asarray(mesh.vertices, dtype=np.float64).copy(),
        faces=list(faces),
        face_attributes=fa.astype(np.int64),
        attributes=list(attributes or []),
        filename=filename,
    )


def psurf_bounds(psurf: Psurf) -> tuple[np.ndarray, np.ndarray]:
    """``PSURF_DIMENSIONS``: the bounding box ``(min, max)``."""
    nodes = np.asarray(psurf.nodes).reshape(-1, 3)
    if len(nodes) == 0:
        return np.zeros(3), np.zeros(3)
    return nodes.min(axis=0), nodes.max(axis=0)


def psurfs_equal(a: Psurf, b: Psurf, atol: float = 1e-5) -> bool:
    """Same geometry, topology and attributes (node coordinates within ``atol``)."""
    if a.nodes.shape != b.nodes.shape or len(a.faces) != len(b.faces):
        return False
    if not np.allclose(a.nodes, b.nodes, atol=atol, rtol=0):
        return False
    if any(len(x) != len(y) or not np.array_equal(x, y) for x, y in zip(a.faces, b.faces, strict=True)):
        return False
    fa = np.zeros(len(a.faces)) if a.face_attributes is None else a.face_attributes
    fb = np.zeros(len(b.faces)) if b.face_attributes is None else b.face_attributes
    if not np.array_equal(fa, fb):
        return False
    ea = np.zeros((0, 2)) if a.edges is None else a.edges
    eb = np.zeros((0, 2)) if b.edges is None else b.edges
    if ea.shape != eb.shape or not np.array_equal(ea, eb):
        return False
    if (a.csurfs or None) != (b.csurfs or None):
        return False
    return _attrs_equal(a.attributes, b.attributes, atol)


def _attrs_equal(a: list[dict], b: list[dict], atol: float) -> bool:
    def norm(entries: list[dict]) -> list[dict]:
        out = list(entries)
        while out and not out[-1]:
            out.pop()
        return out

    a, b = norm(a), norm(b)
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if set(x) != set(y):
            return False
        for k in x:
            vx, vy = x[k], y[k]
            if isinstance(vx, str) or isinstance(vy, str):
                if vx != vy:
                    return False
            elif not np.allclose(np.asarray(vx, dtype=float), np.asarray(vy, dtype=float), atol=atol):
                return False
    return True
