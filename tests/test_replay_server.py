"""`ttes replay`'s core against a real server over TCP, under trio's autojump clock: a synthetic squad
exercise (written by `ttes dis synth`) replayed at its capture times; every soldier must reach the postures
its PDUs asked for, in order, walking / running / crawling when its PDUs say it moves."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trio
from test_replay_support import (
    MAX_LAG,
    Monitor,
    entity_key,
    expected_activities,
    match_in_order,
    server_times,
)
from test_replay_translator import FRAME, make_log, pdu
from test_server_support import running_server

from client_stub.dis import Replayer
from client_stub.dis.drive import ProgressLine, replay_to_server
from client_stub.dis.sink import ServerSink
from client_stub.link.client import Client
from protocol.dis import read_log
from protocol.dis.appearance import LifeformState
from server.config import DEFAULT_DATA_DIR
from ttes.cli import main


def synth_pcap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], soldiers: int = 4, seconds: float = 40.0
) -> Path:
    out = tmp_path / "squad.pcap"
    args = ["dis", "synth", "--out", str(out), "--soldiers", str(soldiers), "--seconds", str(seconds)]
    assert main([*args, "--seed", "3"]) == 0
    capsys.readouterr()
    return out


async def test_synthetic_pcap_replay_soldiers_follow_their_pdus_in_order(
    autojump_clock: trio.abc.Clock, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = read_log(synth_pcap(tmp_path, capsys))
    expected = expected_activities(log)
    assert len(expected) == 4
    async with running_server(throttle=0.0) as server, trio.open_nursery() as nursery:
        monitor = Monitor(server)
        nursery.start_soon(monitor.run)
        link = Client()
        await link.open(nursery, "127.0.0.1", server.addresses[0][1])
        sink = ServerSink(link)
        assert sink.base == 10  # after the start-up script's s0..s9
        replayer = Replayer(log)
        t0 = trio.current_time()
        status = await replay_to_server(replayer, sink, progress=ProgressLine(out=None), finish=False)
        await trio.sleep(MAX_LAG)  # the last requests play out
        m = server.world.manager
        for entity, seq in expected.items():
            slot = int(replayer.translator.slots_of(np.array([entity_key(entity)]))[0])
            index = sink.base + slot
            seen = monitor.seen[index]
            problems = match_in_order(server_times(seq, replayer.cursor.t0, t0), seen)
            assert not problems, (entity, problems, [s[2] for s in seen])
            assert {"WALK", "RUN"} <= {a for _, a in seq}
        everything = {a for seq in expected.values() for _, a in seq}
        assert {"KNEEL_STOWED", "KNEEL_FIRE", "PRONE_STOWED", "PRONE_FIRE", "CRAWLING", "DEAD"} <= everything
        victim = expected[(1, 2, 2)]  # the first opposing soldier is killed at 60 %
        assert victim[-1][1] == "DEAD"
        victim_slot = int(replayer.translator.slots_of(np.array([entity_key((1, 2, 2))]))[0])
        assert m.soldier_info(sink.base + victim_slot)["posture"] == "DEAD"
        # the squad: created once each, no server complaints, M16 soldiers on the AK-only synthetic library
        assert status["created"] == 4 and status["sink_created"] == 4 and status["removed_timeout"] == 0
        assert status["sink_weapon_substituted"] == 2 and sink.weapon_of[sink.base] == "AK_47.fig"
        assert not link.errors
        assert status["pdus"] == sum(log.counters[k] for k in ("pdus",))
        # the end of a replay removes its soldiers from the server
        sink.apply(replayer.finish())
        await trio.sleep(0.5)
        assert [i for i in m.table.live.tolist() if i >= sink.base] == []
        await link.aclose()
        nursery.cancel_scope.cancel()


async def test_timeout_removes_the_soldier_and_reappearance_reuses_its_server_index(
    autojump_clock: trio.abc.Clock,
) -> None:
    """An entity silent for longer than the DIS timeout loses its soldier; when it speaks again (kneeling) it
    gets the same server index back; a deactivated entity's soldier goes at once. Replayed at 4x."""
    entries = [(float(t), pdu(1)) for t in range(0, 6)] + [(float(t), pdu(2)) for t in range(0, 40, 5)]
    entries += [(30.0, pdu(1, state=LifeformState.KNEELING)), (36.0, pdu(2, deactivated=True))]
    entries.sort(key=lambda e: e[0])
    log = make_log(entries)
    async with running_server(throttle=0.0) as server, trio.open_nursery() as nursery:
        link = Client()
        await link.open(nursery, "127.0.0.1", server.addresses[0][1])
        sink = ServerSink(link)
        replayer = Replayer(log, speed=4.0, origin=FRAME)
        m = server.world.manager
        live: list[tuple[float, bool, bool]] = []

        async def watch() -> None:
            while True:
                live.append((trio.current_time(), m.table.is_live(sink.base), m.table.is_live(sink.base + 1)))
                await trio.sleep(0.1)

        t0 = trio.current_time()
        nursery.start_soon(watch)
        await replay_to_server(replayer, sink, finish=False)
        await trio.sleep(2.0)
        info = m.soldier_info(sink.base)

        def at(log_t: float) -> tuple[bool, bool]:
            row = min(live, key=lambda r: abs(r[0] - (t0 + log_t / 4.0)))
            return row[1], row[2]

        assert at(3.0) == (True, True)
        assert at(16.0) == (True, True)  # last PDU of entity 1 at 5 s: 12 s timeout not over
        assert at(20.0) == (False, True)  # timed out
        assert at(31.0) == (True, True)  # back, same index
        assert at(37.0) == (True, False)  # deactivated
        assert info["goal"] in ("KNEEL_STOWED", None) and info["posture"] in ("KNEEL_STOWED", "STAND_STOWED")
        assert replayer.translator.stats["recreated"] == 1 and sink.stats["created"] == 3
        assert not [e for e in link.errors if e.code < 100]
        await link.aclose()
        nursery.cancel_scope.cancel()


async def test_unlimited_speed_replays_everything_with_back_pressure(
    autojump_clock: trio.abc.Clock, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = read_log(synth_pcap(tmp_path, capsys, soldiers=6, seconds=20.0))
    async with running_server(throttle=0.0) as server, trio.open_nursery() as nursery:
        link = Client()
        await link.open(nursery, "127.0.0.1", server.addresses[0][1])
        sink = ServerSink(link)
        replayer = Replayer(log, speed=math.inf)
        t0 = trio.current_time()
        status = await replay_to_server(replayer, sink, drain=link.drain)
        assert trio.current_time() - t0 < 1.0  # 20 s of exercise, no pacing
        assert status["pdus"] == log.counters["pdus"] and status["created"] == 6
        await trio.sleep(0.5)
        assert not link.errors
        assert [
            i for i in server.world.manager.table.live.tolist() if i >= sink.base
        ] == []  # finished: removed
        await link.aclose()
        nursery.cancel_scope.cancel()


async def test_replay_hands_friendly_soldiers_m16s_and_opposing_ones_ak47s(
    autojump_clock: trio.abc.Clock, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 16: with the shipped library (M16 graphs bound) nobody's rifle is substituted any more: the
    entity type's rifle (US M16A2 → M16.fig, CIS AK → AK_47.fig) is the figure set the soldier plays."""
    log = read_log(synth_pcap(tmp_path, capsys, soldiers=4, seconds=4.0))
    data = str(DEFAULT_DATA_DIR)
    async with (
        running_server(throttle=0.0, share_library=False, data_dir=data) as server,
        trio.open_nursery() as n,
    ):
        link = Client()
        await link.open(n, "127.0.0.1", server.addresses[0][1])
        sink = ServerSink(link)
        replayer = Replayer(log)
        status = await replay_to_server(replayer, sink, progress=ProgressLine(out=None), finish=False)
        await trio.sleep(0.5)
        assert status["sink_created"] == 4 and status["sink_weapon_substituted"] == 0
        m, lib = server.world.manager, server.world.library
        tr = replayer.translator
        played = {}
        for entity in expected_activities(log):
            slot = int(tr.slots_of(np.array([entity_key(entity)]))[0])
            index = sink.base + slot
            assert sink.weapon_of[index] == lib.set_keys[int(m.table.fset[index])][1]  # asked for = played
            played[int(tr.force[slot])] = played.get(int(tr.force[slot]), set()) | {sink.weapon_of[index]}
        assert played == {1: {"M16.fig"}, 2: {"AK_47.fig"}}  # friendly: M16; opposing: AK-47
        await link.aclose()
        n.cancel_scope.cancel()
