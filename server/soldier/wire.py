"""From :class:`~server.soldier.manager.TickUpdate` (Jack units) to the protocol's joint updates.

docs/PROTOCOL.md §7–§10: updates carry joint DOFs in radians (translational DOFs in metres) in update-table
order, and per figure its root position in metres and orientation quaternion relative to the soldier's local
frame in Performer axes (origin at the feet, +Y forward, +Z up). Inside the server everything is Jack: cm,
+Y up, facing -Z. :class:`WireConverter` precomputes, per figure set, the table and the column masks, then
converts a whole tick in a few numpy calls (``protocol.coords`` for the axes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from peabody.model import Figure
from protocol import coords, fused
from protocol.bitpack import scratch
from protocol.events import JointUpdates
from protocol.update_table import DEFAULT_DOF_BITS, DofRange, FigureEntry, JointEntry, UpdateTable
from server.soldier.core import TickUpdate
from server.soldier.library import MotionLibrary

T_RANGE_M = 1.0  # range (±m) of a translational DOF without finite joint limits
FIGURE_ENTRY_NAMES = ("soldier", "rifle")  # docs/PROTOCOL.md §7: the figure entries of a soldier's table


def update_table_for(
    library: MotionLibrary, table_id: int, set_index: int = 0, *, dof_bits: int = DEFAULT_DOF_BITS
) -> UpdateTable:
    """The update table of one figure set: every joint of every figure (pose-vector order), then one figure
    entry per figure (``soldier``, ``rifle``, then any further figure by its name).

    Rotations use ``[-pi, pi)`` (angles are wrapped on the way out); translations the joint limits in metres
    when finite, else ``±T_RANGE_M``. Joints of figures after the first are named ``figure.joint``.
    """
    entries = table_entries(library.sets[set_index].prototypes, dof_bits=dof_bits)
    figure, weapon = library.set_keys[set_index]
    return UpdateTable(table_id, figure, weapon, entries)


def table_entries(
    figures: Sequence[Figure], *, dof_bits: int = DEFAULT_DOF_BITS
) -> tuple[JointEntry | FigureEntry, ...]:
    """The entries of :func:`update_table_for` for ``figures`` (soldier first): also what names the nodes of
    the glTF export (``authoring.gltf_export``), so a joint has one name on the wire and in a file."""
    entries: list[JointEntry | FigureEntry] = []
    for k, fig in enumerate(figures):
        for jname, joint in fig.joints.items():
            dofs = []
            for d in joint.dofs:
                if d.kind == "T":
                    lo, hi = d.lower / 100.0, d.upper / 100.0
                    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                        lo, hi = -T_RANGE_M, T_RANGE_M
                    dofs.append(DofRange("T", lo, hi, dof_bits))
                else:
                    dofs.append(DofRange("R", -math.pi, math.pi, dof_bits))
            entries.append(JointEntry(jname if k == 0 else f"{fig.name}.{jname}", tuple(dofs)))
    for k, fig in enumerate(figures):
        entries.append(FigureEntry(FIGURE_ENTRY_NAMES[k] if k < len(FIGURE_ENTRY_NAMES) else fig.name))
    return tuple(entries)


class WireConverter:
    """Converts TickUpdates of one figure set to ``JointUpdates`` for its update table."""

    def __init__(self, library: MotionLibrary, table: UpdateTable, set_index: int = 0) -> None:
        clips = library.sets[set_index]
        kinds = [d.kind for fig in clips.prototypes for j in fig.joints.values() for d in j.dofs]
        if len(kinds) != table.ndofs or clips.nfig != table.nfigures:
            raise ValueError(
                f"table {table.table_id} has {table.ndofs} DOFs / {table.nfigures} figures, "
                f"figure set {clips.name!r} {len(kinds)} / {clips.nfig}"
            )
        self.table = table
        self.translational = np.array([k == "T" for k in kinds], bool)
        self._t_cols = np.flatnonzero(self.translational) if self.translational.any() else None
        self._r_cols = np.flatnonzero(~self.translational)
        lay = table.layout
        self._fused = (  # jack_codes' table arrays, worked out once
            self.translational,
            lay.lo,
            1.0 / lay.step,
            lay.max_code.astype(np.float64),
            *(np.ascontiguousarray(a, np.int64) for a in (lay.dof_fields, lay.pos_fields, lay.qidx_fields)),
            np.ascontiguousarray(lay.comp_fields, np.int64),
        )

    def codes(self, update: TickUpdate) -> np.ndarray | None:
        """The update's codes for the table (a work buffer, valid until the next call), as :meth:`convert`
        then ``protocol.updates.quantise`` give them, in one compiled pass (``protocol.fused.jack_codes``);
        None without numba, or for a batch with a pose that cannot be quantised (the caller's numpy path
        says which)."""
        if not fused.AVAILABLE:
            return None
        out = scratch().get("wire.codes", (len(update), self.table.layout.nfields), np.int32)
        bad = fused.kernel("jack_codes")(update.joints, update.figures, *self._fused, out)
        return out if bad < 0 else None

    def convert(self, update: TickUpdate, tick: int | None = None, *, reuse: bool = False) -> JointUpdates:
        """The update in the protocol's units. ``reuse``: its arrays are this thread's work buffers
        (:func:`protocol.bitpack.scratch`), valid until the next such call: for a caller that copies them at
        once (the pose board), so a tick does not page-fault megabytes of fresh arrays in."""
        sc = scratch() if reuse else None
        shape = update.figures.shape[:-1]
        if sc is None:
            dofs = update.joints.astype(np.float64)
            positions, orientations = np.empty((*shape, 3)), np.empty((*shape, 4))
        else:
            dofs = sc.get("wire.dofs", update.joints.shape, np.float64)
            np.copyto(dofs, update.joints)
            positions = sc.get("wire.positions", (*shape, 3), np.float64)
            orientations = sc.get("wire.orientations", (*shape, 4), np.float64)
        if self._t_cols is not None:
            dofs[:, self._t_cols] /= 100.0
        # wrap angles into [-pi, pi) (rarely needed; max and min: no |dofs| array)
        if len(dofs) and (dofs.max() > math.pi or dofs.min() < -math.pi):
            wrapped = dofs - (2 * math.pi) * np.floor((dofs + math.pi) / (2 * math.pi))
            if self._t_cols is None:
                dofs = wrapped
            else:
                dofs[:, self._r_cols] = wrapped[:, self._r_cols]
        # the axis change of protocol.coords written as a column shuffle: (x, y, z)_P = (x, -z, y)_J / 100
        f = update.figures  # float32, widened by each column's assignment (no float64 copy of it all)
        positions[..., 0] = f[..., 0]
        positions[..., 1] = -f[..., 2]
        positions[..., 2] = f[..., 1]
        positions /= coords.CM_PER_M
        orientations[..., 0] = f[..., 3]
        orientations[..., 1] = f[..., 4]
        orientations[..., 2] = -f[..., 6]
        orientations[..., 3] = f[..., 5]
        return JointUpdates(
            self.table.table_id,
            np.asarray(update.indices, np.int64),
            dofs,
            positions,
            orientations,
            update.tick if tick is None else tick,
        )


def to_joint_updates(
    update: TickUpdate,
    library: MotionLibrary,
    table: UpdateTable,
    set_index: int = 0,
    tick: int | None = None,
) -> JointUpdates:
    """One-off conversion (build a :class:`WireConverter` once to convert every tick)."""
    return WireConverter(library, table, set_index).convert(update, tick)
