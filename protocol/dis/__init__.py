"""DIS (IEEE 1278.1) for TTES: Entity State (and Update), Remove Entity, Fire, Detonation codecs, batch
decoding, lifeform appearance and TTES tokens, WGS84 frames, dead reckoning, logfile readers and synthetic
exercises.

Sans-IO and pure: bytes and numpy arrays in, dataclasses and arrays out. See docs/DIS.md.
"""

from __future__ import annotations

from protocol.dis.appearance import (
    Health,
    LifeformAppearance,
    LifeformState,
    TtesPosture,
    TtesWeapon,
    WeaponState,
    decode_appearance,
    encode_appearance,
    ttes_posture,
    ttes_weapon,
)
from protocol.dis.batch import (
    ESPDU_DTYPE,
    VARIABLE_PARAMETER_DTYPE,
    EntityStateBatch,
    decode_entity_states,
    encode_entity_states,
)
from protocol.dis.codec import decode_pdu, encode_pdu
from protocol.dis.dead_reckoning import DrAlgorithm, dead_reckon
from protocol.dis.entity_state import (
    EntityId,
    EntityStatePdu,
    EntityType,
    VariableParameter,
    decode_entity_state,
    encode_entity_state,
    make_marking,
)
from protocol.dis.entity_type import RIFLE_FIGURES, is_lifeform, rifle_code, rifle_figure
from protocol.dis.entity_update import (
    EntityStateUpdatePdu,
    UpdateBases,
    decode_entity_update,
    encode_entity_update,
    entity_keys,
)
from protocol.dis.errors import DisError
from protocol.dis.geo import (
    LocalFrame,
    ecef_to_geodetic,
    geodetic_to_ecef,
    heading_deg,
    orientation_from_heading,
)
from protocol.dis.logfile import DisLog, PduStatus, read_bytes, read_datagrams, read_log
from protocol.dis.pdu import DEFAULT_PORT, PduType
from protocol.dis.remove_entity import (
    DisEvent,
    RemoveEntity,
    RemoveEntityPdu,
    decode_remove_entity,
    encode_remove_entity,
)
from protocol.dis.tokens import TOKEN_DTYPE, translate
from protocol.dis.warfare import (
    DetonationPdu,
    FirePdu,
    WeaponEvent,
    decode_detonation,
    decode_fire,
    encode_detonation,
    encode_fire,
    weapon_event,
)

__all__ = [
    "DEFAULT_PORT",
    "ESPDU_DTYPE",
    "RIFLE_FIGURES",
    "TOKEN_DTYPE",
    "VARIABLE_PARAMETER_DTYPE",
    "DetonationPdu",
    "DisError",
    "DisEvent",
    "DisLog",
    "DrAlgorithm",
    "EntityId",
    "EntityStateBatch",
    "EntityStatePdu",
    "EntityStateUpdatePdu",
    "EntityType",
    "FirePdu",
    "Health",
    "LifeformAppearance",
    "LifeformState",
    "LocalFrame",
    "PduStatus",
    "PduType",
    "RemoveEntity",
    "RemoveEntityPdu",
    "TtesPosture",
    "TtesWeapon",
    "UpdateBases",
    "VariableParameter",
    "WeaponEvent",
    "WeaponState",
    "dead_reckon",
    "decode_appearance",
    "decode_detonation",
    "decode_entity_state",
    "decode_entity_states",
    "decode_entity_update",
    "decode_fire",
    "decode_pdu",
    "decode_remove_entity",
    "ecef_to_geodetic",
    "encode_appearance",
    "encode_detonation",
    "encode_entity_state",
    "encode_entity_states",
    "encode_entity_update",
    "encode_fire",
    "encode_pdu",
    "encode_remove_entity",
    "entity_keys",
    "geodetic_to_ecef",
    "heading_deg",
    "is_lifeform",
    "make_marking",
    "orientation_from_heading",
    "read_bytes",
    "read_datagrams",
    "read_log",
    "rifle_code",
    "rifle_figure",
    "translate",
    "ttes_posture",
    "ttes_weapon",
    "weapon_event",
]
