"""Batched forward kinematics over a figure's spanning tree (seed 000, 7.2.2-7.4).

**The pose vector** (project-wide layout): one float per DOF, joints in ``figure.joints`` order (file order),
each joint's DOFs in the order of its ``type`` product; radians for ``R`` DOFs, centimetres for ``T`` DOFs.
``FigureKinematics.dof_slices[joint_name]`` is that joint's slice; joints without DOFs take no room.

The spanning tree starts at the world, enters the figure through its root site (placed at
``figure.location``, or a per-pose ``root_location``) and fans out across joints.  A joint is walked
site1->site2 (displacement ``D``) or, when the root lies on its site2 side, site2->site1 (``inv(D)``):

    forward:  G(seg2) = G(seg1) @ L(site1) @ D(q) @ inv(L(site2))
    reverse:  G(seg1) = G(seg2) @ L(site2) @ inv(D(q)) @ inv(L(site1))

with ``D(q) = dof[0](q0) @ dof[1](q1) @ ...`` (left to right in local frames).  All poses of a batch are
evaluated together: the only Python loop is over joints in tree order.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from peabody.model import Figure, Site
from peabody.rotations import axis_angle, skew


@dataclass(frozen=True)
class _Step:
    joint: str
    parent: int  # segment index already placed
    child: int  # segment index placed by this step
    forward: bool  # walked site1 -> site2
    pre: np.ndarray  # (4, 4) site location on the parent side (times a constant displacement if no DOFs)
    post: np.ndarray  # (4, 4) inverse site location on the child side
    dofs: np.ndarray  # DOF indices into the pose vector, in the order they multiply


_PLANES = ((1, 2), (2, 0), (0, 1))  # the columns a rotation about x, y, z mixes


def dof_transforms(axes: np.ndarray, rotational: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``(..., ndof, 4, 4)``: each DOF's transform at ``values`` ``(..., ndof)``: a rotation about its unit
    axis (radians) where ``rotational``, else a translation along it. Shared by Peabody's figures and the
    stub's scene graph, which hold the same DOF tables in different units."""
    q = np.asarray(values, dtype=np.float64)
    out = np.zeros((*q.shape, 4, 4))
    out[..., 3, 3] = 1.0
    if rotational.any():
        out[..., rotational, :3, :3] = axis_angle(axes[rotational], q[..., rotational])
    if not rotational.all():
        tr = ~rotational
        out[..., tr, 0, 0] = out[..., tr, 1, 1] = out[..., tr, 2, 2] = 1.0
        column = out[..., 3]  # a view: (..., ndof, 4); keeps the advanced index next to its axis
        column[..., tr, :3] = q[..., tr, None] * axes[tr]
    return out


def rigid_inverse(m: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms ``(..., 4, 4)`` (rotation + translation)."""
    out = np.zeros_like(m)
    rt = np.swapaxes(m[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


class FigureKinematics:
    """Precomputed spanning tree and DOF tables of one figure; evaluate any batch of poses."""

    def __init__(self, figure: Figure) -> None:
        self.figure = figure
        self.joint_names: list[str] = list(figure.joints)
        self.segment_names: list[str] = list(figure.segments)
        seg_index = {name: i for i, name in enumerate(self.segment_names)}
        self._seg_index = seg_index

        # pose vector layout
        self.dof_slices: dict[str, slice] = {}
        axes, is_rot, lower, upper = [], [], [], []
        offset = 0
        for name, joint in figure.joints.items():
            self.dof_slices[name] = slice(offset, offset + joint.ndofs)
            offset += joint.ndofs
            for d in joint.dofs:
                axes.append(d.axis)
                is_rot.append(d.kind == "R")
                lower.append(d.lower)
                upper.append(d.upper)
        self.ndof = offset
        self._axes = np.array(axes, dtype=np.float64).reshape(offset, 3)
        self._is_rot = np.array(is_rot, dtype=bool)
        self.lower = np.array(lower, dtype=np.float64)
        self.upper = np.array(upper, dtype=np.float64)

        # sites
        sites = figure.sites()
        self.site_names: list[str] = [f"{s.segment.name}.{s.name}" for s in sites if s.segment is not None]
        self._site_index = {name: i for i, name in enumerate(self.site_names)}
        self._site_seg = np.array([seg_index[s.segment.name] for s in sites if s.segment], dtype=np.intp)
        self._site_loc = np.array([s.location for s in sites], dtype=np.float64).reshape(len(sites), 4, 4)

        # spanning tree from the root site
        root = figure.root
        if root is None:
            if not sites:
                raise ValueError(f"figure {figure.name!r} has no sites, so it has no root")
            root = sites[0]
        if root.segment is None or figure.segments.get(root.segment.name) is not root.segment:
            raise ValueError(f"figure {figure.name!r}: root site {root.name!r} is not on one of its segments")
        self.root_name = f"{root.segment.name}.{root.name}"
        self._root_seg = seg_index[root.segment.name]
        self._root_inv = np.linalg.inv(root.location)
        self._steps: list[_Step] = []
        self._parent_step: dict[int, _Step] = {}
        self._build_tree()

    def _build_tree(self) -> None:
        fig = self.figure
        adjacency: dict[int, list[str]] = {i: [] for i in range(len(self.segment_names))}
        for name, joint in fig.joints.items():
            for site in (joint.site1, joint.site2):
                if site.segment is None or fig.segments.get(site.segment.name) is not site.segment:
                    raise ValueError(f"joint {name!r} connects a site outside figure {fig.name!r}")
            adjacency[self._seg_index[joint.site1.segment.name]].append(name)  # type: ignore[union-attr]
            adjacency[self._seg_index[joint.site2.segment.name]].append(name)  # type: ignore[union-attr]
        placed = {self._root_seg}
        used: set[str] = set()
        queue = deque([self._root_seg])
        while queue:
            seg = queue.popleft()
            for name in adjacency[seg]:
                if name in used:
                    continue
                used.add(name)
                joint = fig.joints[name]
                s1 = self._seg_index[joint.site1.segment.name]  # type: ignore[union-attr]
                forward = s1 == seg
                near, far = (joint.site1, joint.site2) if forward else (joint.site2, joint.site1)
                child = self._seg_index[far.segment.name]  # type: ignore[union-attr]
                if child in placed:
                    raise ValueError(f"figure {fig.name!r}: joint {name!r} closes a loop")
                placed.add(child)
                queue.append(child)
                sl = self.dof_slices[name]
                idx = np.arange(sl.start, sl.stop, dtype=np.intp)
                pre = near.location.copy()
                if joint.ndofs == 0:
                    d = joint.displacement
                    pre = pre @ (d if forward else np.linalg.inv(d))
                elif not forward:
                    idx = idx[::-1]  # inv(D0 D1 D2) = inv(D2) inv(D1) inv(D0)
                step = _Step(name, seg, child, forward, pre, np.linalg.inv(far.location), idx)
                self._steps.append(step)
                self._parent_step[child] = step
        if len(placed) != len(self.segment_names):
            missing = [self.segment_names[i] for i in range(len(self.segment_names)) if i not in placed]
            raise ValueError(f"figure {fig.name!r}: segment {missing[0]!r} is not connected to the root")
        self._dof_tables()

    def _dof_tables(self) -> None:
        """Per DOF: the sign of its value and the code of :meth:`_apply_dof`'s fast path."""
        # reversed joints use the negated DOF values (inverse rotation / translation)
        sign = np.ones(self.ndof)
        for step in self._steps:
            if not step.forward:
                sign[step.dofs] = -1.0
        # principal-axis rotations get the column-mixing fast path; -x etc. flip the value's sign
        codes = np.full(self.ndof, 3, dtype=np.intp)
        for i in range(self.ndof):
            if not self._is_rot[i]:
                codes[i] = 4
                continue
            for k in range(3):
                if abs(abs(self._axes[i, k]) - 1.0) < 1e-15:
                    codes[i] = k
                    sign[i] *= np.sign(self._axes[i, k])
        self._dof_code = codes
        # the skew and outer-product matrices of Rodrigues (peabody.rotations.axis_angle) per arbitrary axis
        self._axis_terms = {
            int(i): (skew(self._axes[i]), self._axes[i][:, None] * self._axes[i][None, :])
            for i in np.flatnonzero(codes == 3)
        }
        self._sign = sign

    # --- the tree, for writers of other forms of it (protocol.figure) -------------------------------------

    @property
    def root_segment(self) -> int:
        """Index (``segment_names``) of the segment that holds the root site."""
        return self._root_seg

    @property
    def root_inverse(self) -> np.ndarray:
        """Inverse of the root site's location: the root segment's global is ``figure.location @ this``."""
        return self._root_inv.copy()

    @property
    def rotational(self) -> np.ndarray:
        """``(ndof,)`` bool: True for ``R`` DOFs (radians), False for ``T`` DOFs (centimetres)."""
        return self._is_rot.copy()

    def tree_steps(self) -> list[tuple[str, int, int, bool, np.ndarray, np.ndarray]]:
        """The spanning tree parents first: ``(joint, parent segment, child segment, forward, pre, post)``,
        ``G(child) = G(parent) @ pre @ D(q) @ post`` (``D`` inverted when not ``forward``; see the module)."""
        return [(s.joint, s.parent, s.child, s.forward, s.pre.copy(), s.post.copy()) for s in self._steps]

    # --- poses ----------------------------------------------------------------------------------------------

    def neutral_pose(self) -> np.ndarray:
        """The figure's current DOF values (its ``displacement`` fields) as a pose vector."""
        return np.array([d.value for j in self.figure.joints.values() for d in j.dofs], dtype=np.float64)

    def clamp(self, angles: np.ndarray) -> np.ndarray:
        """Poses clamped to the joint limits."""
        return np.clip(angles, self.lower, self.upper)

    def set_pose(self, angles: np.ndarray) -> None:
        """Write one pose vector back into the figure's DOF values (``SetJointAngles`` for all joints)."""
        q = np.asarray(angles, dtype=np.float64).reshape(self.ndof)
        i = 0
        for joint in self.figure.joints.values():
            for d in joint.dofs:
                d.value = float(q[i])
                i += 1

    def dof_matrices(self, angles: np.ndarray) -> np.ndarray:
        """``(..., ndof, 4, 4)``: each DOF's transform at the given values (vectorised Rodrigues)."""
        return dof_transforms(self._axes, self._is_rot, angles)

    def _check(self, angles: np.ndarray) -> np.ndarray:
        q = np.asarray(angles, dtype=np.float64)
        if q.ndim == 0 or q.shape[-1] != self.ndof:
            raise ValueError(f"expected poses with {self.ndof} DOFs in the last axis, got shape {q.shape}")
        return q

    def segment_globals(self, angles: np.ndarray, root_location: np.ndarray | None = None) -> np.ndarray:
        """``(..., nseg, 4, 4)`` global transforms of all segments (``segment_names`` order).

        The result is a fresh array but usually a non-contiguous view of one (the batch is computed
        pose-innermost); ``np.ascontiguousarray`` it if a consumer needs C order."""
        soa, batch = self._segment_globals_soa(angles, root_location)
        return soa.transpose(3, 0, 1, 2).reshape(*batch, len(self.segment_names), 4, 4)

    def site_globals(self, angles: np.ndarray, root_location: np.ndarray | None = None) -> np.ndarray:
        """``(..., nsite, 4, 4)`` global transforms of all sites (``site_names`` order)."""
        soa, batch = self._segment_globals_soa(angles, root_location)
        out = np.empty((len(self.site_names), 4, 4, soa.shape[-1]))
        for k in range(len(self.site_names)):  # one constant product per site, every pose at once
            np.matmul(self._site_loc[k].T, soa[self._site_seg[k]], out=out[k])
        return out.transpose(3, 0, 1, 2).reshape(*batch, len(self.site_names), 4, 4)

    def _segment_globals_soa(
        self, angles: np.ndarray, root_location: np.ndarray | None
    ) -> tuple[np.ndarray, tuple[int, ...]]:
        """Globals in a structure-of-arrays layout ``(nseg, 4, 4, n)``: element ``[s, i, j]`` of every pose is
        one contiguous run, so DOF updates are a few vector operations and constant products one GEMM."""
        q = self._check(angles)
        loc = self.figure.location if root_location is None else np.asarray(root_location, dtype=np.float64)
        batch = np.broadcast_shapes(q.shape[:-1], loc.shape[:-2])
        n = int(np.prod(batch, dtype=np.int64))
        g = np.empty((len(self.segment_names), 4, 4, n))
        root = np.broadcast_to(loc @ self._root_inv, (*batch, 4, 4)).reshape(n, 4, 4)
        g[self._root_seg] = root.transpose(1, 2, 0)
        if self._steps:
            # DOF values as contiguous rows, negated on joints walked site2 -> site1
            qt = np.ascontiguousarray(
                np.broadcast_to(q * self._sign, (*batch, self.ndof)).reshape(n, self.ndof).T
            )
            for step in self._steps:
                m = np.matmul(step.pre.T, g[step.parent])  # (M @ pre) row by row: pre.T @ M[i]
                for i in step.dofs:
                    self._apply_dof(m, int(i), qt[i])
                np.matmul(step.post.T, m, out=g[step.child])
        return g, batch

    def _apply_dof(self, m: np.ndarray, i: int, value: np.ndarray) -> None:
        """``m <- m @ dof_i(value)`` in place, ``m`` in the ``(4, 4, n)`` layout: a rotation about a principal
        axis only mixes two columns, so no DOF matrix is ever built."""
        code = self._dof_code[i]
        if code < 3:  # rotation about +x, +y or +z (a negative axis is folded into the value's sign)
            a, b = _PLANES[code]
            c = np.cos(value)
            s = np.sin(value)
            ca = m[:, a].copy()
            cb = m[:, b]
            m[:, a] = c * ca + s * cb
            m[:, b] = c * cb - s * ca
        elif code == 3:  # rotation about an arbitrary unit axis: axis_angle's terms, element by element
            k, outer = self._axis_terms[i]
            c = np.cos(value)
            s = np.sin(value)
            cols = [m[:, j].copy() for j in range(3)]
            for col in range(3):
                acc = np.zeros_like(cols[0])
                for j in range(3):
                    r = c * (j == col) + s * k[j, col] + (1.0 - c) * outer[j, col]
                    acc += cols[j] * r
                m[:, col] = acc
        else:  # translation along the axis
            a = self._axes[i]
            m[:, 3] += (a[0] * m[:, 0] + a[1] * m[:, 1] + a[2] * m[:, 2]) * value

    def segment_global(self, name: str, angles: np.ndarray | None = None) -> np.ndarray:
        """``GetSegmentGlobal`` for one pose (default: the current DOF values): only the joints between the
        root and this segment are evaluated."""
        q = self.neutral_pose() if angles is None else np.asarray(angles, dtype=np.float64)
        seg = self._seg_index[name]
        if q.ndim != 1:
            return self.segment_globals(q)[..., seg, :, :]
        return self._chain_global(seg, self._check(q))

    def site_global(self, name: str, angles: np.ndarray | None = None) -> np.ndarray:
        """``GetSiteGlobal`` for one pose; ``name`` is ``"segment.site"``."""
        q = self.neutral_pose() if angles is None else np.asarray(angles, dtype=np.float64)
        i = self._site_index[name]
        seg = int(self._site_seg[i])
        if q.ndim != 1:
            return self.segment_globals(q)[..., seg, :, :] @ self._site_loc[i]
        return self._chain_global(seg, self._check(q)) @ self._site_loc[i]

    def _chain_global(self, seg: int, q: np.ndarray) -> np.ndarray:
        chain = []
        while seg in self._parent_step:
            step = self._parent_step[seg]
            chain.append(step)
            seg = step.parent
        qs = q * self._sign
        m = self.figure.location @ self._root_inv
        for step in reversed(chain):
            m = m @ step.pre
            for i in step.dofs:
                m = m @ self._dof_matrix(int(i), float(qs[i]))
            m = m @ step.post
        return m

    def _dof_matrix(self, i: int, value: float) -> np.ndarray:
        """One DOF's 4x4 at ``value`` (already sign-adjusted like ``_apply_dof``)."""
        code = self._dof_code[i]
        out = np.eye(4)
        if code < 3:
            a, b = _PLANES[code]
            c, s = math.cos(value), math.sin(value)
            out[a, a] = out[b, b] = c
            out[b, a] = s
            out[a, b] = -s
        elif code == 3:
            out[:3, :3] = axis_angle(self._axes[i], value)
        else:
            out[:3, 3] = self._axes[i] * value
        return out

    def location_for_site_global(
        self, name: str, target: np.ndarray, angles: np.ndarray | None = None
    ) -> np.ndarray:
        """``SetSiteGlobal``: the figure location that puts site ``name`` at ``target`` (pose unchanged)."""
        current = self.site_global(name, angles)
        return np.asarray(target) @ np.linalg.inv(current) @ self.figure.location

    # --- the tree -------------------------------------------------------------------------------------------

    def joint_path(self, site_a: str, site_b: str) -> list[tuple[str, bool]]:
        """``JointPath``: the joints between two sites, each with ``True`` when walked site1 -> site2."""
        a = self._seg_index[site_a.partition(".")[0]]
        b = self._seg_index[site_b.partition(".")[0]]
        for name in (site_a, site_b):
            if name not in self._site_index:
                raise KeyError(f"figure {self.figure.name!r} has no site {name!r}")
        up_a = self._ancestors(a)
        up_b = self._ancestors(b)
        common = next(s for s in up_a if s in set(up_b))
        path: list[tuple[str, bool]] = []
        for seg in up_a[: up_a.index(common)]:  # climbing from a: each step walked child -> parent
            step = self._parent_step[seg]
            path.append((step.joint, not step.forward))
        down = [self._parent_step[seg] for seg in up_b[: up_b.index(common)]]
        path.extend((step.joint, step.forward) for step in reversed(down))
        return path

    def _ancestors(self, seg: int) -> list[int]:
        out = [seg]
        while seg in self._parent_step:
            seg = self._parent_step[seg].parent
            out.append(seg)
        return out

    def site(self, name: str) -> Site:
        return self.figure.site(name)
