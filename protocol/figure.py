"""The FIGURE body (docs/PROTOCOL.md §7.2): a soldier's skeleton on the wire, so a client needs no files.

One FIGURE answers a REQUEST_FIGURE for an update table: per figure entry of the table (``soldier``,
``rifle``) its segments parents first, each placed under its parent by a constant ``pre`` transform, the
DOF product of one joint entry and a constant ``post`` transform; its joints' DOF axes and limits; its sites;
optionally every segment's surface as a triangle list. Everything is in the wire's units and axes (Performer:
metres, +Z up, the figure facing +Y at zero angles), so a client evaluates

    G(root segment) = F · pre          (F: the figure entry's position and quaternion, in the soldier frame)
    G(segment)      = G(parent) · pre · D(q) · post
    site            = G(segment) · location

with ``D(q)`` the joint's DOF matrices left to right (``reverse``: right to left with negated values).
:class:`WireFigure` is that client, in numpy: the tests hold it to Peabody's FK.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypeGuard

import numpy as np

from peabody.fk import FigureKinematics, dof_transforms
from peabody.model import Figure
from protocol import coords
from protocol.errors import ErrorCode, WireError
from protocol.update_table import JointEntry, UpdateTable

MAX_FIGURES = 16
MAX_SEGMENTS = 1024
MAX_SITES = 8192
MAX_MESH_VALUES = 1 << 22  # floats or ints in one segment's vertex or triangle list
FACING = (0.0, 1.0, 0.0)  # a figure at zero angles and identity placement faces +Y of its root frame
UP = (0.0, 0.0, 1.0)


def _rows(m: np.ndarray) -> list[float]:
    """A rigid 4x4 as 12 numbers: the top three rows, row-major."""
    return [float(x) for x in np.asarray(m, np.float64)[:3, :].ravel()]


def _perf(m: np.ndarray) -> np.ndarray:
    return coords.transforms_jack_to_performer(np.asarray(m, np.float64))


def _limit(x: float, scale: float) -> float | None:
    return float(x) * scale if math.isfinite(x) else None


def _joint_entries(table: UpdateTable, figures: Sequence[Figure]) -> list[list[int]]:
    """Per figure, per joint (file order, DOF-less joints -1): its entry index in ``table``."""
    joint_entries = [i for i, e in enumerate(table.entries) if isinstance(e, JointEntry)]
    out: list[list[int]] = []
    k = 0
    for fig in figures:
        row = []
        for name, joint in fig.joints.items():
            if not joint.dofs:
                row.append(-1)
                continue
            if k >= len(joint_entries):
                raise ValueError(f"table {table.table_id} has fewer joint entries than {fig.name}'s joints")
            entry = table.entries[joint_entries[k]]
            if not entry.name.endswith(name) or entry.ndofs != joint.ndofs:
                raise ValueError(f"table entry {entry.name!r} does not match joint {fig.name}.{name}")
            row.append(joint_entries[k])
            k += 1
        out.append(row)
    return out


def figure_to_wire(
    table: UpdateTable, figures: Sequence[Figure], names: Sequence[str], *, meshes: bool = False
) -> dict[str, Any]:
    """The FIGURE body for ``table``: ``figures`` are the table's figures in figure-entry order, ``names``
    their entry names. Pack it with ``use_single_float=True`` (f32 is 0.1 µm at 10 m)."""
    entries = _joint_entries(table, figures)
    return {
        "table": table.table_id,
        "figures": [
            _figure_body(fig, name, row, meshes)
            for fig, name, row in zip(figures, names, entries, strict=True)
        ],
    }


def _figure_body(fig: Figure, name: str, entry_of: list[int], meshes: bool) -> dict[str, Any]:
    kin = FigureKinematics(fig)
    seg_rows: list[list[Any]] = [
        [kin.segment_names[kin.root_segment], -1, -1, False, _rows(_perf(kin.root_inverse)), _rows(np.eye(4))]
    ]
    order = [kin.root_segment]
    joint_index = {n: i for i, n in enumerate(fig.joints)}
    for via, parent, child, forward, pre, post in kin.tree_steps():
        order.append(child)
        entry = entry_of[joint_index[via]]
        seg_rows.append(
            [
                kin.segment_names[child],
                order.index(parent),
                entry,
                not forward,
                _rows(_perf(pre)),
                _rows(_perf(post)),
            ]
        )
    row_of = {seg: i for i, seg in enumerate(order)}
    joints = []
    for (jname, joint), entry in zip(fig.joints.items(), entry_of, strict=True):
        if entry < 0:
            continue
        dofs = []
        for d in joint.dofs:
            scale = 1.0 if d.kind == "R" else 1.0 / coords.CM_PER_M
            axis = coords.directions_jack_to_performer(d.axis)
            dofs.append([d.kind, *map(float, axis), _limit(d.lower, scale), _limit(d.upper, scale)])
        joints.append([entry, jname, dofs])
    sites = [
        [
            f"{s.segment.name}.{s.name}",
            row_of[kin.segment_names.index(s.segment.name)],
            _rows(_perf(s.location)),
        ]
        for s in fig.sites()
        if s.segment is not None
    ]
    body: dict[str, Any] = {
        "name": name,
        "file": fig.filename or "",
        "facing": list(FACING),
        "up": list(UP),
        "segments": seg_rows,
        "joints": joints,
        "sites": sites,
    }
    if meshes:
        body["meshes"] = _meshes(fig, [kin.segment_names[s] for s in order])
    return body


def _meshes(fig: Figure, segment_rows: list[str]) -> list[list[Any]]:
    """Per segment with a surface: ``[segment row, vertices (x y z ...), triangles (i j k ...)]``, polygons
    fanned into triangles, vertices in the segment's frame in metres (any psurf transform already applied)."""
    out: list[list[Any]] = []
    for row, name in enumerate(segment_rows):
        seg = fig.segments[name]
        if seg.psurf is None or not len(seg.psurf.nodes):
            continue
        verts = coords.points_jack_to_performer(np.asarray(seg.psurf.nodes, np.float64))
        tris = [[int(f[0]), int(f[i]), int(f[i + 1])] for f in seg.psurf.faces for i in range(1, len(f) - 1)]
        out.append([row, [float(x) for x in verts.ravel()], [i for t in tris for i in t]])
    return out


# -- decoding: a client's view ------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class WireFigure:
    """One figure of a FIGURE message, as a client holds it (numpy arrays, read-only)."""

    name: str
    file: str
    segment_names: tuple[str, ...]
    parent: np.ndarray  # (S,) row of the parent segment, -1 for row 0 (the root segment)
    entry: np.ndarray  # (S,) the joint entry placing the segment, -1 for none
    reverse: np.ndarray  # (S,) bool
    pre: np.ndarray  # (S, 4, 4)
    post: np.ndarray  # (S, 4, 4)
    joints: dict[
        int, tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    ]  # entry -> name, rot, axes, lo, hi
    site_names: tuple[str, ...]
    site_segment: np.ndarray  # (N,)
    site_location: np.ndarray  # (N, 4, 4)
    meshes: dict[int, tuple[np.ndarray, np.ndarray]]  # segment row -> vertices (V, 3), triangles (T, 3)

    def segment_globals(self, table: UpdateTable, dofs: np.ndarray, placement: np.ndarray) -> np.ndarray:
        """``(S, 4, 4)``: every segment in the soldier frame for one soldier's decoded ``dofs`` (table order,
        radians/metres) and this figure's ``placement`` (4x4 from its figure entry)."""
        start = dof_starts(table)
        g = np.empty((len(self.segment_names), 4, 4))
        for s in range(len(self.segment_names)):
            parent = placement if self.parent[s] < 0 else g[self.parent[s]]
            m = parent @ self.pre[s]
            e = int(self.entry[s])
            if e >= 0:
                _, rot, axes, _, _ = self.joints[e]
                q = np.asarray(dofs[start[e] : start[e] + len(rot)], np.float64)
                mats = dof_transforms(axes, rot, -q if self.reverse[s] else q)
                for d in mats[::-1] if self.reverse[s] else mats:
                    m = m @ d
            g[s] = m @ self.post[s]
        return g

    def site_globals(self, table: UpdateTable, dofs: np.ndarray, placement: np.ndarray) -> np.ndarray:
        """``(N, 4, 4)``: every site in the soldier frame (see :meth:`segment_globals`)."""
        g = self.segment_globals(table, dofs, placement)
        return g[self.site_segment] @ self.site_location


def dof_starts(table: UpdateTable) -> dict[int, int]:
    """Joint entry index -> its first column in a table-order DOF vector."""
    out, k = {}, 0
    for i, e in enumerate(table.entries):
        if isinstance(e, JointEntry):
            out[i] = k
            k += e.ndofs
    return out


def _schema(msg: str, where: str = "") -> WireError:
    return WireError(ErrorCode.SCHEMA, msg, f"FIGURE {where}".strip())


def _bad(msg: str, where: str = "") -> WireError:
    return WireError(ErrorCode.BAD_VALUE, msg, f"FIGURE {where}".strip())


def _is_int(v: object) -> TypeGuard[int]:
    return isinstance(v, int) and not isinstance(v, bool)


def _num(v: object, where: str, *, nullable: bool = False) -> float:
    if v is None and nullable:
        return math.nan
    if not (isinstance(v, int | float) and not isinstance(v, bool)):
        raise _schema("expected a number" + (" or nil" if nullable else ""), where)
    if not math.isfinite(v):
        raise _bad(f"{v} is not finite", where)
    return float(v)


def _matrix(v: object, where: str) -> np.ndarray:
    if not (isinstance(v, list) and len(v) == 12):
        raise _schema("a transform is 12 numbers", where)
    m = np.eye(4)
    m[:3, :] = np.array([_num(x, where) for x in v]).reshape(3, 4)
    r = m[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) < 0:
        raise _bad("transform is not a rotation and a translation", where)
    return m


def _list(v: object, where: str, hi: int, lo: int = 0) -> list[Any]:
    if not isinstance(v, list):
        raise _schema("expected an array", where)
    if not lo <= len(v) <= hi:
        raise _bad(f"{len(v)} items not in {lo}..{hi}", where)
    return v


def _str(v: object, where: str) -> str:
    if not isinstance(v, str):
        raise _schema("expected a string", where)
    return v


def figure_from_wire(raw: Any) -> tuple[int, tuple[WireFigure, ...]]:
    """Parse and check a FIGURE body (:class:`WireError` SCHEMA/BAD_VALUE on any fault)."""
    if not isinstance(raw, dict):
        raise _schema("body is not a map")
    table = raw.get("table")
    if not _is_int(table) or not 0 <= table <= 0xFFFF:
        raise _schema("'table' must be an int 0..65535")
    figs = _list(raw.get("figures"), "figures", MAX_FIGURES, 1)
    return int(table), tuple(_figure(f, f"figure {i}") for i, f in enumerate(figs))


def _figure(f: object, where: str) -> WireFigure:
    if not isinstance(f, dict):
        raise _schema("figure is not a map", where)
    for key in ("facing", "up"):
        v = _list(f.get(key), f"{where} {key}", 3, 3)
        [_num(x, f"{where} {key}") for x in v]
    segs = _list(f.get("segments"), f"{where} segments", MAX_SEGMENTS, 1)
    names, parent, entry, reverse, pre, post = [], [], [], [], [], []
    for s, row in enumerate(segs):
        w = f"{where} segment {s}"
        if not (isinstance(row, list) and len(row) == 6):
            raise _schema("segment must be [name, parent, entry, reverse, pre, post]", w)
        if not (_is_int(row[1]) and _is_int(row[2]) and isinstance(row[3], bool)):
            raise _schema("parent and entry must be ints, reverse a bool", w)
        if not (row[1] == -1 if s == 0 else 0 <= row[1] < s) or not -1 <= row[2] <= 1023:
            raise _bad("parent must come first (-1 for segment 0) and entry be -1..1023", w)
        names.append(_str(row[0], w))
        parent.append(row[1])
        entry.append(row[2])
        reverse.append(row[3])
        pre.append(_matrix(row[4], w))
        post.append(_matrix(row[5], w))
    joints = _joints(f.get("joints"), where)
    if missing := {e for e in entry if e >= 0} - set(joints):
        raise _bad(f"segment placed by entry {min(missing)} that has no joint", where)
    site_names, site_seg, site_loc = [], [], []
    for i, row in enumerate(_list(f.get("sites"), f"{where} sites", MAX_SITES)):
        w = f"{where} site {i}"
        if not (isinstance(row, list) and len(row) == 3 and _is_int(row[1])):
            raise _schema("site must be [name, segment, location]", w)
        if not 0 <= row[1] < len(segs):
            raise _bad(f"segment {row[1]} not in 0..{len(segs) - 1}", w)
        site_names.append(_str(row[0], w))
        site_seg.append(row[1])
        site_loc.append(_matrix(row[2], w))
    return _frozen(
        WireFigure(
            _str(f.get("name"), where),
            _str(f.get("file"), where),
            tuple(names),
            np.array(parent, np.int64),
            np.array(entry, np.int64),
            np.array(reverse, bool),
            np.array(pre).reshape(-1, 4, 4),
            np.array(post).reshape(-1, 4, 4),
            joints,
            tuple(site_names),
            np.array(site_seg, np.int64),
            np.array(site_loc).reshape(-1, 4, 4),
            _mesh_map(f.get("meshes", []), len(segs), where),
        )
    )


def _joints(v: object, where: str) -> dict[int, tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    out = {}
    for i, row in enumerate(_list(v, f"{where} joints", 1024)):
        w = f"{where} joint {i}"
        if not (isinstance(row, list) and len(row) == 3 and _is_int(row[0])):
            raise _schema("joint must be [entry, name, dofs]", w)
        if not 0 <= row[0] <= 1023 or row[0] in out:
            raise _bad("entry not in 0..1023 or listed twice", w)
        rot, axes, lo, hi = [], [], [], []
        for d in _list(row[2], w, 16, 1):
            if not (isinstance(d, list) and len(d) == 6 and d[0] in ("R", "T")):
                raise _schema('DOF must be ["R"|"T", ax, ay, az, lower, upper]', w)
            axis = np.array([_num(x, w) for x in d[1:4]])
            if abs(np.linalg.norm(axis) - 1.0) > 1e-4:
                raise _bad("DOF axis is not a unit vector", w)
            rot.append(d[0] == "R")
            axes.append(axis)
            lo.append(_num(d[4], w, nullable=True))
            hi.append(_num(d[5], w, nullable=True))
        out[int(row[0])] = (
            _str(row[1], w),
            np.array(rot, bool),
            np.array(axes).reshape(-1, 3),
            np.array(lo),
            np.array(hi),
        )
    return out


def _mesh_map(v: object, nseg: int, where: str) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for i, row in enumerate(_list(v, f"{where} meshes", nseg)):
        w = f"{where} mesh {i}"
        if not (isinstance(row, list) and len(row) == 3 and _is_int(row[0]) and 0 <= row[0] < nseg):
            raise _schema("mesh must be [segment, vertices, triangles]", w)
        verts = _list(row[1], w, MAX_MESH_VALUES)
        tris = _list(row[2], w, MAX_MESH_VALUES)
        if len(verts) % 3 or len(tris) % 3:
            raise _bad("vertex and triangle lists must hold whole triples", w)
        vv = np.array([_num(x, w) for x in verts]).reshape(-1, 3)
        if not all(_is_int(x) for x in tris):
            raise _schema("triangle indices must be ints", w)
        tt = np.array(tris, np.int64).reshape(-1, 3)
        if tt.size and (tt.min() < 0 or tt.max() >= len(vv)):
            raise _bad("triangle index out of the vertex list", w)
        out[int(row[0])] = (vv, tt)
    return out


def _frozen(f: WireFigure) -> WireFigure:
    for value in vars(f).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return f
