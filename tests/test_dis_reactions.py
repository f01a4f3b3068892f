"""Fire and Detonation PDUs make soldiers react (issue 16), end to end: constructed PDUs (the real encoders)
replayed from a log and sent to the live gateway over loopback UDP, into a server with the shipped library,
under trio's autojump clock. The shooter recoils in his posture; every soldier within FLINCH_RADIUS of a
detonation flinches in his; the others do not react."""

from __future__ import annotations

import socket

import numpy as np
import pytest
import trio
from test_replay_translator import FRAME, feed, make_log, pdu
from test_server_support import running_server

from client_stub.dis import DisTranslator, Replayer
from client_stub.dis.drive import ProgressLine, replay_to_server
from client_stub.dis.gateway import DisGateway, GatewayConfig
from client_stub.dis.sink import ServerSink
from client_stub.dis.translator import FLINCH_RADIUS
from client_stub.link.client import Client
from protocol.dis import EntityId
from protocol.dis.appearance import LifeformState, WeaponState
from protocol.dis.entity_state import encode_entity_state
from protocol.dis.warfare import DetonationPdu, FirePdu, encode_detonation, encode_fire, weapon_event
from server.config import DEFAULT_DATA_DIR

SHOOTER, NEAR, FAR, KNEELER = 1, 2, 3, 4
PLACES = {SHOOTER: (0.0, 0.0), NEAR: (8.0, 0.0), FAR: (20.0, 0.0), KNEELER: (6.0, 3.5)}
STATES = {KNEELER: LifeformState.KNEELING}
BLAST = (9.0, 1.0)  # NEAR 1.4 m, KNEELER 4.2 m, SHOOTER 9.1 m, FAR 11 m away
T_FIRE, T_BLAST, T_END = 4.0, 6.0, 9.0


def entity_states(t: float) -> list[tuple[float, bytes]]:
    return [
        (t, encode_entity_state(pdu(e, xy, state=STATES.get(e, LifeformState.UPRIGHT_STANDING))))
        for e, xy in PLACES.items()
    ]


def weapon_pdus() -> list[tuple[float, bytes]]:
    fire = FirePdu(shooter=EntityId(1, 2, SHOOTER), event_id=EntityId(1, 2, 1), range=100.0,
                   location=tuple(FRAME.to_ecef(np.array([0.0, 0.0, 1.4])).tolist()))  # fmt: skip
    blast = DetonationPdu(shooter=EntityId(1, 2, 9), event_id=EntityId(1, 2, 2),
                          location=tuple(FRAME.to_ecef(np.array([*BLAST, 0.5])).tolist()))  # fmt: skip
    return [(T_FIRE, encode_fire(fire)), (T_BLAST, encode_detonation(blast))]


def traffic() -> list[tuple[float, bytes]]:
    """Every soldier's Entity State PDU each second, the Fire and the Detonation: (time, datagram)."""
    out = [p for k in range(int(T_END) + 1) for p in entity_states(float(k))]
    return sorted(out + weapon_pdus(), key=lambda p: p[0])


def reactions(server, sink: ServerSink, slot_of: dict[int, int]) -> dict[int, list[str]]:  # type: ignore[no-untyped-def]
    """Per entity, the reaction clips its soldier played (stems, in order)."""
    m = server.world.manager
    out = {}
    for e, slot in slot_of.items():
        clips = [c.clip.rsplit("/", 1)[-1].removesuffix("_low") for c in m.clips_of(sink.base + slot)]
        out[e] = [c for c in clips if c.endswith(("_recoil", "_flinch"))]
    return out


EXPECTED = {SHOOTER: ["stfire_recoil"], NEAR: ["ststow_flinch"], FAR: [], KNEELER: ["kstow_flinch"]}


def test_the_scenario_puts_the_blast_where_the_test_says() -> None:
    d = {e: float(np.hypot(x - BLAST[0], y - BLAST[1])) for e, (x, y) in PLACES.items()}
    assert d[NEAR] < FLINCH_RADIUS and d[KNEELER] < FLINCH_RADIUS
    assert d[SHOOTER] > FLINCH_RADIUS and d[FAR] > FLINCH_RADIUS


async def test_replayed_fire_recoils_the_shooter_and_a_near_blast_flinches_the_soldiers_near_it(
    autojump_clock: trio.abc.Clock,
) -> None:
    entries = [(t, pdu(e, xy, state=STATES.get(e, LifeformState.UPRIGHT_STANDING)))
               for t in range(int(T_END) + 1) for e, xy in PLACES.items()]  # fmt: skip
    log = make_log([(float(t), p) for t, p in entries], [weapon_event(b, t) for t, b in weapon_pdus()])
    async with running_server(throttle=0.0, share_library=False, data_dir=str(DEFAULT_DATA_DIR)) as server:
        server.world.manager.configure(record_clips=True)
        async with trio.open_nursery() as nursery:
            link = Client()
            await link.open(nursery, "127.0.0.1", server.addresses[0][1])
            sink = ServerSink(link)
            replayer = Replayer(log, origin=FRAME)
            await replay_to_server(replayer, sink, progress=ProgressLine(out=None), finish=False)
            await trio.sleep(2.0)
            keys = {e: (1 << 32) | (2 << 16) | e for e in PLACES}
            slots = replayer.translator.slots_of(np.array(list(keys.values()), np.uint64))
            got = reactions(server, sink, dict(zip(keys, slots.tolist(), strict=True)))
            assert got == EXPECTED
            assert sink.stats["reactions"] == 3 and not link.errors
            await link.aclose()
            nursery.cancel_scope.cancel()


async def test_the_gateway_plays_the_same_reactions_from_live_udp(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.0, share_library=False, data_dir=str(DEFAULT_DATA_DIR)) as server:
        server.world.manager.configure(record_clips=True)
        async with trio.open_nursery() as nursery:
            link = Client("ttes-gateway")
            await link.open(nursery, "127.0.0.1", server.addresses[0][1])
            sink = ServerSink(link)
            gateway = DisGateway(GatewayConfig(port=0, interface="127.0.0.1", origin=FRAME))
            await nursery.start(gateway.serve, sink)
            sender = trio.socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            t0 = trio.current_time()
            for t, data in traffic():
                await trio.sleep_until(t0 + t)
                await sender.sendto(data, gateway.address)
            await trio.sleep(2.0)
            keys = np.array([(1 << 32) | (2 << 16) | e for e in PLACES], np.uint64)
            slots = gateway.translator.slots_of(keys).tolist()
            assert reactions(server, sink, dict(zip(PLACES, slots, strict=True))) == EXPECTED
            assert not link.errors
            await link.aclose()
            nursery.cancel_scope.cancel()


@pytest.mark.parametrize("weapon", [WeaponState.DEPLOYED, WeaponState.FIRING])
def test_translator_names_the_shooter_and_the_soldiers_within_the_flinch_radius(weapon: int) -> None:
    tr = DisTranslator(FRAME)
    feed(tr, 0.0, *[pdu(e, xy, state=STATES.get(e, LifeformState.UPRIGHT_STANDING), weapon=weapon)
                    for e, xy in PLACES.items()])  # fmt: skip
    fire, blast = (weapon_event(b, t) for t, b in weapon_pdus())
    out = feed(tr, T_FIRE, events=(fire,))
    assert out.recoils.tolist() == [0] and not len(out.flinches)
    out = feed(tr, T_BLAST, events=(blast,))
    assert sorted(out.flinches.tolist()) == [1, 3] and not len(out.recoils)
