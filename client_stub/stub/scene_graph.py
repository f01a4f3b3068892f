"""The run-time scene graph of the TTES entities (seed 002, 7.4, Figures 13 and 14), in numpy.

Figure 13: an entity is ``Entity Position DCS`` (heading and position, the ground height under the feet)
over one subgraph per figure (the soldier and his rifle), each starting at a ``Figure DCS`` (the figure's
root-site placement times the inverse root-site transform). Figure 14: one ``Joint DCS`` per Peabody joint,
whose matrix is ``site1 · joint · site2⁻¹`` (the near site of the traversal, the joint displacement at the
current DOF values, the inverse of the far site), with the far segment's geometry under it; the figure is
rooted through its root site (the waist side: DI.fig's root is ``lower_torso.proximal``).

Nodes are rows of arrays, not objects: every soldier of one kind (figure + weapon) shares one
:class:`EntityLayout` (node names, parents, the indexed array of joint nodes) and the geometry; a
:class:`Crowd` holds the per-soldier matrices as ``(soldiers, nodes, 4, 4)`` arrays and updates any number of
soldiers with a few batched matrix products (a Python loop runs over DOF slots and tree depths, never over
soldiers). Units and axes are Performer's (m, +Z up, soldier facing +Y); the TIPS data (Jack cm, +Y up) is
converted once, with :mod:`protocol.coords`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from client_stub.stub.tips import TipsFigure, TipsGeometry
from peabody.fk import dof_transforms
from protocol import coords

ENTITY_NODE = 0  # the Entity Position DCS is node 0 of every entity


def _to_performer(m: np.ndarray) -> np.ndarray:
    return coords.transforms_jack_to_performer(np.asarray(m, np.float64))


@dataclass(frozen=True)
class SegmentGeometry:
    """One segment's surface in its own frame, Performer metres, shared by every soldier of the kind."""

    figure: str
    segment: str
    vertices: np.ndarray  # (n, 3)
    triangles: np.ndarray  # (t, 3)
    triangle_attribute: np.ndarray  # (t,)
    diffuse: np.ndarray  # (a, 3) per attribute
    vertex_colors: np.ndarray | None = None
    vertex_normals: np.ndarray | None = None


def convert_geometry(figure: str, segment: str, g: TipsGeometry) -> SegmentGeometry:
    normals = None if g.vertex_normals is None else coords.directions_jack_to_performer(g.vertex_normals)
    diffuse = np.array([a.diffuse for a in g.attributes], np.float64).reshape(-1, 3)
    return SegmentGeometry(
        figure,
        segment,
        coords.points_jack_to_performer(g.vertices),
        g.triangles.copy(),
        g.triangle_attribute.copy(),
        diffuse,
        None if g.vertex_colors is None else g.vertex_colors.copy(),
        normals,
    )


class FigureGraph:
    """The static part of one figure's subgraph: joints in pose-vector order, each a Joint DCS.

    ``parent[j]`` is the joint whose node the joint hangs under (-1: the Figure DCS); ``pre[j]``/``post[j]``
    the near-site location and the far-site inverse; DOF ``k`` of the pose vector belongs to joint
    ``dof_joint[k]``. ``levels`` groups joints by tree depth, parents first."""

    def __init__(self, tips: TipsFigure) -> None:
        self.name = tips.name
        self.filename = tips.filename
        self.location = _to_performer(tips.location)
        self.root_inverse = _to_performer(tips.root_inverse)
        walk = tips.walk()
        order = tips.pose_order()
        index = {id(j): k for k, j in enumerate(order)}
        self.joint_names = [j.name for j in order]
        njoint = len(order)
        self.parent = np.full(njoint, -1, np.int64)
        self.pre = np.zeros((njoint, 4, 4))
        self.post = np.zeros((njoint, 4, 4))
        self.fixed = np.zeros((njoint, 4, 4))
        self.dof_slices: dict[str, slice] = {}
        axes, rot, dof_joint = [], [], []
        for joint, site, parent in walk:
            k = index[id(joint)]
            self.parent[k] = -1 if parent is None else index[id(parent)]
            self.pre[k] = _to_performer(site.matrix)
            self.post[k] = _to_performer(joint.othersite_inverse)
            d = _to_performer(joint.matrix)
            self.fixed[k] = np.linalg.inv(d) if joint.reverse else d
        offset = 0
        for k, joint in enumerate(order):
            self.dof_slices[joint.name] = slice(offset, offset + len(joint.dofs))
            offset += len(joint.dofs)
            for dof in joint.dofs:
                axes.append(coords.directions_jack_to_performer(dof.axis))
                rot.append(dof.kind == "R")
                dof_joint.append(k)
        self.ndof = offset
        self.dof_axis = np.array(axes, np.float64).reshape(offset, 3)
        self.dof_rot = np.array(rot, bool)
        self.dof_joint = np.array(dof_joint, np.int64)
        self.has_dofs = np.array([len(j.dofs) > 0 for j in order], bool)
        # DOF slots: the order DOF matrices multiply in each joint (reversed, and negated, on reversed joints)
        width = max([len(j.dofs) for j in order], default=0)
        self.slots = np.full((njoint, width), -1, np.int64)
        self.sign = np.ones(offset)
        for k, joint in enumerate(order):
            cols = list(range(self.dof_slices[joint.name].start, self.dof_slices[joint.name].stop))
            if joint.reverse:
                cols = cols[::-1]
                self.sign[cols] = -1.0
            self.slots[k, : len(cols)] = cols
        depth = np.zeros(njoint, np.int64)
        for joint, _, parent in walk:  # walk is parents-first
            k = index[id(joint)]
            depth[k] = 0 if parent is None else depth[index[id(parent)]] + 1
        self.levels = [np.flatnonzero(depth == d) for d in range(int(depth.max(initial=-1)) + 1)]
        # geometry and sites: the root segment hangs under the Figure DCS (-1), the others under their joint
        self.segments: list[tuple[SegmentGeometry | None, int]] = []
        self.sites: dict[str, tuple[int, np.ndarray]] = {}
        self._collect(tips, walk, index)

    def _collect(self, tips: TipsFigure, walk: list, index: dict[int, int]) -> None:
        for segment, node in [(tips.root, -1)] + [(j.segment, index[id(j)]) for j, _, _ in walk]:
            name = segment.name or "root"
            geom = None if segment.geometry is None else convert_geometry(self.name, name, segment.geometry)
            self.segments.append((geom, node))
            for site in segment.sites:
                self.sites[f"{name}.{site.name}"] = (node, _to_performer(site.matrix))

    def neutral_pose(self) -> np.ndarray:
        """Zero DOF values (the figure files' zero pose: standing, arms at the sides)."""
        return np.zeros(self.ndof)

    def dof_matrices(self, q: np.ndarray) -> np.ndarray:
        """``(S, ndof, 4, 4)``: each DOF's transform at ``sign * q`` (Rodrigues / translation), batched."""
        return dof_transforms(self.dof_axis, self.dof_rot, np.asarray(q, np.float64) * self.sign)

    def joint_matrices(self, q: np.ndarray) -> np.ndarray:
        """``(S, J, 4, 4)`` Joint DCS matrices ``pre · J(q) · post`` for S pose vectors (rad, m)."""
        q = np.asarray(q, np.float64).reshape(-1, self.ndof)
        s = q.shape[0]
        m = np.broadcast_to(self.fixed, (s, *self.fixed.shape)).copy()
        if self.ndof:
            dm = self.dof_matrices(q)
            eye = np.broadcast_to(np.eye(4), (s, 1, 4, 4))
            dm = np.concatenate([dm, eye], axis=1)  # slot -1 picks the identity
            m[:, self.has_dofs] = np.eye(4)
            for k in range(self.slots.shape[1]):
                m = m @ dm[:, self.slots[:, k]]
        return self.pre @ m @ self.post


@dataclass
class EntityLayout:
    """Figure 13's node layout of one kind of entity (soldier figure + weapon), shared by all its soldiers.

    Node 0 is the Entity Position DCS, then per figure its Figure DCS and its Joint DCS nodes (pose order).
    ``joint_nodes`` is the indexed array of Joint DCS nodes in the order of the entity's pose vector
    (soldier DOFs, then weapon DOFs), the O(1) way from an update-table entry to its node."""

    figures: list[FigureGraph]
    names: list[str] = field(default_factory=list)
    parent: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    figure_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    joint_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    dof_offsets: list[int] = field(default_factory=list)
    geometry: list[tuple[SegmentGeometry, int]] = field(default_factory=list)  # (segment, node)

    def __post_init__(self) -> None:
        names = ["Entity Position DCS"]
        parent = [-1]
        fig_nodes, joint_nodes, offsets = [], [], []
        geometry: list[tuple[SegmentGeometry, int]] = []
        dof = 0
        for fig in self.figures:
            fnode = len(names)
            names.append(f"Figure DCS {fig.name}")
            parent.append(ENTITY_NODE)
            fig_nodes.append(fnode)
            first = len(names)
            for k, jname in enumerate(fig.joint_names):
                names.append(f"Joint DCS {fig.name}.{jname}")
                parent.append(fnode if fig.parent[k] < 0 else first + int(fig.parent[k]))
            joint_nodes.append(np.arange(first, first + len(fig.joint_names)))
            offsets.append(dof)
            dof += fig.ndof
            for geom, node in fig.segments:
                if geom is not None:
                    geometry.append((geom, fnode if node < 0 else first + node))
        self.names = names
        self.parent = np.array(parent, np.int64)
        self.figure_nodes = np.array(fig_nodes, np.int64)
        self.joint_nodes = np.concatenate(joint_nodes) if joint_nodes else np.zeros(0, np.int64)
        self.dof_offsets = offsets
        self.geometry = geometry

    @property
    def nnodes(self) -> int:
        return len(self.names)

    @property
    def ndof(self) -> int:
        return sum(f.ndof for f in self.figures)

    def describe(self) -> str:
        """The node tree as indented text (Figures 13 and 14 for this entity)."""
        children: dict[int, list[int]] = {}
        for i, p in enumerate(self.parent):
            children.setdefault(int(p), []).append(i)
        geoms: dict[int, list[str]] = {}
        for g, node in self.geometry:
            geoms.setdefault(node, []).append(f"geometry {g.figure}.{g.segment}")
        lines: list[str] = []
        stack = [(0, 0)]
        while stack:
            node, depth = stack.pop()
            lines.append("  " * depth + self.names[node])
            lines += ["  " * (depth + 1) + g for g in geoms.get(node, [])]
            stack.extend((c, depth + 1) for c in reversed(children.get(node, [])))
        return "\n".join(lines)


class Crowd:
    """Every soldier of one :class:`EntityLayout`: per-soldier node matrices as arrays.

    Rows are slots ``0 .. capacity-1`` (the stub's soldier numbers); ``active`` says which hold a soldier.
    ``dofs`` are Performer units (radians, metres); ``placements`` each figure's root-site placement in the
    soldier's local frame. :meth:`world` composes ``entity · figure · joints`` down the tree."""

    def __init__(self, layout: EntityLayout, capacity: int = 16) -> None:
        self.layout = layout
        self.capacity = 0
        self.active = np.zeros(0, bool)
        self.entity = np.zeros((0, 4, 4))
        self.placements = np.zeros((0, len(layout.figures), 4, 4))
        self.dofs = np.zeros((0, layout.ndof))
        self.local = np.zeros((0, layout.nnodes, 4, 4))
        self._stale = np.zeros(0, bool)
        self.grow(capacity)

    def grow(self, capacity: int) -> None:
        if capacity <= self.capacity:
            return
        extra = capacity - self.capacity
        lay = self.layout
        self.active = np.concatenate([self.active, np.zeros(extra, bool)])
        self.entity = np.concatenate([self.entity, np.broadcast_to(np.eye(4), (extra, 4, 4))])
        default = np.stack([f.location for f in lay.figures]) if lay.figures else np.zeros((0, 4, 4))
        self.placements = np.concatenate([self.placements, np.broadcast_to(default, (extra, *default.shape))])
        self.dofs = np.concatenate([self.dofs, np.zeros((extra, lay.ndof))])
        self.local = np.concatenate([self.local, np.broadcast_to(np.eye(4), (extra, lay.nnodes, 4, 4))])
        self._stale = np.concatenate([self._stale, np.ones(extra, bool)])
        self.capacity = capacity

    def set_dofs(self, rows: np.ndarray, dofs: np.ndarray) -> None:
        rows = np.asarray(rows, np.int64)
        self.dofs[rows] = dofs
        self._stale[rows] = True

    def set_placements(self, rows: np.ndarray, placements: np.ndarray) -> None:
        """Figure root-site placements ``(n, figures, 4, 4)`` in the soldier's local frame."""
        self.placements[np.asarray(rows, np.int64)] = placements
        self._stale[np.asarray(rows, np.int64)] = True

    def set_entity(self, rows: np.ndarray, matrices: np.ndarray) -> None:
        self.entity[np.asarray(rows, np.int64)] = matrices

    def _refresh(self, rows: np.ndarray) -> None:
        """Recompute the local matrices (Figure and Joint DCS) of ``rows`` from their DOFs and placements."""
        if not len(rows):
            return
        lay = self.layout
        for k, fig in enumerate(lay.figures):
            self.local[rows, lay.figure_nodes[k]] = self.placements[rows, k] @ fig.root_inverse
            if len(fig.joint_names):
                q = self.dofs[rows, lay.dof_offsets[k] : lay.dof_offsets[k] + fig.ndof]
                first = lay.figure_nodes[k] + 1
                self.local[rows, first : first + len(fig.joint_names)] = fig.joint_matrices(q)
        self._stale[rows] = False

    def world(self, rows: np.ndarray | None = None) -> np.ndarray:
        """``(n, nodes, 4, 4)`` world matrices of the given rows (default: the active ones)."""
        rows = np.flatnonzero(self.active) if rows is None else np.asarray(rows, np.int64)
        self._refresh(rows[self._stale[rows]])
        lay = self.layout
        out = np.empty((len(rows), lay.nnodes, 4, 4))
        out[:, ENTITY_NODE] = self.entity[rows]
        local = self.local[rows]
        out[:, lay.figure_nodes] = out[:, ENTITY_NODE, None] @ local[:, lay.figure_nodes]
        for k, fig in enumerate(lay.figures):
            first = lay.figure_nodes[k] + 1
            for level in fig.levels:
                nodes = first + level
                out[:, nodes] = out[:, lay.parent[nodes]] @ local[:, nodes]
        return out

    def site_world(self, world: np.ndarray, figure: int, site: str) -> np.ndarray:
        """``(n, 4, 4)`` world transform of a site (``segment.site``; the root segment is ``root``)."""
        lay = self.layout
        node, matrix = lay.figures[figure].sites[site]
        n = lay.figure_nodes[figure] if node < 0 else lay.figure_nodes[figure] + 1 + node
        return world[:, n] @ matrix
