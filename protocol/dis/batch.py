"""Many Entity State PDUs at once: numpy structured dtypes, one gather to decode, one scatter to encode.

A logfile of 100k PDUs is decoded by *one* fancy-index over a sliding-window view of the byte buffer (the
fixed 144-byte parts) plus one for the 16-byte variable-parameter records; no per-PDU Python work. Records
come back in :data:`ESPDU_DTYPE` (native byte order, same field order and sizes as the wire), the
variable-parameter records in :data:`VARIABLE_PARAMETER_DTYPE`, indexed CSR-style by ``param_start``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided, sliding_window_view
from numpy.typing import NDArray

from protocol.dis.entity_state import (
    ESPDU_FIXED_SIZE,
    VARIABLE_PARAMETER_SIZE,
    EntityId,
    EntityStatePdu,
    EntityType,
    VariableParameter,
)
from protocol.dis.errors import DisError
from protocol.dis.pdu import SUPPORTED_VERSIONS, PduType


def _dtypes(e: str) -> tuple[np.dtype, np.dtype, np.dtype, np.dtype]:
    entity_id = np.dtype([("site", e + "u2"), ("application", e + "u2"), ("entity", e + "u2")])
    entity_type = np.dtype(
        [
            ("kind", "u1"),
            ("domain", "u1"),
            ("country", e + "u2"),
            ("category", "u1"),
            ("subcategory", "u1"),
            ("specific", "u1"),
            ("extra", "u1"),
        ]
    )
    espdu = np.dtype(
        [
            ("version", "u1"),
            ("exercise", "u1"),
            ("pdu_type", "u1"),
            ("family", "u1"),
            ("timestamp", e + "u4"),
            ("length", e + "u2"),
            ("pdu_status", "u1"),
            ("padding", "u1"),
            ("entity_id", entity_id),
            ("force_id", "u1"),
            ("num_params", "u1"),
            ("entity_type", entity_type),
            ("alt_entity_type", entity_type),
            ("velocity", e + "f4", (3,)),
            ("location", e + "f8", (3,)),
            ("orientation", e + "f4", (3,)),
            ("appearance", e + "u4"),
            ("dr_algorithm", "u1"),
            ("dr_other", "u1", (15,)),
            ("acceleration", e + "f4", (3,)),
            ("angular_velocity", e + "f4", (3,)),
            ("marking_charset", "u1"),
            ("marking", "S11"),
            ("capabilities", e + "u4"),
        ]
    )
    varparam = np.dtype(
        [
            ("record_type", "u1"),
            ("change", "u1"),
            ("attached_to", e + "u2"),
            ("parameter_type", e + "u4"),
            ("value", e + "f4"),
            ("value_low", e + "u4"),
        ]
    )
    return entity_id, entity_type, espdu, varparam


ENTITY_ID_DTYPE, ENTITY_TYPE_DTYPE, ESPDU_DTYPE, VARIABLE_PARAMETER_DTYPE = _dtypes("=")
_, _, ESPDU_WIRE_DTYPE, VARIABLE_PARAMETER_WIRE_DTYPE = _dtypes(">")
assert ESPDU_WIRE_DTYPE.itemsize == ESPDU_FIXED_SIZE
assert VARIABLE_PARAMETER_WIRE_DTYPE.itemsize == VARIABLE_PARAMETER_SIZE


@dataclass(slots=True)
class EntityStateBatch:
    """Decoded Entity State PDUs: ``records[i]`` owns ``params[param_start[i]:param_start[i + 1]]``."""

    records: NDArray[np.void]
    params: NDArray[np.void]
    param_start: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.records.shape[0])

    @classmethod
    def empty(cls) -> EntityStateBatch:
        return cls(np.zeros(0, ESPDU_DTYPE), np.zeros(0, VARIABLE_PARAMETER_DTYPE), np.zeros(1, np.int64))

    def params_of(self, i: int) -> NDArray[np.void]:
        return self.params[self.param_start[i] : self.param_start[i + 1]]

    def select(self, index: NDArray[np.bool_] | NDArray[np.integer] | slice) -> EntityStateBatch:
        """A sub-batch (boolean mask, integer index or slice), variable parameters carried along."""
        idx = np.arange(len(self))[index]
        counts = (self.param_start[1:] - self.param_start[:-1])[idx]
        start = np.zeros(idx.size + 1, np.int64)
        np.cumsum(counts, out=start[1:])
        gather = np.repeat(self.param_start[idx] - start[:-1], counts) + np.arange(start[-1])
        return EntityStateBatch(self.records[idx], self.params[gather], start)

    @classmethod
    def concatenate(cls, batches: Sequence[EntityStateBatch]) -> EntityStateBatch:
        if not batches:
            return cls.empty()
        counts = np.concatenate([b.param_start[1:] - b.param_start[:-1] for b in batches])
        start = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=start[1:])
        return cls(
            np.concatenate([b.records for b in batches]), np.concatenate([b.params for b in batches]), start
        )


def as_u8(buf: bytes | bytearray | memoryview | NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A read-only uint8 view of any byte buffer (no copy)."""
    if isinstance(buf, np.ndarray):
        return buf.view(np.uint8).reshape(-1)
    return np.frombuffer(buf, dtype=np.uint8)


def _u16(u8: NDArray[np.uint8], at: NDArray[np.int64]) -> NDArray[np.int64]:
    return (u8[at].astype(np.int64) << 8) | u8[at + 1]


# Reason codes of validate_entity_states (0 = good); the offsets say which field.
ES_OK, ES_TRUNCATED, ES_VERSION, ES_TYPE, ES_SHORT, ES_COUNT = range(6)
ES_REASONS = {
    ES_TRUNCATED: "length field runs past the end of the data",
    ES_VERSION: "protocol version not supported (5, 6, 7)",
    ES_TYPE: "not an Entity State PDU",
    ES_SHORT: "Entity State PDU shorter than 144 bytes",
    ES_COUNT: "length does not match the number of variable parameters",
}
_REASON_FIELD = {ES_TRUNCATED: 8, ES_VERSION: 0, ES_TYPE: 2, ES_SHORT: 8, ES_COUNT: 19}


def validate_entity_states(
    u8: NDArray[np.uint8], offsets: NDArray[np.integer], available: NDArray[np.int64] | None = None
) -> tuple[NDArray[np.uint8], NDArray[np.int64]]:
    """Vectorised header checks for ESPDUs at ``offsets``: (reason code per PDU, field offset per PDU).

    ``available`` is how many bytes each PDU may use (defaults to the rest of the buffer). The length field
    must fit, be at least 144 and equal 144 + 16 N.
    """
    return validate_pdus(u8, offsets, available, PduType.ENTITY_STATE, ESPDU_FIXED_SIZE)


def validate_pdus(
    u8: NDArray[np.uint8],
    offsets: NDArray[np.integer],
    available: NDArray[np.int64] | None,
    pdu_type: int,
    fixed_size: int,
) -> tuple[NDArray[np.uint8], NDArray[np.int64]]:
    """:func:`validate_entity_states` for any PDU of ``fixed_size`` bytes plus 16 N whose N is byte 19
    (Entity State, Entity State Update): the ``ES_*`` reason codes (``ES_TYPE``: not ``pdu_type``)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    n = offsets.shape[0]
    n_bytes = u8.shape[0]
    avail = (n_bytes - offsets) if available is None else np.asarray(available, dtype=np.int64)
    # one gather of the first 20 bytes of every PDU (zero-padded where the buffer ends)
    padded = u8 if n_bytes >= 20 else np.concatenate([u8, np.zeros(20 - n_bytes, np.uint8)])
    safe = np.clip(offsets, 0, padded.shape[0] - 20)
    head = sliding_window_view(padded, 20)[safe]
    has_header = (avail >= 12) & (offsets >= 0) & (offsets + 12 <= n_bytes)
    length = (head[:, 8].astype(np.int64) << 8) | head[:, 9]
    version = head[:, 0]
    reason = np.where(has_header, ES_OK, ES_TRUNCATED).astype(np.uint8)
    checks = (
        (ES_TYPE, head[:, 2] != pdu_type),
        (ES_VERSION, (version < SUPPORTED_VERSIONS[0]) | (version > SUPPORTED_VERSIONS[-1])),
        (ES_TRUNCATED, length > avail),
        (ES_SHORT, length < fixed_size),
        (ES_COUNT, length != fixed_size + VARIABLE_PARAMETER_SIZE * head[:, 19].astype(np.int64)),
    )
    for code, bad in checks:
        reason[(reason == ES_OK) & bad] = code
    if n and not has_header.all():
        reason[~has_header] = ES_TRUNCATED
    field = np.array([0, *(_REASON_FIELD[c] for c in range(1, 6))], np.int64)[reason]
    return reason, field


def decode_entity_states(
    buf: bytes | bytearray | memoryview | NDArray[np.uint8],
    offsets: Sequence[int] | NDArray[np.integer] | None = None,
    *,
    validate: bool = True,
) -> EntityStateBatch:
    """Decode the Entity State PDUs starting at ``offsets`` (default: one PDU every 144 bytes).

    With ``validate`` (the default) a bad PDU raises :class:`DisError` whose offset is the absolute offset
    of the bad field in ``buf``; the log readers validate themselves and pass ``validate=False``.
    """
    u8 = as_u8(buf)
    if offsets is None:
        if u8.shape[0] % ESPDU_FIXED_SIZE:
            raise DisError(f"{u8.shape[0]} bytes is not a whole number of 144-byte PDUs", u8.shape[0])
        offsets = np.arange(0, u8.shape[0], ESPDU_FIXED_SIZE, dtype=np.int64)
    offsets = np.asarray(offsets, dtype=np.int64)
    n = offsets.shape[0]
    if n == 0:
        return EntityStateBatch.empty()
    if (offsets < 0).any() or (offsets > u8.shape[0] - ESPDU_FIXED_SIZE).any():
        bad = int(offsets[(offsets < 0) | (offsets > u8.shape[0] - ESPDU_FIXED_SIZE)][0])
        raise DisError("Entity State PDU offset leaves no room for 144 bytes", bad)
    if validate:
        reason, field = validate_entity_states(u8, offsets)
        if reason.any():
            i = int(np.flatnonzero(reason)[0])
            raise DisError(ES_REASONS[int(reason[i])], int(offsets[i] + field[i]))
    # The one gather: rows of a sliding-window view (no index array wider than N).
    if (
        n * ESPDU_FIXED_SIZE == u8.shape[0]
        and offsets[0] == 0
        and (np.diff(offsets) == ESPDU_FIXED_SIZE).all()
    ):
        wire = u8.view(ESPDU_WIRE_DTYPE)
    else:
        wire = sliding_window_view(u8, ESPDU_FIXED_SIZE)[offsets].view(ESPDU_WIRE_DTYPE).reshape(n)
    records = wire.astype(ESPDU_DTYPE)
    first = (offsets + ESPDU_FIXED_SIZE).astype(np.int64)
    return EntityStateBatch(records, *gather_params(u8, first, records["num_params"]))


def gather_params(
    u8: NDArray[np.uint8], first: NDArray[np.int64], counts: NDArray[np.integer]
) -> tuple[NDArray[np.void], NDArray[np.int64]]:
    """The 16-byte variable-parameter records of many PDUs (``counts[i]`` of them at ``first[i]``), in one
    gather: (records in ``VARIABLE_PARAMETER_DTYPE``, CSR ``param_start``)."""
    counts = np.asarray(counts, np.int64)
    start = np.zeros(counts.shape[0] + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    total = int(start[-1])
    if not total:
        return np.zeros(0, VARIABLE_PARAMETER_DTYPE), start
    step = VARIABLE_PARAMETER_SIZE * np.arange(total, dtype=np.int64)
    at = np.repeat(first - VARIABLE_PARAMETER_SIZE * start[:-1], counts) + step
    rows = sliding_window_view(u8, VARIABLE_PARAMETER_SIZE)[at]
    return rows.view(VARIABLE_PARAMETER_WIRE_DTYPE).reshape(total).astype(VARIABLE_PARAMETER_DTYPE), start


def pdu_lengths(batch: EntityStateBatch) -> NDArray[np.int64]:
    counts = batch.param_start[1:] - batch.param_start[:-1]
    return ESPDU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * counts


def encode_entity_states(batch: EntityStateBatch) -> bytes:
    """The concatenated PDUs of a batch (length, record count and PDU type are filled in).

    Vectorised: one cast to the wire dtype and one strided scatter per distinct record count.
    """
    n = len(batch)
    recs = batch.records.copy()
    counts = batch.param_start[1:] - batch.param_start[:-1]
    if (counts > 255).any():
        raise DisError("more than 255 variable parameters in one PDU", 19)
    bad_version = ~np.isin(recs["version"], SUPPORTED_VERSIONS)
    if bad_version.any():
        raise DisError(f"protocol version {int(recs['version'][bad_version][0])} not supported", 0)
    lengths = ESPDU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * counts
    recs["num_params"] = counts
    recs["length"] = lengths
    recs["pdu_type"] = PduType.ENTITY_STATE
    fixed = recs.astype(ESPDU_WIRE_DTYPE).view(np.uint8).reshape(n, ESPDU_FIXED_SIZE)
    if not counts.any():
        return fixed.tobytes()
    params = (
        batch.params.astype(VARIABLE_PARAMETER_WIRE_DTYPE).view(np.uint8).reshape(-1, VARIABLE_PARAMETER_SIZE)
    )
    offsets = np.zeros(n, np.int64)
    np.cumsum(lengths[:-1], out=offsets[1:])
    out = np.zeros(int(lengths.sum()), np.uint8)
    for k in np.unique(counts):
        sel = np.flatnonzero(counts == k)
        width = ESPDU_FIXED_SIZE + VARIABLE_PARAMETER_SIZE * int(k)
        block = np.empty((sel.size, width), np.uint8)
        block[:, :ESPDU_FIXED_SIZE] = fixed[sel]
        if k:
            pidx = batch.param_start[sel][:, None] + np.arange(k)
            block[:, ESPDU_FIXED_SIZE:] = params[pidx].reshape(sel.size, -1)
        rows = as_strided(out, shape=(out.size - width + 1, width), strides=(1, 1))
        rows[offsets[sel]] = block
    return out.tobytes()


# --- conversions between the scalar dataclass and batch rows (tests, synth, small tools) ---------------


def batch_from_pdus(pdus: Sequence[EntityStatePdu]) -> EntityStateBatch:
    recs = np.zeros(len(pdus), ESPDU_DTYPE)
    params: list[tuple[int, ...]] = []
    start = np.zeros(len(pdus) + 1, np.int64)
    for i, p in enumerate(pdus):
        recs[i] = (
            p.version,
            p.exercise,
            PduType.ENTITY_STATE,
            p.family,
            p.timestamp,
            p.length,
            p.pdu_status,
            p.padding,
            tuple(p.entity_id),
            p.force_id,
            len(p.variable_parameters),
            tuple(p.entity_type),
            tuple(p.alt_entity_type),
            p.velocity,
            p.location,
            p.orientation,
            p.appearance,
            p.dr_algorithm,
            np.frombuffer(p.dr_other, np.uint8),
            p.acceleration,
            p.angular_velocity,
            p.marking_charset,
            p.marking,
            p.capabilities,
        )
        for v in p.variable_parameters:
            raw = v.pack()
            params.append(tuple(np.frombuffer(raw, VARIABLE_PARAMETER_WIRE_DTYPE)[0].tolist()))
        start[i + 1] = len(params)
    return EntityStateBatch(recs, np.array(params, VARIABLE_PARAMETER_DTYPE), start)


def _vec3(v: np.ndarray) -> tuple[float, float, float]:
    x, y, z = (float(c) for c in v)
    return x, y, z


def pdu_from_row(batch: EntityStateBatch, i: int) -> EntityStatePdu:
    r = batch.records[i]
    vps = tuple(
        VariableParameter(raw[0], bytes(raw[1:]))
        for raw in (row.tobytes() for row in batch.params_of(i).astype(VARIABLE_PARAMETER_WIRE_DTYPE))
    )
    return EntityStatePdu(
        entity_id=EntityId(*r["entity_id"].tolist()),
        force_id=int(r["force_id"]),
        entity_type=EntityType(*r["entity_type"].tolist()),
        alt_entity_type=EntityType(*r["alt_entity_type"].tolist()),
        velocity=_vec3(r["velocity"]),
        location=_vec3(r["location"]),
        orientation=_vec3(r["orientation"]),
        appearance=int(r["appearance"]),
        dr_algorithm=int(r["dr_algorithm"]),
        dr_other=r["dr_other"].tobytes(),
        acceleration=_vec3(r["acceleration"]),
        angular_velocity=_vec3(r["angular_velocity"]),
        marking_charset=int(r["marking_charset"]),
        marking=bytes(r["marking"]).ljust(11, b"\0"),
        capabilities=int(r["capabilities"]),
        variable_parameters=vps,
        version=int(r["version"]),
        exercise=int(r["exercise"]),
        timestamp=int(r["timestamp"]),
        pdu_status=int(r["pdu_status"]),
        padding=int(r["padding"]),
        family=int(r["family"]),
    )
