"""The 1994 layouts (Figure 11 and the update packet of section 3.7): codecs only.

A library, not a server path, by decision (issue 18): ``ttes server`` has no 1994 listener, since the 1994
sockets carry no handshake, role or credential and leave the figure form to out-of-band agreement; a gateway
process for a real 1994 client would use these codecs (docs/PROTOCOL.md §12 gives the reasons).

``JackPackIn`` (TTES → Jack) is eleven big-endian 32-bit words, 44 bytes::

    int soldierindex; int appearance; int weaponstate; float velocity[3]; float heading;
    float position[3]; int immediate;

The update packet (Jack → TTES) is ``int32 soldierindex | int32 size S | float32 data[S]`` (big-endian).
``data`` is a run of items, each ``float(entry index)`` then that entry's values as the update table says: a
joint's DOFs (radians; metres for translational DOFs), a figure's location as 16 floats (the Performer
``pfMatrix``, row-major with row vectors, i.e. our column-vector matrix transposed: translation in
``data[12:15]``) or, in the "cut down" form the report mentions, 7 floats ``x, y, z, qx, qy, qz, qw``
(Performer's ``pfQuat`` order). A full DI.fig update with 16-float figures is 8 + 4 · (23 + 50 + 2 · 17) = 436
bytes: the report's "about 440".

Our reading, where the report is silent: ``S`` counts floats (Figure 11's ``data[S]`` row is off by one); the
entry index is 0-based; weapon state 2 means FIRING (the report's demo has a FIRING key but no define); a
CRAWL request is sent as PRONE (in 1994 crawling was PRONE with a velocity).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from protocol.coords import matrix_to_quat, quat_to_matrix
from protocol.entity import ENTITY_REQUEST_DTYPE, Appearance, first_bad_row
from protocol.errors import ErrorCode, WireError
from protocol.update_table import FigureEntry, JointEntry, UpdateTable

JACKPACKIN_DTYPE = np.dtype(
    [
        ("soldierindex", ">i4"),
        ("appearance", ">i4"),
        ("weaponstate", ">i4"),
        ("velocity", ">f4", (3,)),
        ("heading", ">f4"),
        ("position", ">f4", (3,)),
        ("immediate", ">i4"),
    ]
)
assert JACKPACKIN_DTYPE.itemsize == 44
PACKET_HEADER = struct.Struct(">ii")
FIGURE_FLOATS = (16, 7)


# -- JackPackIn ---------------------------------------------------------------------------------------------


def encode_jackpackin(rows: np.ndarray) -> bytes:
    """Requests (:data:`ENTITY_REQUEST_DTYPE` rows) as consecutive 44-byte ``JackPackIn`` structs."""
    out = np.zeros(len(rows), JACKPACKIN_DTYPE)
    out["soldierindex"] = rows["index"]
    out["appearance"] = np.where(rows["appearance"] == Appearance.CRAWL, Appearance.PRONE, rows["appearance"])
    out["weaponstate"] = rows["weapon"]
    out["velocity"] = rows["velocity"]
    out["heading"] = rows["heading"]
    out["position"] = rows["position"]
    out["immediate"] = rows["immediate"]
    return out.tobytes()


def decode_jackpackin(data: bytes, max_soldiers: int = 0x10000) -> np.ndarray:
    """Consecutive ``JackPackIn`` structs → request rows; :class:`WireError` naming the first bad struct."""
    if len(data) % JACKPACKIN_DTYPE.itemsize:
        raise WireError(
            ErrorCode.MALFORMED_FRAME, f"{len(data)} bytes is not a whole number of 44-byte JackPackIn"
        )
    raw = np.frombuffer(data, JACKPACKIN_DTYPE)
    ints = np.stack([raw[k].astype(np.int64) for k in ("soldierindex", "appearance", "weaponstate")])
    bad = ((ints < 0) | (ints > 0xFFFF)).any(axis=0) | (ints[1] > Appearance.PRONE)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise WireError(
            ErrorCode.BAD_VALUE,
            "soldierindex, appearance (1..4) or weaponstate out of range",
            f"JackPackIn {row}",
        )
    rows = np.zeros(len(raw), ENTITY_REQUEST_DTYPE)
    rows["index"] = ints[0]
    rows["appearance"] = ints[1]
    rows["weapon"] = ints[2]
    rows["immediate"] = raw["immediate"] != 0  # C truth: any non-zero int
    rows["velocity"] = raw["velocity"]
    rows["heading"] = raw["heading"]
    rows["position"] = raw["position"]
    found = first_bad_row(rows, max_soldiers)
    if found is not None:
        raise WireError(ErrorCode.BAD_VALUE, found[1], f"JackPackIn {found[0]}")
    return rows


# -- update packets -----------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LegacyUpdate:
    """One decoded update packet: entries present, and their values (NaN where the packet had none)."""

    index: int
    entries: tuple[int, ...]
    dofs: np.ndarray  # (D,)
    positions: np.ndarray  # (G, 3)
    orientations: np.ndarray  # (G, 4) w, x, y, z


def _columns(table: UpdateTable, figure_floats: int, entries: np.ndarray) -> tuple[int, list[tuple]]:
    """For the chosen entries: the float offset of each item and (entry, kind, dof/figure slot, offset)."""
    if figure_floats not in FIGURE_FLOATS:
        raise ValueError(f"figure_floats must be 16 or 7, not {figure_floats}")
    dof_at = np.cumsum([0] + [e.ndofs if isinstance(e, JointEntry) else 0 for e in table.entries])
    fig_at = np.cumsum([0] + [int(isinstance(e, FigureEntry)) for e in table.entries])
    items = []
    off = 0
    for i in entries:
        e = table.entries[int(i)]
        if isinstance(e, JointEntry):
            items.append((int(i), "joint", int(dof_at[i]), e.ndofs, off))
            off += 1 + e.ndofs
        else:
            items.append((int(i), "figure", int(fig_at[i]), figure_floats, off))
            off += 1 + figure_floats
    return off, items


def packet_floats(table: UpdateTable, figure_floats: int = 16) -> int:
    """``S`` of a full update packet for this table."""
    return _columns(table, figure_floats, np.arange(len(table.entries)))[0]


def encode_update_packets(
    table: UpdateTable,
    indices: np.ndarray,
    dofs: np.ndarray,
    positions: np.ndarray,
    orientations: np.ndarray,
    figure_floats: int = 16,
    entries: np.ndarray | None = None,
) -> bytes:
    """One update packet per soldier (same ``entries``, default all), concatenated; vectorised."""
    entries = np.arange(len(table.entries)) if entries is None else np.asarray(entries, np.int64)
    size, items = _columns(table, figure_floats, entries)
    n = len(indices)
    data = np.zeros((n, size), np.float64)
    dofs, positions = np.asarray(dofs, np.float64), np.asarray(positions, np.float64)
    quat = np.asarray(orientations, np.float64)
    for entry, kind, slot, width, off in items:  # loop over table entries (<= 25), never over soldiers
        data[:, off] = entry
        if kind == "joint":
            data[:, off + 1 : off + 1 + width] = dofs[:, slot : slot + width]
        elif width == 16:
            m = np.zeros((n, 4, 4))
            m[:, :3, :3] = quat_to_matrix(quat[:, slot])
            m[:, :3, 3] = positions[:, slot]
            m[:, 3, 3] = 1.0
            data[:, off + 1 : off + 17] = np.swapaxes(m, 1, 2).reshape(n, 16)
        else:
            q = quat[:, slot] / np.linalg.norm(quat[:, slot], axis=-1, keepdims=True)
            data[:, off + 1 : off + 8] = np.concatenate([positions[:, slot], q[:, 1:], q[:, :1]], axis=1)
    head = np.zeros((n, 2), ">i4")
    head[:, 0] = indices
    head[:, 1] = size
    return np.concatenate([head.view(np.uint8), data.astype(">f4").view(np.uint8)], axis=1).tobytes()


def decode_update_packet(
    table: UpdateTable, data: bytes, offset: int = 0, figure_floats: int = 16
) -> tuple[LegacyUpdate, int]:
    """Decode the packet at ``offset``: it and the offset after it. :class:`WireError` on any fault."""
    if figure_floats not in FIGURE_FLOATS:
        raise ValueError(f"figure_floats must be 16 or 7, not {figure_floats}")
    where = f"update packet at byte {offset}"
    if len(data) - offset < PACKET_HEADER.size:
        raise WireError(ErrorCode.TRUNCATED, "shorter than its 8-byte header", where)
    index, size = PACKET_HEADER.unpack_from(data, offset)
    full = packet_floats(table, figure_floats)
    if not 0 <= index <= 0xFFFF or not 0 <= size <= full:
        raise WireError(
            ErrorCode.BAD_VALUE, f"soldier index {index} or size {size} out of range (size <= {full})", where
        )
    end = offset + PACKET_HEADER.size + 4 * size
    if len(data) < end:
        raise WireError(ErrorCode.TRUNCATED, f"needs {end - offset} bytes, has {len(data) - offset}", where)
    with np.errstate(invalid="ignore"):  # signalling NaNs are rejected just below
        floats = np.frombuffer(data, ">f4", size, offset + PACKET_HEADER.size).astype(np.float64)
    if not np.isfinite(floats).all():
        raise WireError(ErrorCode.BAD_VALUE, "NaN or inf in data", where)
    dofs = np.full(table.ndofs, np.nan)
    g = table.nfigures
    positions, orientations = np.full((g, 3), np.nan), np.full((g, 4), np.nan)
    _, items = _columns(table, figure_floats, np.arange(len(table.entries)))
    seen: list[int] = []
    k = 0
    while k < size:  # walks the items of one packet (<= one per table entry)
        entry = floats[k]
        if entry != int(entry) or not 0 <= entry < len(table.entries) or int(entry) in seen:
            raise WireError(
                ErrorCode.UNKNOWN_TABLE, f"data[{k}] = {entry} is not a new update table entry", where
            )
        e, kind, slot, width, _ = items[int(entry)]
        if k + 1 + width > size:
            raise WireError(
                ErrorCode.MALFORMED_FRAME, f"entry {e} needs {width} values after data[{k}]", where
            )
        vals = floats[k + 1 : k + 1 + width]
        if kind == "joint":
            dofs[slot : slot + width] = vals
        elif width == 16:
            m = vals.reshape(4, 4).T
            positions[slot] = m[:3, 3]
            orientations[slot] = matrix_to_quat(m[:3, :3])
        else:
            positions[slot] = vals[:3]
            q = np.concatenate([vals[6:7], vals[3:6]])
            norm = np.linalg.norm(q)
            if norm < 1e-6:
                raise WireError(ErrorCode.BAD_VALUE, f"entry {e}: zero quaternion", where)
            orientations[slot] = q / norm
        seen.append(e)
        k += 1 + width
    return LegacyUpdate(index, tuple(seen), dofs, positions, orientations), end


def decode_update_stream(
    table: UpdateTable, data: bytes, figure_floats: int = 16
) -> tuple[list[LegacyUpdate], int]:
    """All whole packets at the start of ``data`` and the bytes they used (a partial packet is left)."""
    out: list[LegacyUpdate] = []
    at = 0
    while len(data) - at >= PACKET_HEADER.size:
        size = PACKET_HEADER.unpack_from(data, at)[1]
        if size >= 0 and len(data) - at < PACKET_HEADER.size + 4 * size:
            break
        packet, at = decode_update_packet(table, data, at, figure_floats)
        out.append(packet)
    return out, at
