"""The update table (section 3.7): how both sides interpret a soldier's joint-update fields.

Each entry is a joint (1..16 DOFs) or a figure (7 values: position + orientation quaternion). The table also
carries each field's quantisation (range and bit width), so server and client reconstruct identical values.
Internally a table is flattened into *fields*: one per joint DOF and, per figure,
``x, y, z, qidx, c0, c1, c2`` (``qidx``: which quaternion component the smallest-three encoding dropped,
2 bits).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal, TypeGuard

import numpy as np

from protocol.errors import ErrorCode, WireError

MAX_ENTRIES = 1024
MAX_FIELDS = 4096
MAX_JOINT_DOFS = 16
MAX_FIELD_BITS = 24  # bit packer reads 4-byte windows: width + 7 <= 32
QIDX_BITS = 2
QUAT_COMPONENT_LIMIT = 1.0 / math.sqrt(2.0)  # smallest-three components lie in [-1/sqrt2, 1/sqrt2]

DEFAULT_DOF_BITS = 12
DEFAULT_POS_LO = -32.768  # metres: int16 millimetres around the soldier's feet
DEFAULT_POS_HI = 32.768
DEFAULT_POS_BITS = 16
DEFAULT_QUAT_BITS = 12


@dataclass(frozen=True)
class DofRange:
    """One joint DOF: ``kind`` R (radians) or T (metres), quantised in ``bits`` on ``[lo, hi)``.

    ``step = (hi - lo) / 2**bits``; code ``q`` in ``0 .. 2**bits - 1`` stands for ``lo + q * step`` (so the
    middle of a symmetric range, e.g. 0 in ``[-pi, pi)``, is exact).
    """

    kind: Literal["R", "T"]
    lo: float
    hi: float
    bits: int = DEFAULT_DOF_BITS

    @property
    def step(self) -> float:
        return (self.hi - self.lo) / (1 << self.bits)


@dataclass(frozen=True)
class JointEntry:
    name: str
    dofs: tuple[DofRange, ...]
    kind: Literal["joint"] = "joint"

    @property
    def ndofs(self) -> int:
        return len(self.dofs)


@dataclass(frozen=True)
class FigureEntry:
    """A figure's root location relative to the soldier's feet: position (metres) and unit quaternion."""

    name: str
    pos_lo: float = DEFAULT_POS_LO
    pos_hi: float = DEFAULT_POS_HI
    pos_bits: int = DEFAULT_POS_BITS
    quat_bits: int = DEFAULT_QUAT_BITS
    kind: Literal["figure"] = "figure"

    @property
    def ndofs(self) -> int:
        return 7


Entry = JointEntry | FigureEntry


@dataclass(frozen=True)
class TableLayout:
    """The table flattened into fields (numpy arrays, built once per table)."""

    width: np.ndarray  # (F,) int64 absolute bit width
    max_code: np.ndarray  # (F,) 2**width - 1
    lo: np.ndarray  # (F,) float64
    step: np.ndarray  # (F,) float64 (qidx fields: lo 0, step 1)
    entry_of: np.ndarray  # (F,) int64
    is_qidx: np.ndarray  # (F,) bool
    entry_start: np.ndarray  # (E,) first field of each entry
    entry_nfields: np.ndarray  # (E,)
    entry_absbits: np.ndarray  # (E,) bits of the entry in absolute mode
    entry_ndelta: np.ndarray  # (E,) fields sent in delta mode (all but qidx)
    dof_fields: np.ndarray  # (D,) field of each joint DOF, in table order
    pos_fields: np.ndarray  # (G, 3)
    qidx_fields: np.ndarray  # (G,)
    comp_fields: np.ndarray  # (G, 3)
    gather: (
        np.ndarray | None
    )  # (F,) column of each field in [dofs | positions | qidx | comps] order, None if same

    @property
    def nfields(self) -> int:
        return len(self.width)


@dataclass(frozen=True)
class UpdateTable:
    """An update table: ``table_id`` (u16), the soldier's figure and weapon files, the entries in order."""

    table_id: int
    figure: str
    weapon: str
    entries: tuple[Entry, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        validate_table(self)

    @property
    def ndofs(self) -> int:
        """Joint DOFs (the ``dofs`` column count of a JointUpdates batch)."""
        return sum(e.ndofs for e in self.entries if isinstance(e, JointEntry))

    @property
    def nfigures(self) -> int:
        return sum(1 for e in self.entries if isinstance(e, FigureEntry))

    @cached_property
    def layout(self) -> TableLayout:
        return _build_layout(self.entries)

    def full_update_bits(self) -> int:
        """Bits of one soldier's full (absolute) update body, excluding index and header."""
        return int(self.layout.entry_absbits.sum())


def validate_table(table: UpdateTable) -> None:
    """Raise :class:`WireError` (BAD_VALUE) if the table is outside the protocol's limits."""

    def bad(msg: str, where: str = "") -> WireError:
        return WireError(ErrorCode.BAD_VALUE, msg, f"update table {table.table_id} {where}".strip())

    if not 0 <= table.table_id <= 0xFFFF:
        raise bad("table id not in 0..65535")
    if not 1 <= len(table.entries) <= MAX_ENTRIES:
        raise bad(f"entry count {len(table.entries)} not in 1..{MAX_ENTRIES}")
    nfields = 0
    for i, e in enumerate(table.entries):
        where = f"entry {i}"
        if not e.name:
            raise bad("empty entry name", where)
        if isinstance(e, JointEntry):
            if not 1 <= len(e.dofs) <= MAX_JOINT_DOFS:
                raise bad(f"joint DOF count {len(e.dofs)} not in 1..{MAX_JOINT_DOFS}", where)
            for d in e.dofs:
                if d.kind not in ("R", "T"):
                    raise bad(f"DOF kind {d.kind!r} not R or T", where)
                _check_range(d.lo, d.hi, d.bits, 16, bad, where)
            nfields += len(e.dofs)
        elif isinstance(e, FigureEntry):
            _check_range(e.pos_lo, e.pos_hi, e.pos_bits, MAX_FIELD_BITS, bad, where)
            if not 2 <= e.quat_bits <= 16:
                raise bad(f"quat_bits {e.quat_bits} not in 2..16", where)
            nfields += 7
        else:
            raise bad(f"unknown entry type {type(e).__name__}", where)
    if nfields > MAX_FIELDS:
        raise bad(f"{nfields} fields exceed {MAX_FIELDS}")


def _check_range(lo: float, hi: float, bits: int, max_bits: int, bad: Any, where: str) -> None:
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise bad(f"range [{lo}, {hi}] not finite and increasing", where)
    if not 1 <= bits <= max_bits:
        raise bad(f"bits {bits} not in 1..{max_bits}", where)


def _build_layout(entries: tuple[Entry, ...]) -> TableLayout:
    width: list[int] = []
    lo: list[float] = []
    step: list[float] = []
    entry_of: list[int] = []
    is_qidx: list[bool] = []
    starts, nf, absbits, ndelta = [], [], [], []
    dof_fields: list[int] = []
    pos_fields: list[list[int]] = []
    qidx_fields: list[int] = []
    comp_fields: list[list[int]] = []
    for i, e in enumerate(entries):
        starts.append(len(width))
        if isinstance(e, JointEntry):
            for d in e.dofs:
                dof_fields.append(len(width))
                width.append(d.bits)
                lo.append(d.lo)
                step.append(d.step)
                entry_of.append(i)
                is_qidx.append(False)
            ndelta.append(len(e.dofs))
        else:
            pstep = (e.pos_hi - e.pos_lo) / (1 << e.pos_bits)
            cstep = 2 * QUAT_COMPONENT_LIMIT / (1 << e.quat_bits)
            base = len(width)
            pos_fields.append([base, base + 1, base + 2])
            qidx_fields.append(base + 3)
            comp_fields.append([base + 4, base + 5, base + 6])
            width += [e.pos_bits] * 3 + [QIDX_BITS] + [e.quat_bits] * 3
            lo += [e.pos_lo] * 3 + [0.0] + [-QUAT_COMPONENT_LIMIT] * 3
            step += [pstep] * 3 + [1.0] + [cstep] * 3
            entry_of += [i] * 7
            is_qidx += [False] * 3 + [True] + [False] * 3
            ndelta.append(6)
        nf.append(len(width) - starts[-1])
        absbits.append(sum(width[starts[-1] :]))
    i64 = np.int64
    kind_order = np.concatenate(
        [dof_fields, np.ravel(pos_fields), qidx_fields, np.ravel(comp_fields)]
    ).astype(i64)
    gather = np.empty(len(width), i64)
    gather[kind_order] = np.arange(len(width))
    layout = TableLayout(
        width=np.asarray(width, i64),
        max_code=(np.int64(1) << np.asarray(width, i64)) - 1,
        lo=np.asarray(lo, np.float64),
        step=np.asarray(step, np.float64),
        entry_of=np.asarray(entry_of, i64),
        is_qidx=np.asarray(is_qidx, bool),
        entry_start=np.asarray(starts, i64),
        entry_nfields=np.asarray(nf, i64),
        entry_absbits=np.asarray(absbits, i64),
        entry_ndelta=np.asarray(ndelta, i64),
        dof_fields=np.asarray(dof_fields, i64),
        pos_fields=np.asarray(pos_fields, i64).reshape(-1, 3),
        qidx_fields=np.asarray(qidx_fields, i64),
        comp_fields=np.asarray(comp_fields, i64).reshape(-1, 3),
        gather=None if (gather == np.arange(len(width))).all() else gather,
    )
    for value in vars(layout).values():  # shared by every connection using the table: read-only
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return layout


# -- msgpack form (the UPDATE_TABLE message body) -------------------------------------------------------


def table_to_wire(table: UpdateTable) -> dict[str, Any]:
    """The msgpack map of an UPDATE_TABLE message."""
    entries: list[list[Any]] = []
    for i, e in enumerate(table.entries):
        if isinstance(e, JointEntry):
            quant: list[Any] = [[d.kind, float(d.lo), float(d.hi), int(d.bits)] for d in e.dofs]
        else:
            quant = [float(e.pos_lo), float(e.pos_hi), int(e.pos_bits), int(e.quat_bits)]
        entries.append([i, e.name, e.kind, e.ndofs, quant])
    return {"table": table.table_id, "figure": table.figure, "weapon": table.weapon, "entries": entries}


def _is_int(v: object) -> TypeGuard[int]:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: object) -> bool:
    return (isinstance(v, int | float)) and not isinstance(v, bool) and math.isfinite(v)


def table_from_wire(body: Any) -> UpdateTable:
    """Parse and validate the msgpack map of an UPDATE_TABLE message (:class:`WireError` on any fault)."""

    def schema(msg: str, where: str = "") -> WireError:
        return WireError(ErrorCode.SCHEMA, msg, f"update table {where}".strip())

    if not isinstance(body, dict):
        raise schema("body is not a map")
    tid, figure, weapon, raw = (body.get(k) for k in ("table", "figure", "weapon", "entries"))
    if not _is_int(tid):
        raise schema("'table' must be an int")
    if not isinstance(figure, str) or not isinstance(weapon, str):
        raise schema("'figure' and 'weapon' must be strings")
    if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_ENTRIES:
        raise schema(f"'entries' must be a list of 1..{MAX_ENTRIES} entries")
    entries: list[Entry] = []
    for i, item in enumerate(raw):
        where = f"entry {i}"
        if not (isinstance(item, list) and len(item) == 5):
            raise schema("entry must be [index, name, kind, ndofs, quant]", where)
        index, name, kind, ndofs, quant = item
        if not _is_int(index) or index != i:
            raise schema(f"entry index must be {i}", where)
        if not isinstance(name, str) or not name:
            raise schema("name must be a non-empty string", where)
        if not _is_int(ndofs) or not isinstance(quant, list):
            raise schema("ndofs must be an int and quant a list", where)
        if kind == "joint":
            if not 1 <= ndofs <= MAX_JOINT_DOFS or len(quant) != ndofs:
                raise schema(f"joint needs 1..{MAX_JOINT_DOFS} DOFs and one quant per DOF", where)
            dofs = []
            for q in quant:
                ok = isinstance(q, list) and len(q) == 4 and q[0] in ("R", "T")
                if not (ok and _is_num(q[1]) and _is_num(q[2]) and _is_int(q[3])):
                    raise schema('DOF quant must be ["R"|"T", lo, hi, bits]', where)
                dofs.append(DofRange(q[0], float(q[1]), float(q[2]), int(q[3])))
            entries.append(JointEntry(name, tuple(dofs)))
        elif kind == "figure":
            ok = ndofs == 7 and len(quant) == 4 and _is_num(quant[0]) and _is_num(quant[1])
            if not (ok and _is_int(quant[2]) and _is_int(quant[3])):
                raise schema("figure needs ndofs 7 and quant [pos_lo, pos_hi, pos_bits, quat_bits]", where)
            entries.append(FigureEntry(name, float(quant[0]), float(quant[1]), int(quant[2]), int(quant[3])))
        else:
            raise schema(f"kind {kind!r} is not 'joint' or 'figure'", where)
    return UpdateTable(int(tid), figure, weapon, tuple(entries))


# -- a DI.fig-shaped example ------------------------------------------------------------------------------

_DI_JOINTS: tuple[tuple[str, int], ...] = (
    ("waist", 3), ("belly", 3), ("spine_slide", 1), ("neck", 3), ("atlanto_occipital", 2),
    ("left_clavicle", 2), ("left_shoulder", 3), ("left_elbow", 2), ("left_wrist", 3),
    ("right_clavicle", 2), ("right_shoulder", 3), ("right_elbow", 2), ("right_wrist", 3),
    ("left_hip", 3), ("left_knee", 1), ("left_ankle", 3), ("left_toes", 1),
    ("right_hip", 3), ("right_knee", 1), ("right_ankle", 3), ("right_toes", 1),
    ("left_palm_grip", 1), ("right_palm_grip", 1),
)  # fmt: skip


def example_di_table(table_id: int = 1) -> UpdateTable:
    """A table with DI.fig's shape (23 joints / 50 DOFs + soldier and rifle figures) for docs, tests, benches.

    Joint names and ranges are plausible stand-ins; the server builds the real table from the loaded figure.
    ``spine_slide`` is the one translational DOF (the DI.fig spine's compression joint, metres).
    """
    entries: list[Entry] = []
    for name, n in _DI_JOINTS:
        if name == "spine_slide":
            entries.append(JointEntry(name, (DofRange("T", -0.05, 0.05),)))
        elif name.endswith("knee"):
            entries.append(JointEntry(name, (DofRange("R", 0.0, math.radians(160.0)),)))
        else:
            entries.append(JointEntry(name, tuple(DofRange("R", -math.pi, math.pi) for _ in range(n))))
    entries.append(FigureEntry("soldier"))
    entries.append(FigureEntry("rifle"))
    table = UpdateTable(table_id, "DI.fig", "AK_47.fig", tuple(entries))
    assert table.ndofs == 50 and len(entries) == 25
    return table
