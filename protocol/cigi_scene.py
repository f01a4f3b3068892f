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

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from peabody import quaternion
from protocol import cigi
from protocol.dis.geo import LocalFrame, ecef_to_geodetic, euler_from_matrix
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


def body_euler(q: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (``(..., 3)`` degrees, CIGI's yaw-pitch-roll order) of soldier-frame (w, x, y, z)
    rotations ``(..., 4)``."""
    r = _SOLDIER_TO_BODY @ quaternion.to_matrix(np.asarray(q, np.float64)) @ _SOLDIER_TO_BODY.T
    psi_theta_phi = euler_from_matrix(np.swapaxes(r, -1, -2))  # DIS's z-y-x angles of world-to-body
    return np.degrees(psi_theta_phi[..., ::-1])


@dataclass(frozen=True)
class SoldierGroup:
    """What one frame says of ``n`` soldiers of one update table: where (Performer east/north/up metres,
    compass headings), their figure's entity type, their figures' offsets (soldier frame, metres; the root
    first) and rotations, the part IDs of those figures, and the joint DOFs (protocol units)."""

    entity_ids: np.ndarray  # (n,)
    entity_type: int
    positions: np.ndarray  # (n, 3)
    headings: np.ndarray  # (n,)
    offsets: np.ndarray  # (n, figures, 3)
    rotations: np.ndarray  # (n, figures, 4)
    figure_parts: tuple[int, ...]
    dofs: np.ndarray  # (n, ndofs)
    kinds: tuple[str, ...]

    def geodetic(self, origin: LocalFrame) -> np.ndarray:
        """(n, 3) latitude, longitude (degrees), altitude (m) about ``origin``."""
        return np.stack(ecef_to_geodetic(origin.to_ecef(np.asarray(self.positions, np.float64))), axis=-1)

    def values(self) -> np.ndarray:
        """The DOFs in CIGI units: degrees for rotations, metres for translations."""
        rot = np.array([k == "R" for k in self.kinds])
        return np.where(rot, np.degrees(self.dofs), self.dofs)


def soldier_packets(g: SoldierGroup, origin: LocalFrame) -> Iterator[cigi.Packet]:
    """Per soldier: Entity Control, the figures' Articulated Part Controls, then the DOFs two to a Short one
    (the packets one by one, as :func:`group_bytes` writes them all at once)."""
    geo, euler, values = g.geodetic(origin), body_euler(g.rotations), g.values()
    body = np.asarray(g.offsets, np.float64) @ _SOLDIER_TO_BODY.T
    selects = [cigi.DofSelect.ROLL if k == "R" else cigi.DofSelect.X_OFFSET for k in g.kinds]
    for n, eid in enumerate(int(e) for e in g.entity_ids):
        lat, lon, alt = (float(v) for v in geo[n])
        yield cigi.EntityControl(eid, g.entity_type, lat, lon, alt, yaw=float(g.headings[n]) % 360.0)
        for f, pid in enumerate(g.figure_parts):
            x, y, z = (float(v) for v in body[n, f])
            yield cigi.ArticulatedPart(eid, pid, True, x, y, z, *(float(a) for a in euler[n, f]))
        for i in range(0, len(selects), 2):
            second = i + 1 < len(selects)  # an odd count: the last packet's second slot is not used
            yield cigi.ShortArticulatedPart(
                eid, i + 1, i + 2 if second else 0, selects[i],
                selects[i + 1] if second else cigi.DofSelect.NOT_USED, float(values[n, i]),
                float(values[n, i + 1]) if second else 0.0, True, second,
            )  # fmt: skip


_ENTITY = np.dtype([("head", "u1", 2), ("entity", ">u2"), ("flags", "u1", 4), ("type", ">u2"),
                    ("parent", ">u2"), ("rpy", ">f4", 3), ("pos", ">f8", 3)])  # fmt: skip
_PART = np.dtype([("head", "u1", 2), ("entity", ">u2"), ("part", "u1"), ("flags", "u1"), ("pad", "u1", 2),
                  ("xyz", ">f4", 3), ("rpy", ">f4", 3)])  # fmt: skip
_SHORT = np.dtype([("head", "u1", 2), ("entity", ">u2"), ("parts", "u1", 2), ("flags", "u1"), ("pad", "u1"),
                   ("dof", ">f4", 2)])  # fmt: skip
assert (_ENTITY.itemsize, _PART.itemsize, _SHORT.itemsize) == (48, 32, 16)


def group_bytes(g: SoldierGroup, origin: LocalFrame) -> np.ndarray:
    """``(n, bytes)``: each soldier's packets, big-endian, byte for byte :func:`soldier_packets` encoded."""
    n, nfig, ndof = len(g.entity_ids), len(g.figure_parts), len(g.kinds)
    eid = np.asarray(g.entity_ids, np.uint16)
    ent = np.zeros(n, _ENTITY)
    ent["head"] = (cigi.PacketId.ENTITY_CONTROL, 48)
    ent["entity"], ent["type"], ent["flags"][:, 0], ent["flags"][:, 2] = eid, g.entity_type, 1, 255
    ent["rpy"][:, 2] = np.asarray(g.headings, np.float64) % 360.0
    ent["pos"] = g.geodetic(origin)
    part = np.zeros((n, nfig), _PART)
    part["head"] = (cigi.PacketId.ARTICULATED_PART, 32)
    part["entity"], part["part"], part["flags"] = eid[:, None], g.figure_parts, 0x7F
    part["xyz"] = np.asarray(g.offsets, np.float64) @ _SOLDIER_TO_BODY.T
    part["rpy"] = body_euler(g.rotations)
    nshort = (ndof + 1) // 2
    values = np.zeros((n, 2 * nshort))
    values[:, :ndof] = g.values()
    select = np.zeros(2 * nshort, np.uint8)
    select[:ndof] = [cigi.DofSelect.ROLL if k == "R" else cigi.DofSelect.X_OFFSET for k in g.kinds]
    enable = np.arange(2 * nshort) < ndof
    ids = np.where(enable, np.arange(1, 2 * nshort + 1), 0).reshape(nshort, 2)
    short = np.zeros((n, nshort), _SHORT)
    short["head"] = (cigi.PacketId.SHORT_ARTICULATED_PART, 16)
    short["entity"], short["parts"], short["dof"] = eid[:, None], ids, values.reshape(n, nshort, 2)
    sel, en = select.reshape(nshort, 2), enable.reshape(nshort, 2)
    short["flags"] = sel[:, 0] | sel[:, 1] << 3 | en[:, 0] << 6 | en[:, 1].astype(np.uint8) << 7
    return np.concatenate([a.view(np.uint8).reshape(n, -1) for a in (ent, part, short)], axis=1)


def frame_messages(
    frame: int,
    groups: list[SoldierGroup],
    origin: LocalFrame,
    max_bytes: int = MAX_MESSAGE,
    timestamp: int = 0,
) -> list[bytes]:
    """One frame's host messages: each opens with IG Control (the same frame number) and holds whole
    soldiers' packets up to ``max_bytes`` (a soldier bigger than that gets a message of his own)."""
    head = cigi.encode(cigi.IgControl(frame & 0xFFFFFFFF, timestamp & 0xFFFFFFFF, timestamp_valid=True))
    messages: list[bytes] = []
    body = bytearray()
    for g in groups:
        rows = group_bytes(g, origin)
        data, size = rows.tobytes(), rows.shape[1]
        for k in range(len(rows)):
            chunk = data[k * size : (k + 1) * size]
            if body and len(head) + len(body) + len(chunk) > max_bytes:
                messages.append(head + bytes(body))
                body.clear()
            body += chunk
    messages.append(head + bytes(body))
    return messages
