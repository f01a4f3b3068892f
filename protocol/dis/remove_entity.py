"""Remove Entity PDUs (type 12, simulation management): a simulation manager takes an entity out of the
exercise. TTES removes that entity's soldier at once instead of waiting out the DIS timeout.

Layout (28 bytes, big-endian, DIS 5, 6 and 7 alike): the 12-byte header, originating entity id @12 (the
manager), receiving entity id @18 (the entity to remove; 65535 in a field is "all", as in IEEE 1278.1's
ALL_SITES / ALL_APPLIC / ALL_ENTITIES), request id u32 @24.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from protocol.dis.entity_state import NO_ENTITY, EntityId
from protocol.dis.errors import DisError
from protocol.dis.pdu import (
    HEADER,
    Family,
    PduType,
    check_encodable,
    check_header,
    header_fields,
)
from protocol.dis.warfare import WeaponEvent

REMOVE_ENTITY_SIZE = 28
ALL = 0xFFFF  # a receiving-id field that matches every site / application / entity
_PDU = struct.Struct(">BBBBIHBB HHH HHH I")
assert _PDU.size == REMOVE_ENTITY_SIZE
assert HEADER.size == 12


@dataclass(frozen=True, slots=True)
class RemoveEntityPdu:
    """One Remove Entity PDU, byte-exact."""

    originator: EntityId = NO_ENTITY
    receiver: EntityId = NO_ENTITY  # the entity to remove
    request_id: int = 0
    version: int = 7
    exercise: int = 1
    timestamp: int = 0
    pdu_status: int = 0
    padding: int = 0
    family: int = int(Family.SIMULATION_MANAGEMENT)


@dataclass(frozen=True, slots=True)
class RemoveEntity:
    """The event TTES takes from a Remove Entity PDU: remove ``entity`` (fields of 65535 match all)."""

    t: float  # receipt time (s, the log's clock)
    entity: EntityId
    originator: EntityId
    request_id: int
    kind: str = "remove_entity"

    def to_json(self) -> dict[str, object]:
        return {"kind": self.kind, "t": self.t, "entity": list(self.entity),
                "originator": list(self.originator), "request_id": self.request_id}  # fmt: skip


DisEvent = WeaponEvent | RemoveEntity  # the events of a log: Fire, Detonation, Remove Entity


def encode_remove_entity(pdu: RemoveEntityPdu) -> bytes:
    check_encodable(pdu.version)
    try:
        return _PDU.pack(pdu.version, pdu.exercise, int(PduType.REMOVE_ENTITY), pdu.family, pdu.timestamp,
                         REMOVE_ENTITY_SIZE, pdu.pdu_status, pdu.padding, *pdu.originator, *pdu.receiver,
                         pdu.request_id)  # fmt: skip
    except (struct.error, TypeError, OverflowError) as exc:
        raise DisError(f"remove entity field out of range: {exc}", 0) from None


def decode_remove_entity(data: bytes | memoryview) -> RemoveEntityPdu:
    """Decode exactly one Remove Entity PDU; :class:`DisError` with the offset of the bad field."""
    data = bytes(data)
    check_header(data, PduType.REMOVE_ENTITY, REMOVE_ENTITY_SIZE)
    if len(data) != REMOVE_ENTITY_SIZE:
        raise DisError(f"remove_entity PDU of {len(data)} bytes, not {REMOVE_ENTITY_SIZE}", 8)
    v = _PDU.unpack(data)
    return RemoveEntityPdu(EntityId(*v[8:11]), EntityId(*v[11:14]), v[14], **header_fields(data))


def remove_event(data: bytes | memoryview, t: float = 0.0) -> RemoveEntity:
    """The event of a Remove Entity PDU (:class:`DisError` for bad bytes)."""
    pdu = decode_remove_entity(data)
    return RemoveEntity(t, pdu.receiver, pdu.originator, pdu.request_id)
