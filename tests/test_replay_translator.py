"""The DIS -> TTES translator, the log cursor, the entity filter and the replayer: pure, no sockets."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import SHARED
from hypothesis import given
from hypothesis import strategies as st

from client_stub.dis import DisTranslator, EntityFilter, FilterError, RemoveReason, Replayer, Translation
from client_stub.dis.translator import REACTION_MAX_AGE
from protocol.dis import (
    RIFLE_FIGURES,
    DisLog,
    EntityId,
    EntityStatePdu,
    EntityType,
    LocalFrame,
    WeaponEvent,
    encode_appearance,
    make_marking,
    orientation_from_heading,
    read_bytes,
)
from protocol.dis.appearance import Health, LifeformState, WeaponState
from protocol.dis.batch import batch_from_pdus
from protocol.dis.logfile import PDU_INDEX_DTYPE
from protocol.entity import Appearance
from protocol.entity import WeaponState as W

FRAME = LocalFrame(38.52, -77.44, 60.0)
M16_TYPE = EntityType(3, 1, 225, 12, 5, 41, 0)
AK_TYPE = EntityType(3, 1, 222, 1, 205, 1, 0)


def pdu(
    entity: int,
    xy: tuple[float, float] = (0.0, 0.0),
    speed: float = 0.0,
    heading: float = 0.0,
    state: int = LifeformState.UPRIGHT_STANDING,
    weapon: int = WeaponState.DEPLOYED,
    *,
    force: int = 1,
    health: int = Health.NO_INJURY,
    deactivated: bool = False,
    alg: int = 2,
    paint: int = 0,
    marking: str = "",
) -> EntityStatePdu:
    local = np.array([xy[0], xy[1], 0.0])
    ecef = FRAME.to_ecef(local)
    h = math.radians(heading)
    vel = FRAME.vector_to_ecef(np.array([speed * math.sin(h), speed * math.cos(h), 0.0]))
    app = encode_appearance(
        health=health, state=state, weapon1=weapon, deactivated=deactivated, paint_scheme=paint, camouflage=2
    )
    return EntityStatePdu(
        entity_id=EntityId(1, 2, entity),
        force_id=force,
        entity_type=M16_TYPE if force == 1 else AK_TYPE,
        velocity=tuple(vel.tolist()),
        location=tuple(ecef.tolist()),
        orientation=tuple(orientation_from_heading(ecef, heading).tolist()),
        appearance=int(app),
        dr_algorithm=alg,
        marking=make_marking(marking or f"E{entity}"),
    )


def feed(
    tr: DisTranslator, now: float, *pdus: EntityStatePdu, events: tuple[WeaponEvent, ...] = ()
) -> Translation:
    batch = batch_from_pdus(list(pdus)) if pdus else None
    return tr.step(now, batch, np.full(len(pdus), now) if pdus else None, events)


def fire(t: float, shooter: int, target: int = 99) -> WeaponEvent:
    return WeaponEvent("fire", t, EntityId(1, 2, shooter), EntityId(1, 2, target), EntityType(), (0.0,) * 3,
                       EntityId(1, 2, 1), range=100.0)  # fmt: skip


def requests_of(t: Translation) -> dict[int, tuple[int, int]]:
    return {int(r["index"]): (int(r["appearance"]), int(r["weapon"])) for r in t.requests}


# -- the entity table ----------------------------------------------------------------------------
def test_one_soldier_per_entity_created_on_first_sight_with_rifle_force_and_camouflage() -> None:
    tr = DisTranslator(FRAME)
    out = feed(tr, 0.0, pdu(7), pdu(3, (5.0, 0.0), force=2, paint=1), pdu(7, (1.0, 0.0)))
    assert out.created["slot"].tolist() == [0, 1]  # first appearance order; entity 7 twice = one soldier
    assert out.created["entity"].tolist() == [[1, 2, 7], [1, 2, 3]]
    assert out.created["force"].tolist() == [1, 2]
    assert out.created["rifle"].tolist() == [0, 1]  # M16, AK
    assert out.created["paint"].tolist() == [0, 1] and out.created["camouflage"].tolist() == [2, 2]
    assert out.created["marking"].tolist() == [b"E7", b"E3"]
    assert requests_of(out) == {0: (Appearance.UPRIGHT, W.DEPLOYED), 1: (Appearance.UPRIGHT, W.DEPLOYED)}
    # the last PDU of an entity wins: entity 7 stands at x = 1
    assert out.requests["position"][0][:2] == pytest.approx([1.0, 0.0], abs=1e-3)
    assert tr.alive == 2 and tr.count == 2


def test_requests_only_when_posture_weapon_velocity_or_heading_change() -> None:
    tr = DisTranslator(FRAME)
    feed(tr, 0.0, pdu(1))
    assert not feed(tr, 5.0, pdu(1)).requests.size  # a heartbeat: nothing new
    assert not feed(tr, 6.0, pdu(1, heading=0.3)).requests.size  # below the heading threshold
    kneel = feed(tr, 7.0, pdu(1, state=LifeformState.KNEELING))
    assert requests_of(kneel) == {0: (Appearance.KNEEL, W.DEPLOYED)}
    walk = feed(tr, 8.0, pdu(1, speed=1.4, heading=90.0, state=LifeformState.UPRIGHT_WALKING))
    (row,) = walk.requests
    assert row["appearance"] == Appearance.UPRIGHT and row["heading"] == pytest.approx(90.0, abs=1e-3)
    assert row["velocity"] == pytest.approx([1.4, 0.0, 0.0], abs=1e-4)
    crawl = feed(tr, 9.0, pdu(1, speed=0.4, state=LifeformState.CRAWLING))
    assert requests_of(crawl) == {0: (Appearance.CRAWL, W.DEPLOYED)}
    dead = feed(tr, 10.0, pdu(1, state=LifeformState.PRONE, weapon=0, health=Health.FATAL))
    assert requests_of(dead) == {0: (Appearance.DEAD, W.STOWED)}


def test_timeout_removes_and_reappearance_gets_the_same_slot() -> None:
    tr = DisTranslator(FRAME, timeout=12.0)
    feed(tr, 0.0, pdu(1), pdu(2))
    feed(tr, 10.0, pdu(2))
    assert not feed(tr, 12.0).removed.size  # exactly 12 s: not yet
    gone = feed(tr, 12.5)
    assert gone.removed.tolist() == [0] and gone.reasons.tolist() == [RemoveReason.TIMEOUT]
    assert tr.alive == 1
    back = feed(tr, 20.0, pdu(3), pdu(1, state=LifeformState.KNEELING))
    assert back.created["slot"].tolist() == [2, 0]  # newcomer gets a new slot, entity 1 his old one
    assert requests_of(back)[0] == (Appearance.KNEEL, W.DEPLOYED)  # a full request for the re-created soldier
    assert tr.stats["recreated"] == 1 and tr.stats["removed_timeout"] == 1


def test_deactivated_entity_is_removed_not_killed_and_may_come_back() -> None:
    tr = DisTranslator(FRAME)
    feed(tr, 0.0, pdu(1), pdu(2))
    out = feed(tr, 1.0, pdu(1, deactivated=True))
    assert out.removed.tolist() == [0] and out.reasons.tolist() == [RemoveReason.DEACTIVATED]
    assert not out.requests.size and not out.created.size
    assert not feed(tr, 2.0, pdu(1, deactivated=True)).removed.size  # removed once
    again = feed(tr, 3.0, pdu(1))
    assert again.created["slot"].tolist() == [0]


def test_pdus_with_unusable_numbers_are_dropped_not_sent() -> None:
    """NaN or infinite fields, or a location far off the Earth: the server would refuse the request batch."""
    good = pdu(1)
    bad = [
        dataclasses.replace(pdu(2), velocity=(math.nan, 0.0, 0.0)),
        dataclasses.replace(pdu(3), orientation=(0.0, math.inf, 0.0)),
        dataclasses.replace(pdu(4), location=(1e300, 0.0, 0.0)),
        dataclasses.replace(pdu(5), angular_velocity=(0.0, 0.0, -math.inf)),
    ]
    tr = DisTranslator(FRAME)
    out = feed(tr, 0.0, *bad, good)
    assert out.created["slot"].tolist() == [0] and tr.stats["bad_values"] == 4
    assert np.isfinite(out.requests["velocity"]).all() and np.isfinite(out.requests["position"]).all()


def test_dead_reckoning_uses_each_entitys_algorithm() -> None:
    tr = DisTranslator(FRAME)
    feed(
        tr,
        0.0,
        pdu(1, (0.0, 0.0), speed=2.0, heading=90.0),
        pdu(2, (10.0, 0.0), speed=2.0, heading=0.0, alg=1),
    )
    pos, heading = tr.dead_reckoned(1.5)
    assert pos[0][:2] == pytest.approx([3.0, 0.0], abs=1e-3)  # FPW: moves along its velocity
    assert pos[1][:2] == pytest.approx([10.0, 0.0], abs=1e-3)  # STATIC: stays
    assert heading == pytest.approx([90.0, 0.0], abs=1e-3)


def test_fire_pdu_raises_a_short_firing_reaction_for_a_standing_still_shooter() -> None:
    tr = DisTranslator(FRAME, fire_hold=1.0)
    feed(
        tr,
        0.0,
        pdu(1),
        pdu(2, speed=1.4, state=LifeformState.UPRIGHT_WALKING),
        pdu(3, weapon=WeaponState.FIRING),
    )
    out = feed(tr, 2.0, events=(fire(2.0, 1), fire(2.0, 2), fire(2.0, 3), fire(2.0, 42)))
    assert requests_of(out) == {
        0: (Appearance.UPRIGHT, W.FIRING)
    }  # the walker keeps walking; 3 already fires
    assert out.fire_reactions.tolist() == [0]
    assert out.recoils.tolist() == [0, 1, 2]  # every live shooter recoils (the server skips the walker)
    assert not feed(tr, 2.5).requests.size  # still holding
    assert requests_of(feed(tr, 3.0)) == {0: (Appearance.UPRIGHT, W.DEPLOYED)}  # hold over: back to the PDU's
    # the PDUs stay the authority: a new posture during the hold ends the reaction
    assert requests_of(feed(tr, 4.0, events=(fire(4.0, 1),))) == {0: (Appearance.UPRIGHT, W.FIRING)}
    assert requests_of(feed(tr, 4.2, pdu(1, state=LifeformState.KNEELING))) == {
        0: (Appearance.KNEEL, W.DEPLOYED)
    }
    assert not feed(tr, 5.5).requests.size


def test_detonations_near_soldiers_flinch_them_and_are_counted() -> None:
    tr = DisTranslator(FRAME)
    feed(tr, 0.0, pdu(1, (0.0, 0.0)), pdu(2, (20.0, 0.0)))
    where = tuple(FRAME.to_ecef(np.array([1.0, 1.0, 0.0])).tolist())
    det = WeaponEvent("detonation", 1.0, EntityId(1, 2, 9), EntityId(1, 2, 1), EntityType(), where,
                      EntityId(1, 2, 5), result=1)  # fmt: skip
    out = feed(tr, 1.0, events=(det,))
    assert not out.requests.size and out.flinches.tolist() == [0]
    assert tr.near_detonations[:2].tolist() == [1, 0] and tr.stats["detonations"] == 1
    # a late event (a replay's skipped start) is counted, but nobody reacts to it
    late = feed(tr, 1.0 + REACTION_MAX_AGE + 0.1, events=(det,))
    assert not len(late.flinches) and tr.near_detonations[0] == 2


def test_full_table_reuses_the_slot_gone_longest_then_drops() -> None:
    tr = DisTranslator(FRAME, capacity=2, timeout=1.0)
    feed(tr, 0.0, pdu(1))
    feed(tr, 0.5, pdu(2))
    feed(tr, 3.0)  # both time out (1 last seen at 0, 2 at 0.5)
    out = feed(tr, 3.1, pdu(3))
    assert out.created["slot"].tolist() == [0] and tr.stats["slots_reused"] == 1
    assert tr.slots_of(np.array([(1 << 32) | (2 << 16) | 1], np.uint64)).tolist() == [-1]  # entity 1 lost it
    feed(tr, 3.2, pdu(4))  # slot 1
    out = feed(tr, 3.3, pdu(5))
    assert not out.created.size and tr.stats["dropped"] == 1


def test_merge_cancels_a_creation_removed_later_in_the_same_step() -> None:
    tr = DisTranslator(FRAME)
    a = feed(tr, 0.0, pdu(1))
    b = tr.reset()
    m = Translation.merge([a, b])
    assert not m.created.size and not m.removed.size and not m.requests.size
    c = feed(tr, 1.0, pdu(1))
    m2 = Translation.merge([b, c])
    assert m2.removed.tolist() == [0] and m2.created["slot"].tolist() == [0] and len(m2.requests) == 1


@pytest.mark.fuzz
@given(st.lists(st.tuples(st.integers(1, 6), st.floats(0, 30), st.sampled_from([1, 2, 4, 5, 6]),
                          st.booleans()), max_size=40))  # fmt: skip
def test_translator_invariants_under_random_streams(stream: list[tuple[int, float, int, bool]]) -> None:
    """Whatever arrives: one slot per entity for good, live soldiers are exactly those created and not yet
    removed, and requests only name live soldiers."""
    tr = DisTranslator(FRAME, timeout=3.0)
    live: set[int] = set()
    slot_of: dict[int, int] = {}
    t = 0.0
    for entity, dt, state, deact in stream:
        t += dt / 10.0
        out = feed(tr, t, pdu(entity, state=state, deactivated=deact))
        live -= set(out.removed.tolist())
        for row in out.created:
            s = int(row["slot"])
            assert s not in live
            e = int(row["entity"][2])
            assert slot_of.setdefault(e, s) == s
            live.add(s)
        assert set(out.requests["index"].tolist()) <= live
        assert set(tr.live_slots().tolist()) == live


def test_a_real_captured_soldier_pdu() -> None:
    """A DIS 7 Entity State PDU of an AK-74 rifleman captured by another project (../shared/dis-samples)."""
    sample = SHARED / "dis-samples" / "001_entity_state.DI_AK74"
    if not sample.exists():
        pytest.skip("shared DIS samples absent")
    log = read_bytes(sample.read_bytes(), fmt="raw")
    tr = DisTranslator()
    out = tr.step(0.0, log.batch, np.zeros(len(log.batch)))
    (row,) = out.created
    assert row["entity"].tolist() == [50, 126, 28] and row["force"] == 2 and row["marking"] == b"RM/A/SQD4"
    assert RIFLE_FIGURES[int(row["rifle"])] == "AK_47.fig"
    assert requests_of(out) == {0: (Appearance.UPRIGHT, W.DEPLOYED)}
    assert out.requests["position"][0] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)  # the origin: itself
    pos, _ = tr.dead_reckoned(30.0)  # dead reckoning 1 (static): stays put
    assert pos[0] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


# -- the entity filter ---------------------------------------------------------------------------
def test_entity_filter_terms() -> None:
    pdus = [pdu(1, force=1, marking="SQD4-A"), pdu(2, force=2, marking="RED-1"), pdu(3, force=1, marking="X")]
    rec = batch_from_pdus(pdus).records
    assert EntityFilter.parse("1:2:2").mask(rec).tolist() == [False, True, False]
    assert EntityFilter.parse("1:*:3, opposing").mask(rec).tolist() == [False, True, True]
    assert EntityFilter.parse("force=1").mask(rec).tolist() == [True, False, True]
    assert EntityFilter.parse("marking=SQD4*").mask(rec).tolist() == [True, False, False]
    assert EntityFilter.parse("marking=X").mask(rec).tolist() == [False, False, True]
    with pytest.raises(FilterError, match="character 6: 'force=x'") as e:
        EntityFilter.parse("1:*:3,force=x")
    assert e.value.position == 6
    with pytest.raises(FilterError, match="empty term"):
        EntityFilter.parse("1:2:3,,friendly")
    with pytest.raises(FilterError, match=r"0\.\.65535"):
        EntityFilter.parse("70000:1:1")


@pytest.mark.fuzz
@given(st.text(max_size=40))
def test_entity_filter_parse_never_fails_otherwise(text: str) -> None:
    try:
        f = EntityFilter.parse(text)
    except FilterError as exc:
        assert 0 <= exc.position <= len(text)
    else:
        assert f.mask(batch_from_pdus([pdu(1)]).records).shape == (1,)


# -- the replayer --------------------------------------------------------------------------------
def make_log(entries: list[tuple[float, EntityStatePdu]], events: list[WeaponEvent] | None = None) -> DisLog:
    batch = batch_from_pdus([p for _, p in entries])
    times = np.array([t for t, _ in entries])
    pdus = np.zeros(len(entries), PDU_INDEX_DTYPE)
    pdus["t"] = times
    return DisLog(
        "test", "raw", batch, times, events or [], pdus, {}, {}, [], float(times.min()), float(times.max())
    )


def test_replayer_paces_by_receipt_time_and_speed() -> None:
    log = make_log([(100.0, pdu(1)), (101.0, pdu(1, state=LifeformState.KNEELING)), (104.0, pdu(2))])
    r = Replayer(log, speed=2.0, origin=FRAME)
    assert requests_of(r.advance(0.0)) == {0: (Appearance.UPRIGHT, W.DEPLOYED)}
    assert r.next_due() == pytest.approx(0.5)
    assert not r.advance(0.49)
    assert requests_of(r.advance(0.5)) == {0: (Appearance.KNEEL, W.DEPLOYED)}
    assert r.advance(2.0).created["slot"].tolist() == [1]
    assert r.finished and r.pdus == 3 and r.replay_time == pytest.approx(4.0)
    assert r.finish().removed.tolist() == [0, 1]


def test_replayer_start_skips_ahead_with_the_state_at_that_time() -> None:
    log = make_log([(0.0, pdu(1)), (1.0, pdu(1, state=LifeformState.PRONE)), (5.0, pdu(2)), (6.0, pdu(2))])
    r = Replayer(log, start=3.0, origin=FRAME)
    out = r.advance(0.0)
    assert out.created["slot"].tolist() == [0] and requests_of(out) == {0: (Appearance.PRONE, W.DEPLOYED)}
    assert r.advance(2.0).created["slot"].tolist() == [1]


def test_replayer_loops_with_the_same_slots_and_a_monotonic_clock() -> None:
    log = make_log([(0.0, pdu(1)), (2.0, pdu(2))])
    r = Replayer(log, loop=True, origin=FRAME)
    r.advance(0.0)
    r.advance(2.0)
    out = r.advance(3.0)  # the end + the loop gap: everybody removed, the log restarts
    assert sorted(out.removed.tolist()) == [0, 1] and r.loops == 1
    again = r.advance(3.0 + 0.01)
    assert again.created["slot"].tolist() == [0]  # entity 1 again, same soldier
    assert r.now >= 3.0 and r.translator.now >= 3.0


def test_unlimited_speed_processes_everything_in_chunks() -> None:
    log = make_log([(float(t), pdu(1 + t % 3, (t * 0.1, 0.0))) for t in range(50)])
    r = Replayer(log, speed=math.inf, origin=FRAME)
    steps = 0
    while not r.finished:
        r.advance(0.0)
        steps += 1
    assert r.pdus == 50 and r.translator.count == 3 and steps <= 60
