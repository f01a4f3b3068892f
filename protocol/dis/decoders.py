"""PDU decoders of the log readers: one small function per PDU type in a read-only registry, yielding typed
events (the shape of :data:`protocol.messages.CODECS`).

A decoder gets every PDU of its type in a log at once (:class:`PduRows`: offsets, lengths, versions, times
and the rows of the PDU index they are) and yields what it found: :class:`EntityStates` (one vectorised
batch), :class:`EntityUpdates` (Entity State Update PDUs, still to be put on top of their entities' Entity
State PDUs), :class:`Event` (a Fire, Detonation or Remove Entity event), :class:`Skipped` (rows with a
status, e.g. an unsupported version) or :class:`Corrupt` (a row and its located :class:`DisError`). The log
reader (:mod:`protocol.dis.logfile`) dispatches on them with ``match`` and derives every counter from what
came back. To read one more PDU type, write its decoder and add it to :data:`DECODERS`; a type without one
is counted as ``other_pdus``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from enum import IntEnum
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from protocol.dis.batch import (
    ES_REASONS,
    ES_VERSION,
    EntityStateBatch,
    decode_entity_states,
    validate_entity_states,
    validate_pdus,
)
from protocol.dis.entity_type import is_lifeform
from protocol.dis.entity_update import ESU_FIXED_SIZE, ESU_REASONS, decode_entity_updates
from protocol.dis.errors import DisError
from protocol.dis.pdu import SUPPORTED_VERSIONS, PduType
from protocol.dis.remove_entity import DisEvent, remove_event
from protocol.dis.warfare import weapon_event

I64 = NDArray[np.int64]


class PduStatus(IntEnum):
    DECODED = 0  # in the batch
    NOT_LIFEFORM = 1  # an Entity State PDU of a non-lifeform (skipped unless lifeforms_only=False)
    OTHER_TYPE = 2  # a PDU type TTES does not read
    EVENT = 3  # Fire / Detonation, in events
    CORRUPT = 4  # reported in issues
    UNSUPPORTED_VERSION = 5  # Entity State / Fire / Detonation of a DIS version other than 5, 6, 7
    OTHER_EXERCISE = 6  # a PDU of an exercise other than the one asked for (``exercise=``), not decoded
    NO_BASE = 7  # an Entity State Update of an entity whose (kept) Entity State PDU was not seen before it


@dataclass(frozen=True, slots=True)
class PduRows:
    """Every PDU of one type in a log: where it starts in ``data``, how long it is, when it arrived."""

    data: bytes
    u8: NDArray[np.uint8]
    rows: I64  # their rows in the log's PDU index
    offset: I64  # buffer offsets
    length: I64
    segment: I64  # the segment (packet / line) each came in; errors carry it as their record
    version: NDArray[np.uint8]
    t: NDArray[np.float64]
    lifeforms_only: bool


# -- the typed events a decoder yields ----------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class EntityStates:
    """Decoded Entity State PDUs: ``batch`` holds the kept ones, ``rows`` their index rows (batch order)."""

    batch: EntityStateBatch
    rows: I64
    lifeforms: int
    non_lifeforms: int
    skipped: I64  # rows of valid non-lifeform PDUs left out (lifeforms_only)

    @classmethod
    def empty(cls) -> EntityStates:
        none = np.zeros(0, np.int64)
        return cls(decode_entity_states(np.zeros(0, np.uint8), none, validate=False), none, 0, 0, none)


@dataclass(frozen=True, slots=True)
class EntityUpdates:
    """Decoded Entity State Update PDUs as partial records (:func:`~protocol.dis.entity_update.
    decode_entity_updates`); ``rows`` their index rows."""

    batch: EntityStateBatch
    rows: I64


@dataclass(frozen=True, slots=True)
class Event:
    row: int
    event: DisEvent


@dataclass(frozen=True, slots=True)
class Skipped:
    rows: I64
    status: PduStatus


@dataclass(frozen=True, slots=True)
class Corrupt:
    row: int
    error: DisError  # offset in the buffer, record = the segment


Decoded = EntityStates | EntityUpdates | Event | Skipped | Corrupt
PduDecoder = Callable[[PduRows], Iterator[Decoded]]


# -- the decoders ------------------------------------------------------------------------------------------
def entity_state(p: PduRows) -> Iterator[Decoded]:
    """Vectorised header checks, then one batch decode of every good PDU."""
    reason, field_off = validate_entity_states(p.u8, p.offset, p.length)
    yield Skipped(p.rows[reason == ES_VERSION], PduStatus.UNSUPPORTED_VERSION)
    for k in np.flatnonzero((reason != 0) & (reason != ES_VERSION)).tolist():
        error = DisError(ES_REASONS[int(reason[k])], int(p.offset[k] + field_off[k]), int(p.segment[k]))
        yield Corrupt(int(p.rows[k]), error)
    good = reason == 0
    batch = decode_entity_states(p.u8, p.offset[good], validate=False)
    types = batch.records["entity_type"]
    life = is_lifeform(types["kind"], types["domain"])
    keep = life if p.lifeforms_only else np.ones(len(batch), bool)
    rows = p.rows[good]
    kept = batch if keep.all() else batch.select(keep)
    yield EntityStates(kept, rows[keep], int(life.sum()), int((~life).sum()), rows[~keep])


def entity_state_update(p: PduRows) -> Iterator[Decoded]:
    """Vectorised header checks, then one gather of every good update (resolved later by the reader)."""
    reason, field_off = validate_pdus(p.u8, p.offset, p.length, PduType.ENTITY_STATE_UPDATE, ESU_FIXED_SIZE)
    yield Skipped(p.rows[reason == ES_VERSION], PduStatus.UNSUPPORTED_VERSION)
    for k in np.flatnonzero((reason != 0) & (reason != ES_VERSION)).tolist():
        error = DisError(ESU_REASONS[int(reason[k])], int(p.offset[k] + field_off[k]), int(p.segment[k]))
        yield Corrupt(int(p.rows[k]), error)
    good = reason == 0
    yield EntityUpdates(decode_entity_updates(p.u8, p.offset[good]), p.rows[good])


def _events(p: PduRows, decode: Callable[[bytes, float], DisEvent]) -> Iterator[Decoded]:
    """Fire, Detonation and Remove Entity PDUs are rare: decoded one by one into events."""
    for k in range(len(p.rows)):
        if int(p.version[k]) not in SUPPORTED_VERSIONS:
            yield Skipped(p.rows[k : k + 1], PduStatus.UNSUPPORTED_VERSION)
            continue
        o, n = int(p.offset[k]), int(p.length[k])
        try:
            yield Event(int(p.rows[k]), decode(p.data[o : o + n], float(p.t[k])))
        except DisError as exc:
            yield Corrupt(int(p.rows[k]), DisError(exc.message, o + exc.offset, int(p.segment[k])))


def fire(p: PduRows) -> Iterator[Decoded]:
    yield from _events(p, weapon_event)


def detonation(p: PduRows) -> Iterator[Decoded]:
    yield from _events(p, weapon_event)


def remove_entity(p: PduRows) -> Iterator[Decoded]:
    yield from _events(p, remove_event)


DECODERS: Mapping[int, PduDecoder] = MappingProxyType(
    {
        PduType.ENTITY_STATE: entity_state,
        PduType.FIRE: fire,
        PduType.DETONATION: detonation,
        PduType.REMOVE_ENTITY: remove_entity,
        PduType.ENTITY_STATE_UPDATE: entity_state_update,
    }
)
