"""Articulation parameters (seed 002, section 3.7): the file the TIPS loader writes, and the update table.

"When the TIPS file is loaded into the Performer runtime database, the loader writes out a file of
articulation parameters, and this information is used to build an update table". Our ``<name>.artic`` format
(text, one item a line, ``#`` starts a comment line)::

    ttes-artic 1
    figure DI DI.fig 23 50               # name, figure file, joints, DOFs
    joint 0 waist 3 R -0.523599 0.523599 R -0.785398 1.570796 R -0.698132 0.698132
    joint 2 spine_compression 1 T -0.030000 0.010000
    ...
    end

Joints are in the figure's pose-vector order (the server's order: ``figure.joints``, file order); each DOF is
its kind and joint limits in Performer units (radians, metres; ``inf`` when unlimited). Several figures may
follow each other. :func:`update_table_for` builds the soldier's update table the way the server does
(``server/soldier/wire.py``): the soldier's joints, the weapon's joints (``figure.joint``), then the figure
entries ``soldier`` and ``rifle``; rotations on ``[-pi, pi)``, translations on their finite limits in metres
(else ±1 m). :func:`bind_table` then maps a table received on the wire onto ours by entry name.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from client_stub.stub.tips import TipsFigure
from protocol.update_table import DEFAULT_DOF_BITS, DofRange, FigureEntry, JointEntry, UpdateTable

MAGIC = "ttes-artic 1"
T_RANGE_M = 1.0  # range of a translational DOF without finite limits (as the server)
FIGURE_ENTRY_NAMES = ("soldier", "rifle")


class ArticError(ValueError):
    """A malformed articulation file (``file:line: message``)."""

    def __init__(self, message: str, file: str = "<artic>", line: int = 0) -> None:
        self.message, self.file, self.line = message, file, line
        super().__init__(f"{file}:{line}: {message}")


@dataclass(frozen=True)
class ArticJoint:
    name: str
    dofs: tuple[tuple[str, float, float], ...]  # (kind, lower, upper), Performer units

    @property
    def ndofs(self) -> int:
        return len(self.dofs)


@dataclass(frozen=True)
class ArticFigure:
    name: str
    filename: str
    joints: tuple[ArticJoint, ...]

    @property
    def ndofs(self) -> int:
        return sum(j.ndofs for j in self.joints)


def articulation(figure: TipsFigure) -> ArticFigure:
    """The articulation parameters of a loaded TIPS figure (T limits converted cm -> m)."""
    joints = []
    for joint in figure.pose_order():
        dofs = tuple(
            (
                d.kind,
                d.lower / 100.0 if d.kind == "T" else d.lower,
                d.upper / 100.0 if d.kind == "T" else d.upper,
            )
            for d in joint.dofs
        )
        joints.append(ArticJoint(joint.name, dofs))
    return ArticFigure(figure.name, figure.filename, tuple(joints))


def _num(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x + 0.0:f}"


def format_artic(figures: list[ArticFigure]) -> str:
    lines = [MAGIC]
    for fig in figures:
        lines.append(f"figure {fig.name} {fig.filename} {len(fig.joints)} {fig.ndofs}")
        for k, joint in enumerate(fig.joints):
            dofs = " ".join(f"{kind} {_num(lo)} {_num(hi)}" for kind, lo, hi in joint.dofs)
            lines.append(f"joint {k} {joint.name} {joint.ndofs} {dofs}".rstrip())
    lines.append("end")
    return "\n".join(lines) + "\n"


def write_artic(figures: list[ArticFigure], path: str | os.PathLike[str]) -> None:
    Path(path).write_text(format_artic(figures), encoding="utf-8")


def parse_artic(text: str, filename: str = "<artic>") -> list[ArticFigure]:
    """Read an articulation file; :class:`ArticError` with the line on any fault."""
    rows = [(n, line.split()) for n, line in enumerate(text.splitlines(), start=1)]
    rows = [(n, parts) for n, parts in rows if parts and not parts[0].startswith("#")]
    if not rows or " ".join(rows[0][1]) != MAGIC:
        raise ArticError(f"first line must be {MAGIC!r}", filename, rows[0][0] if rows else 1)
    figures: list[ArticFigure] = []
    current: tuple[str, str, int, int] | None = None
    joints: list[ArticJoint] = []

    def close(line: int) -> None:
        if current is None:
            return
        name, file, njoints, ndofs = current
        if len(joints) != njoints or sum(j.ndofs for j in joints) != ndofs:
            raise ArticError(
                f"figure {name}: {njoints} joints / {ndofs} DOFs announced, "
                f"{len(joints)} / {sum(j.ndofs for j in joints)} given",
                filename,
                line,
            )
        figures.append(ArticFigure(name, file, tuple(joints)))

    for n, parts in rows[1:]:
        try:
            if parts[0] == "figure" and len(parts) == 5:
                close(n)
                current, joints = (parts[1], parts[2], int(parts[3]), int(parts[4])), []
            elif parts[0] == "joint" and current is not None and len(parts) >= 4:
                k, name, ndofs = int(parts[1]), parts[2], int(parts[3])
                if k != len(joints) or not 0 <= ndofs <= 16 or len(parts) != 4 + 3 * ndofs:
                    raise ArticError(f"joint {k}: bad index, DOF count or field count", filename, n)
                dofs = []
                for i in range(ndofs):
                    kind, lo, hi = parts[4 + 3 * i], float(parts[5 + 3 * i]), float(parts[6 + 3 * i])
                    if kind not in ("R", "T") or math.isnan(lo) or math.isnan(hi):
                        raise ArticError(f"joint {name}: bad DOF {kind} {lo} {hi}", filename, n)
                    dofs.append((kind, lo, hi))
                joints.append(ArticJoint(name, tuple(dofs)))
            elif parts == ["end"]:
                close(n)
                return figures
            else:
                raise ArticError(f"unexpected line {' '.join(parts)!r}", filename, n)
        except ValueError as exc:
            if isinstance(exc, ArticError):
                raise
            raise ArticError(f"bad number: {exc}", filename, n) from None
    raise ArticError("missing 'end'", filename, rows[-1][0])


def read_artic(path: str | os.PathLike[str]) -> list[ArticFigure]:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ArticError(f"cannot read: {exc}", str(p), 0) from None
    return parse_artic(text, str(p))


def update_table_for(
    soldier: ArticFigure, weapon: ArticFigure | None, table_id: int = 1, *, dof_bits: int = DEFAULT_DOF_BITS
) -> UpdateTable:
    """The update table of a soldier (+ weapon), built as the server builds it from the same figures."""
    figures = [soldier] if weapon is None else [soldier, weapon]
    entries: list[JointEntry | FigureEntry] = []
    for k, fig in enumerate(figures):
        for joint in fig.joints:
            if not joint.dofs:
                continue
            dofs = []
            for kind, lo, hi in joint.dofs:
                if kind == "T":
                    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                        lo, hi = -T_RANGE_M, T_RANGE_M
                    dofs.append(DofRange("T", lo, hi, dof_bits))
                else:
                    dofs.append(DofRange("R", -math.pi, math.pi, dof_bits))
            entries.append(JointEntry(joint.name if k == 0 else f"{fig.name}.{joint.name}", tuple(dofs)))
    for k, fig in enumerate(figures):
        entries.append(FigureEntry(FIGURE_ENTRY_NAMES[k] if k < len(FIGURE_ENTRY_NAMES) else fig.name))
    return UpdateTable(table_id, soldier.filename, "" if weapon is None else weapon.filename, tuple(entries))


@dataclass(frozen=True)
class TableBinding:
    """How the columns of a wire table's JointUpdates land in our pose vectors.

    ``dof_src``/``dof_dst``: wire DOF columns -> our DOF columns (soldier then weapon, pose order);
    ``figure_src``: the wire figure column of our soldier and weapon figures (-1 if the table has none);
    ``agrees``: the wire table equals ours in names, kinds and DOF counts (section 3.7: both sides use the
    same table); ``missing``: our joints the wire table does not carry."""

    table_id: int
    dof_src: np.ndarray
    dof_dst: np.ndarray
    figure_src: np.ndarray
    agrees: bool
    missing: tuple[str, ...]


def bind_table(ours: UpdateTable, wire: UpdateTable) -> TableBinding:
    """Match a received update table to ours by entry name (kind and DOF count must match too)."""

    def columns(table: UpdateTable) -> tuple[dict[str, tuple[int, int, str]], list[str]]:
        joints: dict[str, tuple[int, int, str]] = {}
        figures: list[str] = []
        col = 0
        for e in table.entries:
            if isinstance(e, JointEntry):
                joints[e.name] = (col, e.ndofs, "".join(d.kind for d in e.dofs))
                col += e.ndofs
            else:
                figures.append(e.name)
        return joints, figures

    mine, my_figs = columns(ours)
    theirs, their_figs = columns(wire)
    src: list[int] = []
    dst: list[int] = []
    missing: list[str] = []
    for name, (col, n, kinds) in mine.items():
        other = theirs.get(name)
        if other is None or other[1] != n or other[2] != kinds:
            missing.append(name)
            continue
        src.extend(range(other[0], other[0] + n))
        dst.extend(range(col, col + n))
    fig_src = np.array([their_figs.index(f) if f in their_figs else -1 for f in my_figs], np.int64)
    same = [(e.name, e.kind, e.ndofs) for e in ours.entries] == [
        (e.name, e.kind, e.ndofs) for e in wire.entries
    ]
    return TableBinding(
        wire.table_id, np.array(src, np.int64), np.array(dst, np.int64), fig_src, same, tuple(missing)
    )
