"""The trio server over real TCP (127.0.0.1, port 0) with trio's autojump clock: handshake, ready, soldiers,
subscriptions, full then delta updates, request errors, roles, shutdown."""

from __future__ import annotations

import numpy as np
import pytest
import trio
from test_server_support import Client, running_server

from protocol.entity import Appearance, Reaction, WeaponState
from protocol.errors import ErrorCode
from protocol.events import (
    CreateSoldier,
    Error,
    Goodbye,
    Hello,
    JointUpdates,
    Ping,
    Pong,
    React,
    Ready,
    RemoveSoldier,
    RequestFullUpdate,
    SoldierCreated,
    Status,
    Subscribe,
    Unsubscribe,
    UpdateTableMsg,
)
from server.config import DEFAULT_DATA_DIR
from server.soldier.manager import TickUpdate


def port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.addresses[0][1]


async def test_handshake_tables_and_ready_list_the_start_up_soldiers(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        c = await Client.open(port_of(server), "ig-1")
        table = await c.expect(UpdateTableMsg)
        ready = await c.expect(Ready)
        assert table.table.table_id == 1
        assert (table.table.figure, table.table.weapon) == ("DI.fig", "AK_47.fig")
        assert table.table == server.world.sets[0].table
        assert ready.soldiers == tuple((i, 1) for i in range(10))
        await c.send(Ping(42))
        assert (await c.expect(Pong)).nonce == 42
        await c.send(Goodbye("done"))
        await c.until_closed()


async def test_unsupported_version_and_foreign_clients_are_refused(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        c = await Client.open(port_of(server), hello=False)
        # a version-3 HELLO: the connection answers UNSUPPORTED_VERSION and the server closes
        from protocol.framing import encode_frame
        from protocol.messages import CODECS, MessageType

        payload = CODECS[MessageType.HELLO][1](Hello("future", "observer", version=3))
        await c.send_raw(encode_frame(MessageType.HELLO, payload))
        events = await c.until_closed()
        errors = [e for e in c.events if isinstance(e, Error)]
        assert errors and errors[0].code == ErrorCode.UNSUPPORTED_VERSION, events
        assert "supported: [1, 2]" in errors[0].message
        # an HTTP client: the length prefix "GET " is refused after 4 bytes
        h = await Client.open(port_of(server), hello=False)
        await h.send_raw(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        await h.until_closed()
        assert [e.code for e in h.events if isinstance(e, Error)] == [ErrorCode.FRAME_TOO_LARGE]
        # still serving
        ok = await Client.open(port_of(server))
        await ok.expect(Ready)


async def test_a_version_1_client_keeps_its_format_beside_a_version_2_client(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Issue 18: version 2 changed JOINT_UPDATES; a version-1 client is answered in version 1 and decodes the
    same codes as a version-2 client of the same walking soldier (a shared one of the start-up script)."""
    async with running_server(throttle=0.0) as server:
        old = await Client.open(port_of(server), "old", version=1)
        new = await Client.open(port_of(server), "new")
        assert (old.accept.version, new.accept.version) == (1, 2)
        for c in (old, new):
            await c.expect(Ready)
            await c.send(Subscribe((0,)))
        await new.requests(index=0, appearance=Appearance.UPRIGHT, velocity=(0.0, 1.4, 0.0), heading=0.0)
        for c in (old, new):
            assert len([e for e in await c.drain(2.0) if isinstance(e, JointUpdates)]) >= 20
        await new.requests(index=0, appearance=Appearance.UPRIGHT, velocity=(0.0, 0.0, 0.0), heading=0.0)
        for c in (old, new):  # he stops and stands: both end on his resting pose
            await c.drain(4.0)
        dec_old, dec_new = old.conn.decoder(1), new.conn.decoder(1)
        assert dec_old is not None and dec_new is not None
        assert (dec_old.version, dec_new.version) == (1, 2)
        assert np.array_equal(dec_old.codes(np.array([0])), dec_new.codes(np.array([0])))


async def test_create_subscribe_full_then_deltas_and_idle_costs_nothing(
    autojump_clock: trio.abc.Clock,
) -> None:
    async with running_server(throttle=0.0) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.send(CreateSoldier(7, "DI.fig", "AK_47.fig", None))
        created = await c.expect(SoldierCreated)
        assert created.id == 7 and created.index == 10 and created.table == 1
        i = created.index
        await c.send(Subscribe((i,)))
        first = await c.expect(JointUpdates, lambda u: i in u.indices.tolist())
        # the first update of a subscribed soldier is full: every entry present
        row = first.indices.tolist().index(i)
        assert first.changed is not None and first.changed[row].all()
        # resting: nothing more arrives for this soldier
        quiet = [e for e in await c.drain(1.0) if isinstance(e, JointUpdates)]
        assert quiet == []
        # start walking: deltas arrive, only for the changed entries
        await c.requests(index=i, appearance=Appearance.UPRIGHT, velocity=(0.0, 1.4, 0.0), heading=0.0)
        ups = [e for e in await c.drain(2.0) + await c.caught_up(server) if isinstance(e, JointUpdates)]
        assert len(ups) >= 20  # ~30 Hz
        assert all(u.indices.tolist() == [i] for u in ups)
        assert any(not u.changed[0].all() for u in ups[3:])  # some frames carry only part of the soldier
        dofs, _, _ = c.pose(1, i)
        board = server.board_ref.board
        assert board is not None
        np.testing.assert_allclose(dofs, board.dofs[i], atol=2 * np.pi / 4096)
        # unsubscribe: nothing more; re-subscribe: a full update again
        await c.send(Unsubscribe((i,)))
        await c.drain(0.2)
        assert [e for e in await c.drain(1.0) if isinstance(e, JointUpdates)] == []
        await c.send(Subscribe((i,)))
        again = await c.expect(JointUpdates)
        assert again.changed is not None and again.changed[0].all()
        await c.send(RequestFullUpdate(()))
        full = await c.expect(JointUpdates)
        assert full.changed is not None and full.changed[0].all()


async def test_request_errors_leave_the_connection_open(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(max_soldiers_per_client=2) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)

        async def err(ev: object) -> Error:
            await c.send(ev)  # type: ignore[arg-type]
            return await c.expect(Error)

        assert (await err(CreateSoldier(1, "DI.fig", "AK_47.fig", 3))).code == ErrorCode.SOLDIER_EXISTS
        assert (await err(CreateSoldier(2, "Nobody.fig", "AK_47.fig", None))).code == ErrorCode.UNKNOWN_FIGURE
        e = await err(CreateSoldier(3, "DI.fig", "M60.fig", None))
        assert (e.code, e.ref) == (ErrorCode.UNKNOWN_WEAPON, 3)
        assert (await err(RemoveSoldier(500))).code == ErrorCode.UNKNOWN_SOLDIER
        e = await err(__import__("protocol.events", fromlist=["Jcl"]).Jcl("frobnicate();", 9))
        assert (e.code, e.ref) == (ErrorCode.JCL_ERROR, 9) and "unknown command 'frobnicate'" in e.message
        await c.requests(index=[0, 600], velocity=(0.0, 0.0, 0.0))
        e = await c.expect(Error)
        assert e.code == ErrorCode.UNKNOWN_SOLDIER and "no soldier 600" in e.message
        # the per-client soldier limit
        for k in range(2):
            await c.send(CreateSoldier(10 + k, "DI.fig", "", None))
            await c.expect(SoldierCreated)
        assert (await err(CreateSoldier(12, "DI.fig", "", None))).code == ErrorCode.NO_FREE_SOLDIER
        # removing a soldier frees the quota and the index is reused, announced with a full update
        await c.send(RemoveSoldier(10))
        await c.send(CreateSoldier(13, "DI.fig", "AK_47.fig", None))
        assert (await c.expect(SoldierCreated)).index == 10
        await c.send(Ping(1))
        await c.expect(Pong)


async def test_observers_may_watch_but_not_command(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        obs = await Client.open(port_of(server), "watcher", role="observer")
        await obs.expect(Ready)
        await obs.send(CreateSoldier(5, "DI.fig", "AK_47.fig", None))
        e = await obs.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.NOT_PERMITTED, 5)
        await obs.requests(index=0, velocity=(0.0, 1.0, 0.0))
        assert (await obs.expect(Error)).code == ErrorCode.NOT_PERMITTED
        await obs.send(Subscribe((0,)))
        assert 0 in (await obs.expect(JointUpdates)).indices.tolist()


async def test_status_every_report_interval(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(report_interval=2.0, throttle=0.0) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        t0 = trio.current_time()
        s1 = await c.expect(Status)
        assert s1.soldiers == 10 and "10 soldiers" in s1.text
        assert s1.update_rate <= 0.5  # everyone rests: one batch (the first poses), then none
        await c.requests(index=0, velocity=(0.0, 1.4, 0.0))
        s2 = await c.expect(Status)
        s3 = await c.expect(Status)
        assert s3.time - s2.time == pytest.approx(2.0, abs=0.05)
        assert trio.current_time() - t0 <= 6.1
        assert s3.update_rate == pytest.approx(30.0, rel=0.05)  # a walker: one batch per 30 Hz tick
        # the JCL command changes the interval on the fly
        await c.jcl("set_ttes_report_interval(5.0);")
        s4 = await c.expect(Status)
        s5 = await c.expect(Status)
        assert s5.time - s4.time == pytest.approx(5.0, abs=0.05)
        del server


async def test_not_ready_until_a_client_starts_the_simulation(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(startup_script="") as server:
        c = await Client.open(port_of(server))
        await c.send(CreateSoldier(1, "DI.fig", "AK_47.fig", None))
        e = await c.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.NOT_READY, 1)
        # the 1994 way: the client sends the start-up script; READY follows start_ttes_socket_simulation()
        # loading data changes the world: an operator's (issue 17), not a controller's
        await c.jcl('read_file("jack-ttes-soldier_low.jcl");', 2)
        e = await c.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.JCL_ERROR, 2) and "needs the operator role" in e.message
        c = await Client.open(port_of(server), role="operator")
        await c.jcl('read_file("jack-ttes-soldier_low.jcl");', 2)
        # the script loads files in a worker thread (issue 17): autojump's virtual time runs on meanwhile
        await c.expect(UpdateTableMsg, timeout=1e9)
        ready = await c.expect(Ready)
        assert len(ready.soldiers) == 10
        other = await Client.open(port_of(server))
        assert len((await other.expect(Ready)).soldiers) == 10


async def test_graceful_shutdown_says_goodbye(autojump_clock: trio.abc.Clock) -> None:
    server_box = []
    async with trio.open_nursery() as nursery:
        from test_server_support import make_server

        server = make_server()
        server_box.append(server)
        await nursery.start(server.serve)
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        server.shutdown()
        await c.expect(Goodbye)
        await c.until_closed()
    assert server.sessions == {}


async def test_max_clients_refuses_the_next_one_politely(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(max_clients=2) as server:
        a = await Client.open(port_of(server), "a")
        b = await Client.open(port_of(server), "b")
        c = await Client.open(port_of(server), "c", hello=False)
        await c.send(Hello("c"))
        await c.expect(Error, lambda e: e.code == ErrorCode.NOT_PERMITTED and "server full" in e.message)
        await c.expect(Goodbye)
        await c.until_closed()
        await b.send(Goodbye("bye"))
        await b.until_closed()
        await trio.sleep(0.1)
        d = await Client.open(port_of(server), "d")  # a place is free again
        await d.expect(Ready)
        await a.send(Ping(3))
        assert (await a.expect(Pong)).nonce == 3


async def test_report_exposes_each_soldiers_clip(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.requests(index=3, appearance=Appearance.KNEEL)
        await trio.sleep(0.5)
        rep = await c.report('report_ttes_status("s3", "s4");')
        s3, s4 = rep["soldiers"]
        assert (s3["name"], s3["mode"], s3["clip"], s3["goal"]) == (
            "s3",
            "TRANSITION",
            "soldier_low/ststow2kstow_low",
            "KNEEL_STOWED",
        )
        # asked 0.5 s ago; a request's clip starts at its first moving frame (server.soldier.lead_in): the
        # synthetic ststow2kstow eases in, 1-3 frames at 60 fps under one wire step before it
        assert server.now() - 0.5 - 0.04 - 0.05 <= s3["clip_start"] <= server.now() - 0.5 + 0.04
        assert (s4["mode"], s4["posture"]) == ("IDLE", "STAND_STOWED")
        await c.jcl('report_ttes_status("nobody");', 5)
        e = await c.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.JCL_ERROR, 5)


async def test_request_rate_limit_slows_reading_instead_of_queueing(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(max_requests_per_s=100.0) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.drain(2.0)  # the bucket refills to its 1 s burst (100 tokens)
        t0 = trio.current_time()
        await c.requests(index=[k % 10 for k in range(1000)], velocity=(0.0, 1.0, 0.0))  # 1000 rows at once
        await c.send(Ping(11))
        await c.expect(Pong, lambda p: p.nonce == 11)
        # the rows were taken at once, then the server stopped reading until the budget recovered
        assert trio.current_time() - t0 == pytest.approx((1000 + 1 - 100) / 100.0, abs=0.2)
        info = await c.report('report_ttes_status("s0");')
        assert info["soldiers"][0]["mode"] == "LOCO"


async def test_an_m16_soldier_is_served_with_the_m16_library(autojump_clock: trio.abc.Clock) -> None:
    """Issue 16: DI.fig + M16.fig soldiers play the ``*_m16`` graphs; their updates carry the M16's figure.
    The shipped data dir (the synthetic one has no M16 graphs)."""
    async with running_server(throttle=0.0, share_library=False, data_dir=str(DEFAULT_DATA_DIR)) as server:
        c = await Client.open(port_of(server))
        tables = {}
        while True:
            ev = await c.next_event()
            if isinstance(ev, UpdateTableMsg):
                tables[ev.table.table_id] = ev.table
            if isinstance(ev, Ready):
                break
        assert {(t.figure, t.weapon) for t in tables.values()} == {
            ("DI.fig", "AK_47.fig"),
            ("DI.fig", "M16.fig"),
        }
        await c.send(CreateSoldier(1, "DI.fig", "M16.fig", None))
        m16 = await c.expect(SoldierCreated)
        assert tables[m16.table].weapon == "M16.fig"
        ak = 0  # a start-up soldier: DI.fig + AK_47.fig
        await c.send(Subscribe((ak, m16.index)))
        await c.requests(index=[ak, m16.index], appearance=Appearance.KNEEL, velocity=(0.0, 0.0, 0.0))
        await c.drain(3.0)  # both kneel (ststow2kstow: 1.6 s); the client decodes every update
        lib = server.world.library
        sets = {lib.set_keys[s.index][1]: s for s in server.world.sets}
        assert [lib.set_keys[int(k)][1] for k in server.world.manager.table.fset[[ak, m16.index]]] == [
            "AK_47.fig",
            "M16.fig",
        ]
        # the pose each client decoded is that library's KNEEL_STOWED, weapon figure included
        node = lib.node("KNEEL_STOWED")
        clip, direc = int(lib.rest_clip[node]), int(lib.rest_dir[node])
        assert lib.clip_names[clip].endswith("ststow2kstow_low")
        got = {w: c.pose(sets[w].table.table_id, i) for w, i in (("AK_47.fig", ak), ("M16.fig", m16.index))}
        want = {}
        for w, fs in sets.items():
            smp = lib.sets[fs.index].sample(
                np.array([clip]), np.array([0.0]), np.array([direc]), np.array([1.0]), 1.0
            )
            tu = TickUpdate(np.zeros(1, np.int64), smp.joints, smp.figures, np.zeros(1, bool))
            want[w] = fs.converter.convert(tu)
        for w in sets:
            np.testing.assert_allclose(got[w][1], want[w].positions[0], atol=0.002)  # figure placements (m)
        rifle_m16, rifle_ak = got["M16.fig"][1][1], got["AK_47.fig"][1][1]
        assert np.abs(rifle_m16 - rifle_ak).max() > 0.01  # held by its own grip: not the AK's placement


async def test_a_controller_makes_its_soldiers_react_without_jcl(autojump_clock: trio.abc.Clock) -> None:
    """REACT (docs/PROTOCOL.md §5): a resting soldier flinches at once and the first update after the message
    shows it; a soldier asked to fire recoils once the rifle is up; unknown indices are a request error;
    observers may not. The shipped data dir (the synthetic one has no reaction clips)."""
    async with running_server(throttle=0.0, share_library=False, data_dir=str(DEFAULT_DATA_DIR)) as server:
        m = server.world.manager
        m.configure(record_clips=True)
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.send(Subscribe((4,)))
        await c.expect(JointUpdates)
        await c.requests(index=3, weapon=WeaponState.FIRING, velocity=(0.0, 0.0, 0.0))
        await c.send(React(int(Reaction.RECOIL), (3,)))
        await c.send(React(int(Reaction.FLINCH), (4, 600)))
        e = await c.expect(Error)
        assert e.code == ErrorCode.UNKNOWN_SOLDIER and "no soldier 600" in e.message
        sent = server.now()
        ev = await c.expect(JointUpdates)
        assert 4 in ev.indices.tolist() and server.now() - sent <= 1 / 30 + 1e-6
        assert [c.clip.rsplit("/", 1)[-1] for c in m.clips_of(4)][-1] == "ststow_flinch_low"
        await trio.sleep(4.0)
        clips = [c.clip.rsplit("/", 1)[-1] for c in m.clips_of(3)]
        assert clips[-1] == "stfire_recoil_low" and m.soldier_info(3)["posture"] == "STAND_FIRE"
        obs = await Client.open(port_of(server), "watcher", role="observer")
        await obs.expect(Ready)
        await obs.send(React(int(Reaction.FLINCH), (4,)))
        assert (await obs.expect(Error)).code == ErrorCode.NOT_PERMITTED
