"""Soldiers as CIGI 3.3 entities (sans I/O): the part map of an update table and a frame's host messages.

Each soldier is one entity, placed by its entity request (the client's own position and heading: geodetic
about an origin, yaw = compass heading) with the entity type of its figure. The figure root's pose in the
soldier's frame (docs/PROTOCOL.md: the pelvis over the feet, lying, kneeling, turned 45° when standing bladed)
is articulated part 0, an Articulated Part Control with all six values; every joint DOF is one more part
(1..), sent two to a Short Articulated Part Control: a rotation DOF as ``ROLL`` (degrees about the joint's own
DOF axis, which the figure file names), a translation as ``X_OFFSET`` (metres). The table's other figures
(the rifle) come last, each an Articulated Part Control like the root. :func:`part_map` is the file the IG
integrator loads to bind part IDs to the model's joints.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from peabody import quaternion
from protocol import cigi
from protocol.dis.geo import LocalFrame, ecef_to_geodetic
from protocol.update_table import FigureEntry, JointEntry, UpdateTable

ROOT_PART = 0
FIRST_ENTITY_TYPE = 1001  # entity types this host gives its figures, in the order the tables came
MAX_MESSAGE = 1472  # bytes: one Ethernet frame, no IP fragments
# the soldier's frame (x right, y forward, z up; docs/PROTOCOL.md) -> CIGI body axes (x forward, right, down)
_SOLDIER_TO_BODY = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class PartDof:
    part_id: int
    joint: str
    dof: int  # index of the DOF within its joint
    kind: str  # "R" or "T"

    @property
    def select(self) -> cigi.DofSelect:
        return cigi.DofSelect.ROLL if self.kind == "R" else cigi.DofSelect.X_OFFSET


def part_dofs(table: UpdateTable) -> list[PartDof]:
    """Part IDs 1.. for the table's joint DOFs in update-column order; ValueError past 255."""
    dofs = _numbered(table)
    if len(dofs) + table.nfigures - 1 > cigi.MAX_PART_ID:
        raise ValueError(f"{table.figure}: {len(dofs)} joint DOFs, CIGI part IDs stop at {cigi.MAX_PART_ID}")
    return dofs


def _numbered(table: UpdateTable) -> list[PartDof]:
    out: list[PartDof] = []
    for e in table.entries:
        if isinstance(e, JointEntry):
            first = len(out) + 1
            out += [PartDof(first + k, e.name, k, d.kind) for k, d in enumerate(e.dofs)]
    return out


def figure_parts(table: UpdateTable) -> list[tuple[int, str]]:
    """(part ID, figure entry name) of the table's figures: the root is part 0, the others follow the DOFs."""
    names = [e.name for e in table.entries if isinstance(e, FigureEntry)]
    first = table.ndofs + 1
    return [(ROOT_PART, names[0])] + [(first + k, n) for k, n in enumerate(names[1:])] if names else []


def part_map(tables: dict[int, UpdateTable]) -> dict:
    """The IG integrator's file (JSON-ready): per figure its entity type and every part ID's joint DOF."""
    figures = []
    for n, tid in enumerate(sorted(tables)):
        t = tables[tid]
        figures.append({
            "figure": t.figure,
            "weapon": t.weapon,
            "update_table": tid,
            "entity_type": FIRST_ENTITY_TYPE + n,
            "parts": [{"part_id": pid, "figure_entry": name, "packet": "articulated_part",
                       "values": "x y z offsets (m, body axes: forward, right, down), roll pitch yaw (deg)"}
                      for pid, name in figure_parts(t)]
            + [{"part_id": p.part_id, "joint": p.joint, "dof": p.dof, "kind": p.kind,
                "dof_select": p.select.name.lower(), "unit": "deg" if p.kind == "R" else "m"}
               for p in part_dofs(t)],
        })  # fmt: skip
    return {"cigi_version": "3.3", "figures": figures}


def entity_types(tables: dict[int, UpdateTable]) -> dict[int, int]:
    """Update table id -> the entity type :func:`part_map` gives its figure."""
    return {tid: FIRST_ENTITY_TYPE + n for n, tid in enumerate(sorted(tables))}


def body_euler(q: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw (degrees, CIGI's yaw-pitch-roll order) of a soldier-frame (w, x, y, z) rotation."""
    r = _SOLDIER_TO_BODY @ quaternion.to_matrix(np.asarray(q, np.float64)) @ _SOLDIER_TO_BODY.T
    pitch = math.asin(max(-1.0, min(1.0, -float(r[2, 0]))))
    roll = math.atan2(float(r[2, 1]), float(r[2, 2]))
    yaw = math.atan2(float(r[1, 0]), float(r[0, 0]))
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


@dataclass(frozen=True)
class SoldierPose:
    """What one frame says of one soldier: where (Performer east/north/up metres, compass heading), his
    figure's entity type, his figures' offsets (soldier frame, metres; the root first) and rotations, the part
    IDs of those figures and the joint DOFs (protocol units)."""

    entity_id: int
    entity_type: int
    position: np.ndarray
    heading: float
    offsets: np.ndarray  # (figures, 3)
    rotations: np.ndarray  # (figures, 4)
    figure_parts: tuple[int, ...]
    dofs: np.ndarray
    kinds: tuple[str, ...]


def soldier_packets(s: SoldierPose, origin: LocalFrame) -> Iterator[cigi.Packet]:
    """Entity Control, the figures' Articulated Part Controls, then the DOFs two to a Short one."""
    lat, lon, alt = (float(v) for v in ecef_to_geodetic(origin.to_ecef(np.asarray(s.position, np.float64))))
    yield cigi.EntityControl(s.entity_id, s.entity_type, lat, lon, alt, yaw=float(s.heading) % 360.0)
    for pid, offset, rotation in zip(s.figure_parts, s.offsets, s.rotations, strict=True):
        x, y, z = (float(v) for v in _SOLDIER_TO_BODY @ np.asarray(offset, np.float64))
        yield cigi.ArticulatedPart(s.entity_id, pid, True, x, y, z, *body_euler(rotation))
    values = [math.degrees(v) if k == "R" else float(v) for v, k in zip(s.dofs, s.kinds, strict=True)]
    selects = [cigi.DofSelect.ROLL if k == "R" else cigi.DofSelect.X_OFFSET for k in s.kinds]
    for i in range(0, len(values), 2):
        j = min(i + 1, len(values) - 1)
        second = j != i  # an odd count: the last packet's second slot is not used
        yield cigi.ShortArticulatedPart(
            s.entity_id, i + 1, j + 1 if second else 0, selects[i],
            selects[j] if second else cigi.DofSelect.NOT_USED, values[i], values[j] if second else 0.0,
            True, second,
        )  # fmt: skip


def frame_messages(
    frame: int,
    soldiers: list[SoldierPose],
    origin: LocalFrame,
    max_bytes: int = MAX_MESSAGE,
    timestamp: int = 0,
) -> list[bytes]:
    """One frame's host messages: each opens with IG Control (the same frame number) and holds whole
    soldiers' packets up to ``max_bytes`` (a soldier bigger than that gets a message of his own)."""
    head = cigi.encode(cigi.IgControl(frame & 0xFFFFFFFF, timestamp & 0xFFFFFFFF, timestamp_valid=True))
    messages: list[bytes] = []
    body = bytearray()
    for s in soldiers:
        chunk = b"".join(cigi.encode(p) for p in soldier_packets(s, origin))
        if body and len(head) + len(body) + len(chunk) > max_bytes:
            messages.append(head + bytes(body))
            body.clear()
        body += chunk
    messages.append(head + bytes(body))
    return messages
