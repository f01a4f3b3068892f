"""CIGI 3.3 packets (SISO-STD-013-2014), sans I/O: host → IG packets, and the IG's Start of Frame.

An image generator that speaks the Common Image Generator Interface can show our soldiers without knowing
Jack: per frame the host sends one *message* (a UDP datagram) that starts with IG Control, then Entity
Control for each soldier and Short Articulated Part Control for its joint DOFs (``docs/CIGI.md`` quotes the
sizes and offsets). Packets are written big-endian; CIGI 3 lets the sender use its own byte order and the
receiver tells which from IG Control's magic number (0x8000), so :func:`decode_message` reads both.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

MAJOR_VERSION = 3
MINOR_VERSION = 3
MAGIC = 0x8000
DEFAULT_PORT = 8004  # the IG's port most CIGI implementations use (not registered)
MAX_PART_ID = 255  # articulated part IDs are one byte
Order = Literal[">", "<"]


class PacketId(IntEnum):
    IG_CONTROL = 1
    ENTITY_CONTROL = 2
    ARTICULATED_PART = 6
    SHORT_ARTICULATED_PART = 7


class DofSelect(IntEnum):
    """Short Articulated Part Control's DOF Select (which of the part's six values a float sets)."""

    NOT_USED = 0
    X_OFFSET = 1
    Y_OFFSET = 2
    Z_OFFSET = 3
    YAW = 4
    PITCH = 5
    ROLL = 6


class CigiError(ValueError):
    """A CIGI message that cannot be read (truncated, a size not the standard's, no IG Control)."""


@dataclass(frozen=True)
class IgControl:
    """IG Control (opcode 1, 24 bytes): the first packet of every host message."""

    host_frame: int
    timestamp: int = 0  # 10 µs ticks
    timestamp_valid: bool = False
    database: int = 0  # int8; 0 = no change
    ig_mode: int = 1  # 0 standby, 1 operate, 2 debug
    interpolation: bool = False
    last_ig_frame: int = 0


@dataclass(frozen=True)
class EntityControl:
    """Entity Control (opcode 2, 48 bytes): one entity's state, type and geodetic or local placement."""

    entity_id: int
    entity_type: int
    x: float  # latitude or, for a child, X offset (metres): here the database's local X (north)
    y: float  # longitude or Y offset (east)
    z: float  # altitude or Z offset (metres, up)
    roll: float = 0.0  # degrees
    pitch: float = 0.0
    yaw: float = 0.0
    state: int = 1  # 0 inactive/standby, 1 active, 2 destroyed
    attached: bool = False
    collision: bool = False
    inherit_alpha: bool = False
    clamp: int = 0  # 0 none, 1 non-conformal, 2 conformal
    alpha: int = 255
    parent_id: int = 0


@dataclass(frozen=True)
class ArticulatedPart:
    """Articulated Part Control (opcode 6, 32 bytes): up to six values of one part, each with an enable."""

    entity_id: int
    part_id: int
    enabled: bool = True
    x: float | None = None  # metres; None = not enabled
    y: float | None = None
    z: float | None = None
    roll: float | None = None  # degrees
    pitch: float | None = None
    yaw: float | None = None


@dataclass(frozen=True)
class ShortArticulatedPart:
    """Short Articulated Part Control (opcode 7, 16 bytes): one value of each of two parts."""

    entity_id: int
    part1: int
    part2: int
    select1: DofSelect
    select2: DofSelect
    value1: float
    value2: float
    enable1: bool = True
    enable2: bool = True


Packet = IgControl | EntityControl | ArticulatedPart | ShortArticulatedPart

_FORMATS = {  # after the two-byte header (opcode, size)
    PacketId.IG_CONTROL: "BbBxHIII4x",
    PacketId.ENTITY_CONTROL: "HBBBxHHfffddd",
    PacketId.ARTICULATED_PART: "HBB2xffffff",
    PacketId.SHORT_ARTICULATED_PART: "HBBBxff",
}
SIZES = {pid: 2 + struct.calcsize(">" + fmt) for pid, fmt in _FORMATS.items()}
assert SIZES == {
    PacketId.IG_CONTROL: 24,
    PacketId.ENTITY_CONTROL: 48,
    PacketId.ARTICULATED_PART: 32,
    PacketId.SHORT_ARTICULATED_PART: 16,
}
_STRUCTS = {(pid, o): struct.Struct(o + "BB" + fmt) for pid, fmt in _FORMATS.items() for o in (">", "<")}
_ART_FIELDS = ("x", "y", "z", "roll", "pitch", "yaw")


def _struct(pid: PacketId, order: Order) -> struct.Struct:
    return _STRUCTS[pid, order]


def _pack_ig(p: IgControl, order: Order) -> bytes:
    flags = (p.ig_mode & 3) | p.timestamp_valid << 2 | p.interpolation << 3 | MINOR_VERSION << 4
    return _struct(PacketId.IG_CONTROL, order).pack(
        1, 24, MAJOR_VERSION, p.database, flags, MAGIC, p.host_frame, p.timestamp, p.last_ig_frame
    )


def _pack_entity(p: EntityControl, order: Order) -> bytes:
    flags = (p.state & 3) | p.attached << 2 | p.collision << 3 | p.inherit_alpha << 4 | (p.clamp & 3) << 5
    return _struct(PacketId.ENTITY_CONTROL, order).pack(
        2, 48, p.entity_id, flags, 0, p.alpha, p.entity_type, p.parent_id,
        p.roll, p.pitch, p.yaw, p.x, p.y, p.z,
    )  # fmt: skip


def _pack_part(p: ArticulatedPart, order: Order) -> bytes:
    values = [getattr(p, name) for name in _ART_FIELDS]
    flags = p.enabled | sum((v is not None) << (i + 1) for i, v in enumerate(values))
    floats = [0.0 if v is None else v for v in values]
    return _struct(PacketId.ARTICULATED_PART, order).pack(6, 32, p.entity_id, p.part_id, flags, *floats)


def _pack_short(p: ShortArticulatedPart, order: Order) -> bytes:
    flags = (p.select1 & 7) | (p.select2 & 7) << 3 | p.enable1 << 6 | p.enable2 << 7
    return _struct(PacketId.SHORT_ARTICULATED_PART, order).pack(
        7, 16, p.entity_id, p.part1, p.part2, flags, p.value1, p.value2
    )


def encode(packet: Packet, order: Order = ">") -> bytes:
    """One packet's bytes (big-endian unless ``order`` is ``"<"``); CigiError for a field out of its range."""
    try:
        if isinstance(packet, IgControl):
            return _pack_ig(packet, order)
        if isinstance(packet, EntityControl):
            return _pack_entity(packet, order)
        if isinstance(packet, ArticulatedPart):
            return _pack_part(packet, order)
        return _pack_short(packet, order)
    except struct.error as exc:
        raise CigiError(f"{type(packet).__name__}: {exc}") from None


def _unpack_ig(v: tuple[int | float, ...]) -> IgControl:
    _, _, major, db, flags, magic, frame, stamp, last = (int(x) for x in v)
    if major != MAJOR_VERSION or magic != MAGIC:
        raise CigiError(f"IG Control of CIGI {major} (magic {magic:#06x}), not CIGI 3")
    return IgControl(frame, stamp, bool(flags & 4), db, flags & 3, bool(flags & 8), last)


def _unpack_entity(v: tuple[int | float, ...]) -> EntityControl:
    eid, flags, _anim, alpha, etype, parent = (int(x) for x in v[2:8])
    roll, pitch, yaw, x, y, z = (float(f) for f in v[8:])
    return EntityControl(
        eid, etype, x, y, z, roll, pitch, yaw, flags & 3, bool(flags & 4), bool(flags & 8),
        bool(flags & 16), (flags >> 5) & 3, alpha, parent,
    )  # fmt: skip


def _unpack_part(v: tuple[int | float, ...]) -> ArticulatedPart:
    eid, part, flags = int(v[2]), int(v[3]), int(v[4])
    values = {
        n: (float(f) if flags >> (i + 1) & 1 else None)
        for i, (n, f) in enumerate(zip(_ART_FIELDS, v[5:], strict=True))
    }
    return ArticulatedPart(eid, part, bool(flags & 1), **values)


def _unpack_short(v: tuple[int | float, ...]) -> ShortArticulatedPart:
    eid, p1, p2, flags = (int(x) for x in v[2:6])
    s1, s2 = flags & 7, (flags >> 3) & 7
    if s1 > DofSelect.ROLL or s2 > DofSelect.ROLL:
        raise CigiError(f"Short Articulated Part Control with DOF Select {s1}/{s2}")
    return ShortArticulatedPart(
        eid,
        p1,
        p2,
        DofSelect(s1),
        DofSelect(s2),
        float(v[6]),
        float(v[7]),
        bool(flags & 64),
        bool(flags & 128),
    )


_UNPACK: dict[PacketId, Callable[[tuple[int | float, ...]], Packet]] = {
    PacketId.IG_CONTROL: _unpack_ig,
    PacketId.ENTITY_CONTROL: _unpack_entity,
    PacketId.ARTICULATED_PART: _unpack_part,
    PacketId.SHORT_ARTICULATED_PART: _unpack_short,
}


def byte_order(message: bytes) -> Order:
    """The sender's byte order, from the magic number of the IG Control that must open a host message."""
    if len(message) < SIZES[PacketId.IG_CONTROL] or message[0] != PacketId.IG_CONTROL:
        raise CigiError("a CIGI host message starts with a 24-byte IG Control")
    magic = message[6:8]
    if magic == b"\x80\x00":
        return ">"
    if magic == b"\x00\x80":
        return "<"
    raise CigiError(f"IG Control magic number {magic.hex()} is neither 8000 nor 0080")


def decode_message(message: bytes) -> tuple[list[Packet], int]:
    """The packets of one host message, and how many packets of other types were skipped (by their size).

    Raises :class:`CigiError` for a message that does not open with IG Control, a packet that runs past the
    end, a known packet whose size is not the standard's, or a packet size of zero."""
    order = byte_order(message)
    packets: list[Packet] = []
    skipped, at = 0, 0
    while at < len(message):
        if at + 2 > len(message):
            raise CigiError(f"a packet header cut at byte {at}")
        opcode, size = message[at], message[at + 1]
        if size < 2 or at + size > len(message):
            raise CigiError(f"packet {opcode} at byte {at}: size {size} with {len(message) - at} bytes left")
        if opcode in _UNPACK:
            pid = PacketId(opcode)
            if size != SIZES[pid]:
                raise CigiError(f"{pid.name} at byte {at} has size {size}, not {SIZES[pid]}")
            packets.append(_UNPACK[pid](_struct(pid, order).unpack_from(message, at)))
        else:
            skipped += 1
        at += size
    return packets, skipped


# --- IG → host: Start of Frame --------------------------------------------------------------------------

START_OF_FRAME = 101  # packet ID; an IG → host message opens with it, as a host message opens with IG Control
SOF_SIZE = 24
HOST_PORT = 8005  # the host's receive port most CIGI implementations use, beside the IG's 8004
_SOF_STRUCTS = {o: struct.Struct(o + "BBBbBBHIII4x") for o in (">", "<")}
assert _SOF_STRUCTS[">"].size == SOF_SIZE


@dataclass(frozen=True)
class StartOfFrame:
    """Start of Frame (packet 101, 24 bytes, IG → host): the IG's frame, and the last host frame it read."""

    ig_frame: int
    last_host_frame: int = 0
    timestamp: int = 0  # 10 µs ticks
    timestamp_valid: bool = False
    database: int = 0  # int8; negative: the database cannot be loaded
    ig_status: int = 0  # 0 normal, else an IG-defined error code
    ig_mode: int = 1  # 0 reset/standby, 1 operate, 2 debug, 3 offline maintenance
    earth_reference_model: bool = False  # True: the IG uses a custom ERM, not WGS 84
    minor_version: int = MINOR_VERSION


def encode_start_of_frame(sof: StartOfFrame, order: Order = ">") -> bytes:
    """A Start of Frame's bytes (what an IG sends; the host only reads them: for tests and fake IGs)."""
    flags = (
        (sof.ig_mode & 3) | sof.timestamp_valid << 2 | sof.earth_reference_model << 3
        | (sof.minor_version & 15) << 4
    )  # fmt: skip
    try:
        return _SOF_STRUCTS[order].pack(
            START_OF_FRAME, SOF_SIZE, MAJOR_VERSION, sof.database, sof.ig_status, flags, MAGIC,
            sof.ig_frame, sof.timestamp, sof.last_host_frame,
        )  # fmt: skip
    except struct.error as exc:
        raise CigiError(f"StartOfFrame: {exc}") from None


def decode_start_of_frame(message: bytes) -> StartOfFrame:
    """The Start of Frame that opens an IG → host message, in either byte order (the magic number tells).

    The packets after it (HAT/HOT responses, ...) are not read. Raises :class:`CigiError` for a message that
    does not open with a CIGI 3 24-byte Start of Frame or whose magic number is neither 0x8000 nor 0x0080."""
    if len(message) < SOF_SIZE or message[0] != START_OF_FRAME or message[1] != SOF_SIZE:
        raise CigiError("a CIGI IG message starts with a 24-byte Start of Frame")
    magic = message[6:8]
    if magic not in (b"\x80\x00", b"\x00\x80"):
        raise CigiError(f"Start of Frame magic number {magic.hex()} is neither 8000 nor 0080")
    order: Order = ">" if magic == b"\x80\x00" else "<"
    _, _, major, db, status, flags, _, frame, stamp, last = _SOF_STRUCTS[order].unpack_from(message)
    if major != MAJOR_VERSION:
        raise CigiError(f"Start of Frame of CIGI {major}, not CIGI 3")
    return StartOfFrame(
        frame, last, stamp, bool(flags & 4), db, status, flags & 3, bool(flags & 8), flags >> 4
    )
