"""The 12-byte DIS PDU header, PDU type names and DIS timestamps.

Layout (big-endian, IEEE 1278.1): version u8, exercise u8, PDU type u8, protocol family u8, timestamp u32,
length u16, then two bytes that differ by version: DIS 7 has ``pdu_status`` u8 + padding u8, DIS 5 and 6 a
16-bit padding field.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from protocol.dis.errors import DisError

HEADER = struct.Struct(">BBBBIHBB")
HEADER_SIZE = 12
DEFAULT_PORT = 3000
SUPPORTED_VERSIONS = (5, 6, 7)  # IEEE 1278.1-1995, 1278.1a-1998, 1278.1-2012


class PduType(IntEnum):
    """The PDU types TTES reads; every other type is counted by number and skipped."""

    ENTITY_STATE = 1
    FIRE = 2
    DETONATION = 3
    REMOVE_ENTITY = 12
    ENTITY_STATE_UPDATE = 67


class Family(IntEnum):
    ENTITY_INFORMATION = 1
    WARFARE = 2
    SIMULATION_MANAGEMENT = 5


_NAMES = (
    "entity_state",
    "fire",
    "detonation",
    "collision",
    "service_request",
    "resupply_offer",
    "resupply_received",
    "resupply_cancel",
    "repair_complete",
    "repair_response",
    "create_entity",
    "remove_entity",
    "start_resume",
    "stop_freeze",
    "acknowledge",
    "action_request",
    "action_response",
    "data_query",
    "set_data",
    "data",
    "event_report",
    "comment",
    "electromagnetic_emission",
    "designator",
    "transmitter",
    "signal",
    "receiver",
    "iff",
    "underwater_acoustic",
    "supplemental_emission",
    "intercom_signal",
    "intercom_control",
    "aggregate_state",
    "is_group_of",
    "transfer_ownership",
    "is_part_of",
    "minefield_state",
    "minefield_query",
    "minefield_data",
    "minefield_response_nack",
    "environmental_process",
    "gridded_data",
    "point_object_state",
    "linear_object_state",
    "areal_object_state",
    "tspi",
    "appearance",
    "articulated_parts",
    "le_fire",
    "le_detonation",
    "create_entity_r",
    "remove_entity_r",
    "start_resume_r",
    "stop_freeze_r",
    "acknowledge_r",
    "action_request_r",
    "action_response_r",
    "data_query_r",
    "set_data_r",
    "data_r",
    "event_report_r",
    "comment_r",
    "record_r",
    "set_record_r",
    "record_query_r",
    "collision_elastic",
    "entity_state_update",
    "directed_energy_fire",
    "entity_damage_status",
    "information_operations_action",
    "information_operations_report",
    "attribute",
)
PDU_TYPE_NAMES: dict[int, str] = {i + 1: n for i, n in enumerate(_NAMES)}


def pdu_type_name(pdu_type: int) -> str:
    """``entity_state``, ``fire``, ... or ``type_N`` for numbers outside SISO-REF-010."""
    return PDU_TYPE_NAMES.get(int(pdu_type), f"type_{int(pdu_type)}")


@dataclass(frozen=True, slots=True)
class PduHeader:
    version: int
    exercise: int
    pdu_type: int
    family: int
    timestamp: int
    length: int
    pdu_status: int  # DIS 7: PDU status; DIS 5/6: first padding byte (kept for byte-exact round trips)
    padding: int

    def pack(self) -> bytes:
        try:
            return HEADER.pack(
                self.version,
                self.exercise,
                self.pdu_type,
                self.family,
                self.timestamp,
                self.length,
                self.pdu_status,
                self.padding,
            )
        except struct.error as exc:
            raise DisError(f"header field out of range: {exc}", 0) from None


def unpack_header(data: bytes | memoryview, offset: int = 0) -> PduHeader:
    """The header at ``offset``; :class:`DisError` when fewer than 12 bytes remain."""
    if len(data) - offset < HEADER_SIZE:
        raise DisError(f"need {HEADER_SIZE} header bytes, have {max(len(data) - offset, 0)}", offset)
    return PduHeader(*HEADER.unpack_from(data, offset))


def check_encodable(version: int, parameters: int | None = None) -> None:
    """The checks every encoder makes first: a version we speak and, for PDUs that carry them, at most 255
    variable parameters (a one-byte count); :class:`DisError` at the field's offset."""
    if version not in SUPPORTED_VERSIONS:
        raise DisError(f"protocol version {version} not supported (5, 6, 7)", 0)
    if parameters is not None and parameters > 255:
        raise DisError(f"{parameters} variable parameters (at most 255)", 19)


def check_header(data: bytes, pdu_type: PduType, minimum: int) -> None:
    """The checks every one-PDU decoder makes first (type, version, length field = the bytes, at least
    ``minimum`` bytes); :class:`DisError` at the field's offset."""
    if len(data) < HEADER_SIZE:
        raise DisError(f"truncated header: {len(data)} bytes", len(data))
    if data[2] != pdu_type:
        raise DisError(f"PDU type {data[2]} is not {pdu_type.name.lower()} ({int(pdu_type)})", 2)
    if data[0] not in SUPPORTED_VERSIONS:
        raise DisError(f"protocol version {data[0]} not supported (5, 6, 7)", 0)
    length = (data[8] << 8) | data[9]
    if length != len(data):
        raise DisError(f"length field {length} but {len(data)} bytes", 8)
    if length < minimum:
        raise DisError(f"{pdu_type.name.lower()} PDU of {length} bytes is shorter than {minimum}", 8)


def header_fields(data: bytes) -> dict[str, int]:
    """The header's fields a PDU dataclass keeps for byte-exact round trips (keyword arguments)."""
    h = HEADER.unpack_from(data, 0)
    return {"version": h[0], "exercise": h[1], "timestamp": h[4], "pdu_status": h[6], "padding": h[7],
            "family": h[3]}  # fmt: skip


def looks_like_dis(version: int, pdu_type: int, length: int) -> bool:
    """The cheap plausibility test used to tell DIS datagrams from other UDP traffic."""
    return 1 <= version <= 7 and pdu_type != 0 and length >= HEADER_SIZE


# --- timestamps -----------------------------------------------------------------------------------------
# Bits 31..1 count 3600 s / 2**31 units past the hour; bit 0 is 1 for absolute (UTC-synchronised) time.
_TS_UNIT = 3600.0 / 2**31


def encode_timestamp(seconds_past_hour: ArrayLike, absolute: bool = True) -> NDArray[np.uint32] | int:
    """DIS timestamp(s) for a time past the hour (wrapped into [0, 3600))."""
    s = np.mod(np.asarray(seconds_past_hour, dtype=np.float64), 3600.0)
    units = np.minimum(np.floor(s / _TS_UNIT), 2**31 - 1).astype(np.uint64)
    ts = ((units << np.uint64(1)) | np.uint64(1 if absolute else 0)).astype(np.uint32)
    return int(ts) if ts.ndim == 0 else ts


def timestamp_seconds(timestamp: ArrayLike) -> NDArray[np.float64]:
    """Seconds past the hour of DIS timestamp(s) (either flavour)."""
    ts = np.asarray(timestamp, dtype=np.uint32)
    return (ts >> np.uint32(1)).astype(np.float64) * _TS_UNIT


def unwrap_timestamps(seconds_past_hour: ArrayLike) -> NDArray[np.float64]:
    """A monotone-ish time axis from successive past-the-hour times: add 3600 s at each hour roll-over.

    Used only where a log carries no receipt time (raw PDU streams). A backwards jump of more than half an
    hour is taken as a roll-over; smaller backwards steps (reordering) are kept as they are.
    """
    s = np.asarray(seconds_past_hour, dtype=np.float64)
    if s.size == 0:
        return s.copy()
    rolls = np.concatenate(([0.0], np.cumsum(np.diff(s) < -1800.0) * 3600.0))
    return s + rolls
