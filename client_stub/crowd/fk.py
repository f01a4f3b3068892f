"""Forward kinematics for thousands of soldiers: Figure 14's Joint DCS chain as float32 3×4 array algebra.

:class:`client_stub.stub.scene_graph.Crowd` (the stub's reference scene graph) composes ``(n, nodes, 4, 4)``
float64 matrices and builds each DOF matrix in full: about 140 ms for 1,000 DI.fig soldiers on this
machine. Here a rigid transform is its top 3×4 rows, a product is numpy's float32 matmul of the 3×3 part
plus the translation (:func:`mul`), the rotational DOFs come from precomputed cross-product matrices
(Rodrigues) and the DOF columns are reordered so each kind is one slice: about 16 ms for the same 1,000.
The static data (near-site locations, far-site inverses, DOF axes and slots, tree levels) is
:class:`~client_stub.stub.scene_graph.FigureGraph`'s, so both give the same matrices (a test compares them).

:meth:`FastFigure.local_nodes` returns every node of a figure in the *soldier's local frame* (feet at the
origin, facing +Y): the figure DCS (placement · root inverse) and each joint DCS. The renderer caches these
per soldier and multiplies by the entity transform (heading and position) each frame, so a soldier whose
joints did not change costs one product per body part.
"""

from __future__ import annotations

import numpy as np

from client_stub.stub.scene_graph import FigureGraph
from peabody.rotations import skew
from protocol import coords

F32 = np.float32


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Products of rigid transforms stored as their top 3×4 rows, broadcast over leading axes."""
    out = np.matmul(a[..., :3], b)
    out[..., 3] += a[..., 3]
    return out


def to34(m: np.ndarray) -> np.ndarray:
    """4×4 (..., 4, 4) → 3×4 float32."""
    return np.ascontiguousarray(np.asarray(m)[..., :3, :], F32)


def to44(m: np.ndarray) -> np.ndarray:
    """3×4 (..., 3, 4) → 4×4 float64 (for tests and callers that want full matrices)."""
    m = np.asarray(m, np.float64)
    out = np.zeros((*m.shape[:-2], 4, 4))
    out[..., :3, :] = m
    out[..., 3, 3] = 1.0
    return out


class FastFigure:
    """One figure's kinematic tree, precomputed for batched float32 evaluation."""

    def __init__(self, graph: FigureGraph) -> None:
        self.graph = graph
        self.name = graph.name
        self.ndof = graph.ndof
        self.njoint = len(graph.joint_names)
        self.pre = to34(graph.pre)
        self.post = to34(graph.post)
        self.fixed = to34(graph.fixed)
        self.root_inverse = to34(graph.root_inverse)
        self.location = to34(graph.location)
        self.has_dofs = graph.has_dofs.copy()
        self.slots = graph.slots.copy()  # (J, W) DOF columns in product order, -1 = none
        self.sign = graph.sign.astype(F32)
        self.axis = graph.dof_axis.astype(F32)
        self.rot = graph.dof_rot.copy()
        # node index of each joint's parent within this figure's node list (0 = the figure DCS)
        self.parent_node = np.where(graph.parent < 0, 0, graph.parent + 1).astype(np.int64)
        self.levels = [lv.copy() for lv in graph.levels]
        # DOF columns reordered rotations first, so each kind is a slice; slots index the reordered columns
        self.order = np.concatenate([np.flatnonzero(self.rot), np.flatnonzero(~self.rot)])
        self.nrot = int(self.rot.sum())
        where = np.empty(self.ndof + 1, np.int64)
        where[self.order] = np.arange(self.ndof)
        where[-1] = self.ndof  # -1 (no DOF) -> the identity appended after the DOFs
        self.slots_ordered = np.where(self.slots < 0, self.ndof, where[self.slots])
        ar = self.axis[self.order[: self.nrot]]
        k = skew(ar)  # float32 like the axes
        self._k = k
        self._kk = np.matmul(k, k)  # K² (Rodrigues: R = I + sin K + (1 - cos) K²)
        self._taxis = self.axis[self.order[self.nrot :]]

    @property
    def nnodes(self) -> int:
        return 1 + self.njoint

    def dof_transforms(self, q: np.ndarray) -> np.ndarray:
        """(n, ndof + 1, 3, 4): each DOF's transform at ``sign * q`` in :attr:`order` (rotations first),
        then the identity (the slot of "no DOF")."""
        q = (np.asarray(q, F32) * self.sign)[:, self.order]
        n, nr = q.shape[0], self.nrot
        out = np.zeros((n, self.ndof + 1, 3, 4), F32)
        if nr:
            qr = q[:, :nr, None, None]
            out[:, :nr, :, :3] = np.sin(qr) * self._k + (1.0 - np.cos(qr)) * self._kk
        out[:, :, 0, 0] += 1.0
        out[:, :, 1, 1] += 1.0
        out[:, :, 2, 2] += 1.0
        if nr < self.ndof:
            out[:, nr : self.ndof, :, 3] = q[:, nr:, None] * self._taxis
        return out

    def joint_transforms(self, q: np.ndarray) -> np.ndarray:
        """(n, J, 3, 4) Joint DCS matrices ``pre · J(q) · post``."""
        n = q.shape[0]
        if not self.ndof:
            return np.broadcast_to(mul(mul(self.pre, self.fixed), self.post), (n, self.njoint, 3, 4)).copy()
        d = self.dof_transforms(q)
        m = d[:, self.slots_ordered[:, 0]]
        for k in range(1, self.slots_ordered.shape[1]):
            m = mul(m, d[:, self.slots_ordered[:, k]])
        m[:, ~self.has_dofs] = self.fixed[~self.has_dofs]
        return mul(mul(self.pre, m), self.post)

    def local_nodes(self, q: np.ndarray, placement: np.ndarray) -> np.ndarray:
        """(n, 1 + J, 3, 4): the figure DCS and every joint DCS in the soldier's local frame.

        ``q`` (n, ndof) radians/metres in pose order; ``placement`` (n, 3, 4) the figure's root-site
        placement in the soldier frame (the wire's figure entry)."""
        q = np.asarray(q, F32).reshape(-1, self.ndof)
        n = q.shape[0]
        out = np.empty((n, self.nnodes, 3, 4), F32)
        out[:, 0] = mul(np.asarray(placement, F32), self.root_inverse)
        if self.njoint:
            local = self.joint_transforms(q)
            for level in self.levels:
                out[:, level + 1] = mul(out[:, self.parent_node[level]], local[:, level])
        return out


def entity_transforms(heading_deg: np.ndarray, position: np.ndarray) -> np.ndarray:
    """(n, 3, 4) float32 world placement of each soldier's local frame (compass heading, feet position)."""
    return to34(coords.heading_transform(heading_deg, np.asarray(position, np.float64).reshape(-1, 3)))
