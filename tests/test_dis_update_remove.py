"""Entity State Update (type 67) and Remove Entity (type 12) PDUs: codecs, the log readers (an update stands
on its entity's last Entity State PDU), the translator (Remove Entity removes the soldier at once), the
replay and the gateway (an update heard a burst after its Entity State PDU)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_replay_support import pcap_of

from client_stub.dis import LogCursor, RemoveReason, Replayer
from client_stub.dis.gateway import DisGateway, GatewayConfig
from protocol.dis import (
    DisError,
    EntityId,
    EntityStatePdu,
    EntityStateUpdatePdu,
    EntityType,
    LocalFrame,
    PduStatus,
    RemoveEntity,
    RemoveEntityPdu,
    VariableParameter,
    decode_entity_update,
    decode_pdu,
    decode_remove_entity,
    encode_appearance,
    encode_entity_state,
    encode_entity_update,
    encode_remove_entity,
    orientation_from_heading,
    read_bytes,
)
from protocol.dis.appearance import LifeformState, WeaponState
from protocol.dis.entity_update import decode_entity_updates
from protocol.entity import Appearance
from ttes.commands.dis import dump_rows

FRAME = LocalFrame(38.52, -77.44, 60.0)
SOLDIER = EntityType(3, 1, 225, 12, 5, 41, 0)
TANK = EntityType(1, 1, 225, 1, 1, 3, 0)
MANAGER = EntityId(1, 1, 0)


def where(east: float) -> tuple[float, float, float]:
    x, y, z = FRAME.to_ecef(np.array([east, 0.0, 0.0])).tolist()
    return x, y, z


def espdu(entity: int, east: float = 0.0, etype: EntityType = SOLDIER, state: int = 1) -> bytes:
    loc = where(east)
    return encode_entity_state(
        EntityStatePdu(
            entity_id=EntityId(1, 2, entity),
            force_id=1,
            entity_type=etype,
            location=loc,
            orientation=tuple(orientation_from_heading(np.array(loc), 90.0).tolist()),
            appearance=int(encode_appearance(state=state, weapon1=WeaponState.DEPLOYED)),
            dr_algorithm=2,
            marking=b"SQD1".ljust(11, b"\0"),
        )
    )


def update(entity: int, east: float, state: int = LifeformState.PRONE, params: int = 0) -> bytes:
    loc = where(east)
    return encode_entity_update(
        EntityStateUpdatePdu(
            entity_id=EntityId(1, 2, entity),
            location=loc,
            orientation=tuple(orientation_from_heading(np.array(loc), 90.0).tolist()),
            appearance=int(encode_appearance(state=state, weapon1=WeaponState.DEPLOYED)),
            variable_parameters=tuple(
                VariableParameter.articulated(4096 + k, 0.25 * k) for k in range(params)
            ),
        )
    )


def remove(entity: int) -> bytes:
    return encode_remove_entity(RemoveEntityPdu(MANAGER, EntityId(1, 2, entity), request_id=7))


# -- codecs -----------------------------------------------------------------------------------------
finite = st.floats(-1e7, 1e7, allow_nan=False, width=32)
ids = st.builds(EntityId, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))


@given(
    ids,
    st.tuples(finite, finite, finite),
    st.tuples(st.floats(-1e7, 1e7), st.floats(-1e7, 1e7), st.floats(-1e7, 1e7)),
    st.integers(0, 2**32 - 1),
    st.integers(0, 4),
    st.sampled_from((5, 6, 7)),
    st.integers(0, 255),
)
def test_entity_state_update_round_trips_and_the_batch_decoder_agrees(
    entity: EntityId,
    vel: tuple[float, float, float],
    loc: tuple[float, float, float],
    appearance: int,
    nparams: int,
    version: int,
    pad: int,
) -> None:
    pdu = EntityStateUpdatePdu(
        entity_id=entity, velocity=vel, location=loc, orientation=vel, appearance=appearance,
        variable_parameters=tuple(VariableParameter.articulated(k, 1.5) for k in range(nparams)),
        version=version, padding1=pad,
    )  # fmt: skip
    data = encode_entity_update(pdu)
    assert len(data) == 72 + 16 * nparams and data[2] == 67
    assert decode_entity_update(data) == pdu and decode_pdu(data) == pdu
    batch = decode_entity_updates(np.frombuffer(data, np.uint8), np.array([0]))
    r = batch.records[0]
    assert tuple(r["entity_id"].tolist()) == tuple(entity) and int(r["appearance"]) == appearance
    np.testing.assert_array_equal(r["location"], loc)
    np.testing.assert_array_equal(r["velocity"], np.float32(vel))
    assert len(batch.params_of(0)) == nparams


@given(ids, ids, st.integers(0, 2**32 - 1), st.sampled_from((5, 6, 7)))
def test_remove_entity_round_trips(
    originator: EntityId, receiver: EntityId, request: int, version: int
) -> None:
    pdu = RemoveEntityPdu(originator, receiver, request, version)
    data = encode_remove_entity(pdu)
    assert len(data) == 28 and data[2] == 12 and data[3] == 5
    assert decode_remove_entity(data) == pdu and decode_pdu(data) == pdu


def test_bad_updates_and_removals_name_the_field() -> None:
    with pytest.raises(DisError) as bad:
        decode_entity_update(update(1, 0.0)[:-4])
    assert bad.value.offset == 8
    with pytest.raises(DisError) as bad:
        decode_remove_entity(remove(1) + b"\0")
    assert bad.value.offset == 8
    counted = bytearray(update(1, 0.0, params=1))
    counted[19] = 2
    with pytest.raises(DisError) as bad:
        decode_entity_update(bytes(counted))
    assert bad.value.offset == 19


# -- the log readers -----------------------------------------------------------------------------------
def test_updates_stand_on_their_entitys_last_entity_state_pdu() -> None:
    log = read_bytes(pcap_of([
        (0.0, espdu(1)),
        (0.5, update(2, 3.0)),  # entity 2 not seen yet: nothing to stand on
        (1.0, update(1, 2.0, params=2)),
        (1.5, espdu(9, etype=TANK)),
        (2.0, update(9, 5.0)),  # a tank's update: its base is not kept (lifeforms only)
        (3.0, update(1, 4.0, state=LifeformState.KNEELING)),
        (3.5, update(7, 0.0)[:50]),  # truncated
    ]))  # fmt: skip
    r = log.batch.records
    assert r["entity_id"]["entity"].tolist() == [1, 1, 1] and r["pdu_type"].tolist() == [1, 67, 67]
    np.testing.assert_allclose(log.times, [0.0, 1.0, 3.0])
    np.testing.assert_allclose(FRAME.to_local(r["location"])[:, 0], [0.0, 2.0, 4.0], atol=1e-6)
    assert (r["entity_type"][1:] == r["entity_type"][0]).all() and (r["marking"][1:] == b"SQD1").all()
    assert r["force_id"].tolist() == [1, 1, 1] and r["dr_algorithm"].tolist() == [2, 2, 2]
    assert len(log.batch.params_of(1)) == 2 and len(log.batch.params_of(2)) == 0
    c = log.counters
    assert (c["entity_state_updates"], c["updates_without_base"], c["corrupt"]) == (4, 2, 1)
    st_ = log.pdus["status"].tolist()
    assert st_.count(PduStatus.NO_BASE) == 2 and st_.count(PduStatus.DECODED) == 3
    assert log.pdus["batch_index"][log.pdus["status"] == PduStatus.DECODED].tolist() == [0, 1, 2]
    lines = [row for row in dump_rows(log) if not row.get("skipped")]  # `ttes dis dump --json`
    assert [row.get("update", False) for row in lines] == [False, True, True]
    assert [row["posture"] for row in lines] == ["standing", "prone", "kneeling"]
    assert {row["marking"] for row in lines} == {"SQD1"}
    reasons = [row.get("reason") for row in dump_rows(log) if row.get("skipped")]
    assert reasons.count("update_without_entity_state") == 2


def test_remove_entity_becomes_an_event() -> None:
    log = read_bytes(pcap_of([(0.0, espdu(1)), (2.0, remove(1))]))
    (ev,) = log.events
    assert isinstance(ev, RemoveEntity) and ev.entity == (1, 2, 1) and ev.t == 2.0
    assert ev.originator == MANAGER and log.counters["remove_entity"] == 1
    assert ev.to_json()["kind"] == "remove_entity"


# -- the translator, the replay and the gateway -------------------------------------------------------
def test_replay_plays_updates_and_removes_at_once() -> None:
    log = read_bytes(pcap_of([
        (100.0, espdu(1)),
        (100.0, espdu(2, 10.0)),
        (101.0, update(1, 1.0, state=LifeformState.PRONE)),
        (102.0, remove(1)),
        (103.0, remove(0xFFFF)),  # 1:2:65535 = every entity of application 1:2
    ]))  # fmt: skip
    r = Replayer(LogCursor(log), origin=FRAME)
    first = r.advance(0.0)
    assert sorted(first.created["slot"].tolist()) == [0, 1]
    prone = r.advance(1.0)
    assert {int(q["index"]): int(q["appearance"]) for q in prone.requests} == {0: Appearance.PRONE}
    gone = r.advance(2.0)
    assert gone.removed.tolist() == [0] and gone.reasons.tolist() == [RemoveReason.REMOVED]
    assert r.advance(3.0).removed.tolist() == [1]
    assert r.translator.stats["removed_by_pdu"] == 2 and r.translator.stats["removed_timeout"] == 0


def test_a_skipped_start_keeps_removed_entities_removed() -> None:
    log = read_bytes(pcap_of([(0.0, espdu(1)), (1.0, espdu(2)), (2.0, remove(1)), (8.0, espdu(2))]))
    r = Replayer(LogCursor(log), origin=FRAME, start=5.0)
    out = r.advance(0.0)
    assert out.created["slot"].tolist() == [1] and r.translator.alive == 1


def test_gateway_puts_an_update_on_an_entity_state_heard_a_burst_before() -> None:
    gw = DisGateway(GatewayConfig(port=0, origin=FRAME))
    made = gw.handle([espdu(1)], 10.0)
    assert made.created["slot"].tolist() == [0]
    moved = gw.handle([update(1, 2.0, state=LifeformState.KNEELING), update(5, 0.0)], 11.0)
    ((row,),) = [moved.requests]  # one request: entity 1 kneels where the update says
    assert int(row["appearance"]) == Appearance.KNEEL and row["position"][0] == pytest.approx(2.0, abs=1e-4)
    assert gw.status["entity_state_updates"] == 2 and gw.status["updates_without_base"] == 1
    out = gw.handle([remove(1)], 12.0)
    assert out.removed.tolist() == [0] and gw.translator.alive == 0
    assert math.isclose(gw.translator.last_seen[0], 11.0)
