"""Entity State Update PDUs (type 67, IEEE 1278.1-2012 7.2.5): an entity's motion and appearance, without the
fields that do not change (type, force, marking, dead-reckoning parameters).

Layout after the 12-byte header (big-endian):

====== ===== =====================================================================
offset bytes field
====== ===== =====================================================================
12     6     entity id (site, application, entity) u16 each
18     1     padding
19     1     number of variable-parameter records N
20     12    linear velocity, 3 x f32, m/s, ECEF
32     24    location, 3 x f64, m, ECEF
56     12    orientation psi, theta, phi, 3 x f32, rad
68     4     appearance u32
72     16N   variable-parameter records (as in the Entity State PDU)
====== ===== =====================================================================

An update means something only on top of the entity's last full Entity State PDU, so the readers *resolve*
it: :func:`resolve_updates` copies that PDU's record and overwrites the update's fields, and the result is
one more Entity State record for everything downstream (dump, replay, gateway). :class:`UpdateBases` keeps
the last full record of every entity between the bursts of a live gateway. An update of an entity whose
Entity State PDU was never seen (or was left out: not a lifeform) cannot be placed and is skipped.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from protocol.dis.batch import ESPDU_DTYPE, EntityStateBatch, gather_params
from protocol.dis.entity_state import (
    NO_ENTITY,
    VARIABLE_PARAMETER_SIZE,
    EntityId,
    VariableParameter,
    Vec3,
    unpack_params,
)
from protocol.dis.errors import DisError
from protocol.dis.pdu import (
    HEADER,
    HEADER_SIZE,
    Family,
    PduType,
    check_encodable,
    check_header,
    header_fields,
)

ESU_FIXED_SIZE = 72
_BODY = struct.Struct(">HHHBB 3f 3d 3f I")
assert HEADER.size + _BODY.size == ESU_FIXED_SIZE
UPDATED_FIELDS = ("velocity", "location", "orientation", "appearance")  # what an update overwrites
ESU_WIRE_DTYPE = np.dtype(
    [
        ("version", "u1"),
        ("exercise", "u1"),
        ("pdu_type", "u1"),
        ("family", "u1"),
        ("timestamp", ">u4"),
        ("length", ">u2"),
        ("pdu_status", "u1"),
        ("padding", "u1"),
        ("entity_id", [("site", ">u2"), ("application", ">u2"), ("entity", ">u2")]),
        ("padding1", "u1"),
        ("num_params", "u1"),
        ("velocity", ">f4", (3,)),
        ("location", ">f8", (3,)),
        ("orientation", ">f4", (3,)),
        ("appearance", ">u4"),
    ]
)
assert ESU_WIRE_DTYPE.itemsize == ESU_FIXED_SIZE
ESU_REASONS = {
    1: "length field runs past the end of the data",
    2: "protocol version not supported (5, 6, 7)",
    3: "not an Entity State Update PDU",
    4: "Entity State Update PDU shorter than 72 bytes",
    5: "length does not match the number of variable parameters",
}


@dataclass(frozen=True, slots=True)
class EntityStateUpdatePdu:
    """One Entity State Update PDU, byte-exact (padding bytes kept)."""

    entity_id: EntityId = NO_ENTITY
    velocity: Vec3 = (0.0, 0.0, 0.0)
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: Vec3 = (0.0, 0.0, 0.0)
    appearance: int = 0
    variable_parameters: tuple[VariableParameter, ...] = field(default_factory=tuple)
    version: int = 7
    exercise: int = 1
    timestamp: int = 0
    pdu_status: int = 0
    padding: int = 0
    padding1: int = 0  # the byte after the entity id
    family: int = int(Family.ENTITY_INFORMATION)

    @property
    def length(self) -> int:
        return ESU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * len(self.variable_parameters)


def encode_entity_update(pdu: EntityStateUpdatePdu) -> bytes:
    """The PDU's bytes (72 + 16 N); :class:`DisError` for values that do not fit their fields."""
    n = len(pdu.variable_parameters)
    check_encodable(pdu.version, n)
    try:
        head = HEADER.pack(pdu.version, pdu.exercise, int(PduType.ENTITY_STATE_UPDATE), pdu.family,
                           pdu.timestamp, pdu.length, pdu.pdu_status, pdu.padding)  # fmt: skip
        body = _BODY.pack(*pdu.entity_id, pdu.padding1, n, *pdu.velocity, *pdu.location, *pdu.orientation,
                          pdu.appearance)  # fmt: skip
    except (struct.error, TypeError, OverflowError) as exc:
        raise DisError(f"entity state update field out of range: {exc}", 0) from None
    return head + body + b"".join(p.pack() for p in pdu.variable_parameters)


def decode_entity_update(data: bytes | memoryview) -> EntityStateUpdatePdu:
    """Decode exactly one Entity State Update PDU (the buffer is the whole PDU); :class:`DisError` with the
    offset of the bad field."""
    data = bytes(data)
    check_header(data, PduType.ENTITY_STATE_UPDATE, ESU_FIXED_SIZE)
    n = data[19]
    if len(data) != ESU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * n:
        raise DisError(f"length {len(data)} does not match {n} variable parameters ({72 + 16 * n})", 19)
    b = _BODY.unpack_from(data, HEADER_SIZE)
    params = unpack_params(data, ESU_FIXED_SIZE, n)
    return EntityStateUpdatePdu(
        entity_id=EntityId(*b[0:3]),
        padding1=b[3],
        velocity=b[5:8],
        location=b[8:11],
        orientation=b[11:14],
        appearance=b[14],
        variable_parameters=params,
        **header_fields(data),
    )


def decode_entity_updates(u8: NDArray[np.uint8], offsets: NDArray[np.int64]) -> EntityStateBatch:
    """Many validated updates at once (one gather, as :func:`~protocol.dis.batch.decode_entity_states`), as
    *partial* Entity State records: the header, entity id and the updated fields; the rest is zero until
    :func:`resolve_updates` fills it in. ``pdu_type`` stays 67."""
    offsets = np.asarray(offsets, np.int64)
    n = offsets.shape[0]
    recs = np.zeros(n, ESPDU_DTYPE)
    if n == 0:
        return EntityStateBatch(recs, *gather_params(u8, offsets, np.zeros(0, np.int64)))
    wire = sliding_window_view(u8, ESU_FIXED_SIZE)[offsets].view(ESU_WIRE_DTYPE).reshape(n)
    for name in ("version", "exercise", "pdu_type", "family", "timestamp", "length", "pdu_status", "padding",
                 "entity_id", "num_params", *UPDATED_FIELDS):  # fmt: skip
        recs[name] = wire[name]
    return EntityStateBatch(recs, *gather_params(u8, offsets + ESU_FIXED_SIZE, recs["num_params"]))


def entity_keys(entity_id: NDArray[np.void]) -> NDArray[np.uint64]:
    """One u64 per DIS entity id (site, application, entity)."""
    site: NDArray[np.uint64] = entity_id["site"].astype(np.uint64)
    app: NDArray[np.uint64] = entity_id["application"].astype(np.uint64)
    entity: NDArray[np.uint64] = entity_id["entity"].astype(np.uint64)
    return (site << np.uint64(32)) | (app << np.uint64(16)) | entity


@dataclass
class UpdateBases:
    """The last full Entity State record of every entity seen (a gateway keeps one across bursts)."""

    keys: NDArray[np.uint64] = field(default_factory=lambda: np.zeros(0, np.uint64))  # sorted
    records: NDArray[np.void] = field(default_factory=lambda: np.zeros(0, ESPDU_DTYPE))

    def learn(self, records: NDArray[np.void]) -> None:
        """Remember ``records`` (in receipt order: the last of each entity wins)."""
        if not len(records):
            return
        keys = np.concatenate([self.keys, entity_keys(records["entity_id"])])
        recs = np.concatenate([self.records, records])
        last = len(keys) - 1 - np.unique(keys[::-1], return_index=True)[1]  # sorted by key
        self.keys, self.records = keys[last], recs[last]

    def lookup(self, keys: NDArray[np.uint64]) -> NDArray[np.int64]:
        """Index into ``records`` of each key, -1 for entities not seen."""
        if not len(self.keys):
            return np.full(len(keys), -1, np.int64)
        pos = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        return np.where(self.keys[pos] == keys, pos, -1)


def resolve_updates(
    full: EntityStateBatch,
    full_rows: NDArray[np.int64],
    updates: EntityStateBatch,
    update_rows: NDArray[np.int64],
    bases: UpdateBases | None = None,
) -> tuple[EntityStateBatch, NDArray[np.bool_]]:
    """Each update on top of its entity's last full record before it (``*_rows``: positions in receipt
    order), else the one in ``bases`` (earlier bursts): (the resolved records, which updates were placed).
    A resolved record is the base with the update's header, updated fields and variable parameters."""
    n = len(updates)
    if n == 0:
        return updates, np.zeros(0, bool)
    ukeys = entity_keys(updates.records["entity_id"])
    fkeys = entity_keys(full.records["entity_id"])
    _, kid = np.unique(np.concatenate([fkeys, ukeys]), return_inverse=True)
    stride = int(max(full_rows.max(initial=0), update_rows.max(initial=0))) + 1
    f_comp = kid[: len(fkeys)].astype(np.int64) * stride + full_rows
    u_comp = kid[len(fkeys) :].astype(np.int64) * stride + update_rows
    order = np.argsort(f_comp, kind="stable")
    at = np.searchsorted(f_comp[order], u_comp) - 1
    cand = order[np.maximum(at, 0)] if len(order) else np.zeros(n, np.int64)
    here = (at >= 0) & (fkeys[cand] == ukeys) if len(order) else np.zeros(n, bool)
    earlier = bases.lookup(ukeys) if bases is not None else np.full(n, -1, np.int64)
    placed = here | (earlier >= 0)
    out = np.zeros(n, ESPDU_DTYPE)
    if here.any():
        out[here] = full.records[cand[here]]
    if (~here & placed).any():
        assert bases is not None
        out[~here & placed] = bases.records[earlier[~here & placed]]
    upd = updates.records
    for name in ("version", "exercise", "pdu_type", "family", "timestamp", "length", "pdu_status", "padding",
                 "entity_id", "num_params", *UPDATED_FIELDS):  # fmt: skip
        out[name] = upd[name]
    resolved = EntityStateBatch(out, updates.params, updates.param_start)
    return resolved.select(placed), placed
