"""One entry point per direction for the PDUs TTES reads: dispatch on the header's PDU type."""

from __future__ import annotations

from collections.abc import Callable

from protocol.dis.entity_state import EntityStatePdu, decode_entity_state, encode_entity_state
from protocol.dis.entity_update import EntityStateUpdatePdu, decode_entity_update, encode_entity_update
from protocol.dis.errors import DisError
from protocol.dis.pdu import HEADER_SIZE, PduType, pdu_type_name
from protocol.dis.remove_entity import RemoveEntityPdu, decode_remove_entity, encode_remove_entity
from protocol.dis.warfare import (
    DetonationPdu,
    FirePdu,
    decode_detonation,
    decode_fire,
    encode_detonation,
    encode_fire,
)

Pdu = EntityStatePdu | FirePdu | DetonationPdu | RemoveEntityPdu | EntityStateUpdatePdu
_DECODE: dict[int, Callable[[bytes], Pdu]] = {
    PduType.ENTITY_STATE: decode_entity_state,
    PduType.FIRE: decode_fire,
    PduType.DETONATION: decode_detonation,
    PduType.REMOVE_ENTITY: decode_remove_entity,
    PduType.ENTITY_STATE_UPDATE: decode_entity_update,
}


def decode_pdu(data: bytes | memoryview) -> Pdu:
    """Decode one whole PDU of a type TTES reads; :class:`DisError` for anything else."""
    data = bytes(data)
    if len(data) < HEADER_SIZE:
        raise DisError(f"truncated header: {len(data)} bytes", len(data))
    pdu_type = data[2]
    decode = _DECODE.get(pdu_type)
    if decode is None:
        raise DisError(f"PDU type {pdu_type} ({pdu_type_name(pdu_type)}) is not decoded here", 2)
    return decode(data)


def encode_pdu(pdu: Pdu) -> bytes:
    if isinstance(pdu, EntityStatePdu):
        return encode_entity_state(pdu)
    if isinstance(pdu, FirePdu):
        return encode_fire(pdu)
    if isinstance(pdu, DetonationPdu):
        return encode_detonation(pdu)
    if isinstance(pdu, RemoveEntityPdu):
        return encode_remove_entity(pdu)
    if isinstance(pdu, EntityStateUpdatePdu):
        return encode_entity_update(pdu)
    raise TypeError(f"not a PDU: {type(pdu).__name__}")
