"""Entity State PDU codec, one PDU at a time, byte-exact for DIS 5, 6 and 7.

Layout after the 12-byte header (offsets from the PDU start, big-endian):

====== ===== ====================================================================================
offset bytes field
====== ===== ====================================================================================
12     6     entity id (site, application, entity) u16 each
18     1     force id
19     1     number of variable-parameter (articulation) records N
20     8     entity type (kind, domain, country u16, category, subcategory, specific, extra)
28     8     alternative entity type
36     12    linear velocity, 3 x f32, m/s, world (ECEF)
48     24    location, 3 x f64, m, ECEF
72     12    orientation psi, theta, phi, 3 x f32, rad
84     4     appearance u32
88     1     dead-reckoning algorithm
89     15    other dead-reckoning parameters
104    12    linear acceleration, 3 x f32
116    12    angular velocity, 3 x f32, rad/s, body axes
128    1     marking character set
129    11    marking characters
140    4     capabilities u32
144    16N   variable-parameter records
====== ===== ====================================================================================

The batch decoder (:mod:`protocol.dis.batch`) reads the same layout for many PDUs at once.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import NamedTuple

from protocol.dis.errors import DisError
from protocol.dis.pdu import HEADER, HEADER_SIZE, SUPPORTED_VERSIONS, Family, PduType, check_encodable

ESPDU_FIXED_SIZE = 144
VARIABLE_PARAMETER_SIZE = 16
_BODY = struct.Struct(">HHHBB BBHBBBB BBHBBBB 3f 3d 3f I B15s 3f 3f B11s I")
_VARPARAM = struct.Struct(">B15s")
_ARTICULATED = struct.Struct(">BBHIfI")
assert HEADER.size + _BODY.size == ESPDU_FIXED_SIZE


class EntityId(NamedTuple):
    site: int = 0
    application: int = 0
    entity: int = 0


class EntityType(NamedTuple):
    kind: int = 0
    domain: int = 0
    country: int = 0
    category: int = 0
    subcategory: int = 0
    specific: int = 0
    extra: int = 0


Vec3 = tuple[float, float, float]
NO_ENTITY = EntityId()
NO_TYPE = EntityType()


@dataclass(frozen=True, slots=True)
class VariableParameter:
    """One 16-byte variable-parameter record (DIS 7) / articulation parameter (DIS 5/6), kept raw.

    ``record_type`` is byte 0 (0 articulated part, 1 attached part, ...); ``data`` the other 15 bytes.
    The properties read the articulated-part layout: change u8, attached-to u16, parameter type u32,
    value f32 (+ 4 bytes that DIS 7 calls padding and DIS 5/6 the low half of a 64-bit value).
    """

    record_type: int = 0
    data: bytes = bytes(15)

    @classmethod
    def articulated(
        cls, parameter_type: int, value: float, change: int = 0, attached_to: int = 0, record_type: int = 0
    ) -> VariableParameter:
        raw = _ARTICULATED.pack(record_type, change, attached_to, parameter_type, value, 0)
        return cls(raw[0], raw[1:])

    def pack(self) -> bytes:
        if len(self.data) != 15:
            raise DisError(f"variable parameter data must be 15 bytes, not {len(self.data)}")
        return _VARPARAM.pack(self.record_type, self.data)

    @property
    def change(self) -> int:
        return self.data[0]

    @property
    def attached_to(self) -> int:
        return int.from_bytes(self.data[1:3], "big")

    @property
    def parameter_type(self) -> int:
        return int.from_bytes(self.data[3:7], "big")

    @property
    def value(self) -> float:
        return struct.unpack(">f", self.data[7:11])[0]


@dataclass(frozen=True, slots=True)
class EntityStatePdu:
    """An Entity State PDU. Defaults give a DIS 7 lifeform standing still at the ECEF origin."""

    entity_id: EntityId = NO_ENTITY
    force_id: int = 0
    entity_type: EntityType = NO_TYPE
    alt_entity_type: EntityType = NO_TYPE
    velocity: Vec3 = (0.0, 0.0, 0.0)
    location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: Vec3 = (0.0, 0.0, 0.0)
    appearance: int = 0
    dr_algorithm: int = 1
    dr_other: bytes = bytes(15)
    acceleration: Vec3 = (0.0, 0.0, 0.0)
    angular_velocity: Vec3 = (0.0, 0.0, 0.0)
    marking_charset: int = 1
    marking: bytes = bytes(11)  # raw 11 bytes; see marking_text
    capabilities: int = 0
    variable_parameters: tuple[VariableParameter, ...] = field(default_factory=tuple)
    version: int = 7
    exercise: int = 1
    timestamp: int = 0
    pdu_status: int = 0  # DIS 7 PDU status; in DIS 5/6 the first padding byte
    padding: int = 0
    family: int = int(Family.ENTITY_INFORMATION)  # protocol family byte, kept for byte-exact round trips

    @property
    def length(self) -> int:
        return ESPDU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * len(self.variable_parameters)

    @property
    def marking_text(self) -> str:
        """The marking as text: Latin-1, cut at the first NUL (never fails)."""
        return self.marking.split(b"\0", 1)[0].decode("latin-1")


def make_marking(text: str) -> bytes:
    """11 marking bytes from text (Latin-1, NUL padded); :class:`DisError` if it does not fit."""
    try:
        raw = text.encode("latin-1")
    except UnicodeEncodeError:
        raise DisError(f"marking {text!r} is not Latin-1", 129) from None
    if len(raw) > 11:
        raise DisError(f"marking {text!r} longer than 11 bytes", 129)
    return raw.ljust(11, b"\0")


def encode_entity_state(pdu: EntityStatePdu) -> bytes:
    """The PDU's bytes (144 + 16 N). Raises :class:`DisError` for values that do not fit their fields."""
    n = len(pdu.variable_parameters)
    check_encodable(pdu.version, n)
    if len(pdu.dr_other) != 15:
        raise DisError(f"dr_other must be 15 bytes, not {len(pdu.dr_other)}", 89)
    marking = pdu.marking.ljust(11, b"\0")
    if len(marking) != 11:
        raise DisError(f"marking must be at most 11 bytes, not {len(pdu.marking)}", 129)
    try:
        head = HEADER.pack(
            pdu.version,
            pdu.exercise,
            int(PduType.ENTITY_STATE),
            pdu.family,
            pdu.timestamp,
            pdu.length,
            pdu.pdu_status,
            pdu.padding,
        )
        body = _BODY.pack(
            *pdu.entity_id,
            pdu.force_id,
            n,
            *pdu.entity_type,
            *pdu.alt_entity_type,
            *pdu.velocity,
            *pdu.location,
            *pdu.orientation,
            pdu.appearance,
            pdu.dr_algorithm,
            pdu.dr_other,
            *pdu.acceleration,
            *pdu.angular_velocity,
            pdu.marking_charset,
            marking,
            pdu.capabilities,
        )
    except (struct.error, TypeError, OverflowError) as exc:
        raise DisError(f"entity state field out of range: {exc}", 0) from None
    return head + body + b"".join(p.pack() for p in pdu.variable_parameters)


def check_entity_state_header(data: bytes | memoryview) -> int:
    """Validate version, type, length field and record count; return N. Raises :class:`DisError`."""
    if len(data) < HEADER_SIZE:
        raise DisError(f"truncated header: {len(data)} bytes", len(data))
    version, pdu_type, length = data[0], data[2], (data[8] << 8) | data[9]
    if pdu_type != PduType.ENTITY_STATE:
        raise DisError(f"PDU type {pdu_type} is not Entity State (1)", 2)
    if version not in SUPPORTED_VERSIONS:
        raise DisError(f"protocol version {version} not supported (5, 6, 7)", 0)
    if length != len(data):
        raise DisError(f"length field {length} but {len(data)} bytes", 8)
    if length < ESPDU_FIXED_SIZE:
        raise DisError(f"Entity State PDU of {length} bytes is shorter than {ESPDU_FIXED_SIZE}", 8)
    n = data[19]
    if length != ESPDU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * n:
        raise DisError(f"length {length} does not match {n} variable parameters ({144 + 16 * n})", 19)
    return n


def unpack_params(data: bytes, first: int, n: int) -> tuple[VariableParameter, ...]:
    """The ``n`` 16-byte variable-parameter records from byte ``first`` (Entity State and its Update)."""
    return tuple(
        VariableParameter(*_VARPARAM.unpack_from(data, first + VARIABLE_PARAMETER_SIZE * i)) for i in range(n)
    )


def decode_entity_state(data: bytes | memoryview) -> EntityStatePdu:
    """Decode exactly one Entity State PDU (the buffer must be the whole PDU)."""
    data = bytes(data)
    n = check_entity_state_header(data)
    h = HEADER.unpack_from(data, 0)
    b = _BODY.unpack_from(data, HEADER_SIZE)
    params = unpack_params(data, ESPDU_FIXED_SIZE, n)
    return EntityStatePdu(
        entity_id=EntityId(*b[0:3]),
        force_id=b[3],
        entity_type=EntityType(*b[5:12]),
        alt_entity_type=EntityType(*b[12:19]),
        velocity=b[19:22],
        location=b[22:25],
        orientation=b[25:28],
        appearance=b[28],
        dr_algorithm=b[29],
        dr_other=b[30],
        acceleration=b[31:34],
        angular_velocity=b[34:37],
        marking_charset=b[37],
        marking=b[38],
        capabilities=b[39],
        variable_parameters=params,
        version=h[0],
        exercise=h[1],
        timestamp=h[4],
        pdu_status=h[6],
        padding=h[7],
        family=h[3],
    )


def is_finite_state(pdu: EntityStatePdu) -> bool:
    """True when every float field is finite (a decoder keeps NaN/inf; consumers may want to drop them)."""
    return all(
        math.isfinite(v)
        for v in (*pdu.velocity, *pdu.location, *pdu.orientation, *pdu.acceleration, *pdu.angular_velocity)
    )
