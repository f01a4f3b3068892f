"""One entry point per direction for the PDUs TTES reads: dispatch on the header's PDU type."""

from __future__ import annotations

from protocol.dis.entity_state import EntityStatePdu, decode_entity_state, encode_entity_state
from protocol.dis.errors import DisError
from protocol.dis.pdu import HEADER_SIZE, PduType, pdu_type_name
from protocol.dis.warfare import (
    DetonationPdu,
    FirePdu,
    decode_detonation,
    decode_fire,
    encode_detonation,
    encode_fire,
)

Pdu = EntityStatePdu | FirePdu | DetonationPdu


def decode_pdu(data: bytes | memoryview) -> Pdu:
    """Decode one whole Entity State, Fire or Detonation PDU; :class:`DisError` for anything else."""
    data = bytes(data)
    if len(data) < HEADER_SIZE:
        raise DisError(f"truncated header: {len(data)} bytes", len(data))
    pdu_type = data[2]
    if pdu_type == PduType.ENTITY_STATE:
        return decode_entity_state(data)
    if pdu_type == PduType.FIRE:
        return decode_fire(data)
    if pdu_type == PduType.DETONATION:
        return decode_detonation(data)
    raise DisError(f"PDU type {pdu_type} ({pdu_type_name(pdu_type)}) is not decoded here", 2)


def encode_pdu(pdu: Pdu) -> bytes:
    if isinstance(pdu, EntityStatePdu):
        return encode_entity_state(pdu)
    if isinstance(pdu, FirePdu):
        return encode_fire(pdu)
    if isinstance(pdu, DetonationPdu):
        return encode_detonation(pdu)
    raise TypeError(f"not a PDU: {type(pdu).__name__}")
