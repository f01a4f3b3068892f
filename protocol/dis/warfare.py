"""Fire and Detonation PDUs, decoded far enough to raise events (shooter, target, munition, location).

Fire (96 bytes): header, firing entity id @12, target entity id @18, munition id @24 (DIS 7: munition
expendable id), event id @30, fire mission index u32 @36, location f64 x3 @40, munition descriptor @64
(entity type, warhead u16, fuse u16, quantity u16, rate u16), velocity f32 x3 @80, range f32 @92.

Detonation (104 + 16 N bytes): header, firing entity @12, target entity @18, munition id @24 (DIS 7:
exploding entity id), event id @30, velocity f32 x3 @36, location f64 x3 @48, munition descriptor @72,
location in entity coordinates f32 x3 @88, detonation result u8 @100, N u8 @101, padding u16 @102,
variable-parameter records @104.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from protocol.dis.entity_state import (
    NO_ENTITY,
    NO_TYPE,
    VARIABLE_PARAMETER_SIZE,
    EntityId,
    EntityType,
    VariableParameter,
)
from protocol.dis.errors import DisError
from protocol.dis.pdu import (
    HEADER,
    HEADER_SIZE,
    Family,
    PduType,
    check_encodable,
    check_header,
)

FIRE_SIZE = 96
DETONATION_FIXED_SIZE = 104
_FIRE = struct.Struct(">HHH HHH HHH HHH I 3d BBHBBBB HHHH 3f f")
_DETONATION = struct.Struct(">HHH HHH HHH HHH 3f 3d BBHBBBB HHHH 3f BBH")
assert HEADER_SIZE + _FIRE.size == FIRE_SIZE
assert HEADER_SIZE + _DETONATION.size == DETONATION_FIXED_SIZE

Vec3 = tuple[float, float, float]


class DetonationResult:
    """A few SISO-REF-010 detonation results (the field is an open u8 enumeration)."""

    OTHER = 0
    ENTITY_IMPACT = 1
    ENTITY_PROXIMATE_DETONATION = 2
    GROUND_IMPACT = 3
    GROUND_PROXIMATE_DETONATION = 4
    DETONATION = 5
    NONE = 6


@dataclass(frozen=True, slots=True)
class MunitionDescriptor:
    munition: EntityType = NO_TYPE
    warhead: int = 0
    fuse: int = 0
    quantity: int = 1
    rate: int = 0


_NO_DESCRIPTOR = MunitionDescriptor()


@dataclass(frozen=True, slots=True)
class FirePdu:
    shooter: EntityId = NO_ENTITY
    target: EntityId = NO_ENTITY
    munition_id: EntityId = NO_ENTITY
    event_id: EntityId = NO_ENTITY  # (site, application, event number)
    fire_mission_index: int = 0
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    descriptor: MunitionDescriptor = _NO_DESCRIPTOR
    velocity: Vec3 = (0.0, 0.0, 0.0)
    range: float = 0.0
    version: int = 7
    exercise: int = 1
    timestamp: int = 0
    pdu_status: int = 0
    padding: int = 0
    family: int = int(Family.WARFARE)


@dataclass(frozen=True, slots=True)
class DetonationPdu:
    shooter: EntityId = NO_ENTITY
    target: EntityId = NO_ENTITY
    munition_id: EntityId = NO_ENTITY  # DIS 7: the exploding entity
    event_id: EntityId = NO_ENTITY
    velocity: Vec3 = (0.0, 0.0, 0.0)
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    descriptor: MunitionDescriptor = _NO_DESCRIPTOR
    entity_location: Vec3 = (0.0, 0.0, 0.0)
    result: int = DetonationResult.ENTITY_IMPACT
    variable_parameters: tuple[VariableParameter, ...] = field(default_factory=tuple)
    version: int = 7
    exercise: int = 1
    timestamp: int = 0
    pdu_status: int = 0
    padding: int = 0
    family: int = int(Family.WARFARE)
    body_padding: int = 0


def _header(pdu: FirePdu | DetonationPdu, pdu_type: PduType, length: int) -> bytes:
    check_encodable(pdu.version)
    return HEADER.pack(
        pdu.version,
        pdu.exercise,
        int(pdu_type),
        pdu.family,
        pdu.timestamp,
        length,
        pdu.pdu_status,
        pdu.padding,
    )


def encode_fire(pdu: FirePdu) -> bytes:
    d = pdu.descriptor
    try:
        return _header(pdu, PduType.FIRE, FIRE_SIZE) + _FIRE.pack(
            *pdu.shooter,
            *pdu.target,
            *pdu.munition_id,
            *pdu.event_id,
            pdu.fire_mission_index,
            *pdu.location,
            *d.munition,
            d.warhead,
            d.fuse,
            d.quantity,
            d.rate,
            *pdu.velocity,
            pdu.range,
        )
    except (struct.error, TypeError, OverflowError) as exc:
        raise DisError(f"fire field out of range: {exc}", 0) from None


def encode_detonation(pdu: DetonationPdu) -> bytes:
    d = pdu.descriptor
    n = len(pdu.variable_parameters)
    length = DETONATION_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * n
    try:
        return (
            _header(pdu, PduType.DETONATION, length)
            + _DETONATION.pack(
                *pdu.shooter,
                *pdu.target,
                *pdu.munition_id,
                *pdu.event_id,
                *pdu.velocity,
                *pdu.location,
                *d.munition,
                d.warhead,
                d.fuse,
                d.quantity,
                d.rate,
                *pdu.entity_location,
                pdu.result,
                n,
                pdu.body_padding,
            )
            + b"".join(p.pack() for p in pdu.variable_parameters)
        )
    except (struct.error, TypeError, OverflowError) as exc:
        raise DisError(f"detonation field out of range: {exc}", 0) from None


def decode_fire(data: bytes | memoryview) -> FirePdu:
    data = bytes(data)
    check_header(data, PduType.FIRE, FIRE_SIZE)
    if len(data) != FIRE_SIZE:
        raise DisError(f"fire PDU of {len(data)} bytes (expected {FIRE_SIZE})", 8)
    h = HEADER.unpack_from(data)
    b = _FIRE.unpack_from(data, HEADER_SIZE)
    return FirePdu(
        shooter=EntityId(*b[0:3]),
        target=EntityId(*b[3:6]),
        munition_id=EntityId(*b[6:9]),
        event_id=EntityId(*b[9:12]),
        fire_mission_index=b[12],
        location=b[13:16],
        descriptor=MunitionDescriptor(EntityType(*b[16:23]), *b[23:27]),
        velocity=b[27:30],
        range=b[30],
        version=h[0],
        exercise=h[1],
        timestamp=h[4],
        pdu_status=h[6],
        padding=h[7],
        family=h[3],
    )


def decode_detonation(data: bytes | memoryview) -> DetonationPdu:
    data = bytes(data)
    check_header(data, PduType.DETONATION, DETONATION_FIXED_SIZE)
    h = HEADER.unpack_from(data)
    b = _DETONATION.unpack_from(data, HEADER_SIZE)
    n = b[33]
    if len(data) != DETONATION_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * n:
        raise DisError(f"length {len(data)} does not match {n} variable parameters", 101)
    params = tuple(
        VariableParameter(data[o], data[o + 1 : o + 16])
        for o in range(DETONATION_FIXED_SIZE, len(data), VARIABLE_PARAMETER_SIZE)
    )
    return DetonationPdu(
        shooter=EntityId(*b[0:3]),
        target=EntityId(*b[3:6]),
        munition_id=EntityId(*b[6:9]),
        event_id=EntityId(*b[9:12]),
        velocity=b[12:15],
        location=b[15:18],
        descriptor=MunitionDescriptor(EntityType(*b[18:25]), *b[25:29]),
        entity_location=b[29:32],
        result=b[32],
        variable_parameters=params,
        body_padding=b[34],
        version=h[0],
        exercise=h[1],
        timestamp=h[4],
        pdu_status=h[6],
        padding=h[7],
        family=h[3],
    )


@dataclass(frozen=True, slots=True)
class WeaponEvent:
    """What TTES needs from a Fire or Detonation PDU: who fired at whom, with what, where, when."""

    kind: str  # "fire" or "detonation"
    t: float  # receipt time (s, the log's clock)
    shooter: EntityId
    target: EntityId
    munition: EntityType
    location: tuple[float, float, float]  # ECEF m
    event_id: EntityId
    result: int | None = None  # detonations only
    range: float | None = None  # fire only

    def to_json(self) -> dict[str, object]:
        return {
            "kind": self.kind,
            "t": self.t,
            "shooter": list(self.shooter),
            "target": list(self.target),
            "munition": list(self.munition),
            "location": list(self.location),
            "event": list(self.event_id),
            "result": self.result,
            "range": self.range,
        }


def weapon_event(data: bytes | memoryview, t: float = 0.0) -> WeaponEvent:
    """The event of a Fire or Detonation PDU; :class:`DisError` for anything else or bad bytes."""
    data = bytes(data)
    if len(data) >= 3 and data[2] == PduType.FIRE:
        f = decode_fire(data)
        return WeaponEvent(
            "fire", t, f.shooter, f.target, f.descriptor.munition, f.location, f.event_id, range=f.range
        )
    if len(data) >= 3 and data[2] == PduType.DETONATION:
        d = decode_detonation(data)
        return WeaponEvent(
            "detonation",
            t,
            d.shooter,
            d.target,
            d.descriptor.munition,
            d.location,
            d.event_id,
            result=d.result,
        )
    raise DisError("not a Fire or Detonation PDU", 2)
