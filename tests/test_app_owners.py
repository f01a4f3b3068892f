"""Issue 17: owners, granted roles, per-connection settings and caps that hold, over real TCP with trio's
autojump clock. Each test is one failure the issue lists (a second client drove, removed, re-created and
watched another's soldier; a controller changed everyone's throttle and STATUS period; JCL ignored the
per-client cap; soldiers outlived their client; roles were whatever a client declared)."""

from __future__ import annotations

import pytest
import trio
from test_server_support import Client, running_server

from protocol.entity import Reaction
from protocol.errors import ErrorCode
from protocol.events import (
    CreateSoldier,
    Error,
    Goodbye,
    Hello,
    JointUpdates,
    React,
    Ready,
    RemoveSoldier,
    Settings,
    SoldierCreated,
    SoldierRemoved,
    Status,
    Subscribe,
)
from server.app import check_exposure
from server.config import ConfigError, ServerConfig

WALK = (0.0, 1.4, 0.0)


def port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.addresses[0][1]


async def owner_and_soldier(server, client_id: str = "alpha") -> tuple[Client, int]:  # type: ignore[no-untyped-def]
    a = await Client.open(port_of(server), "a", client_id=client_id)
    await a.expect(Ready)
    await a.send(CreateSoldier(1, "DI.fig", "AK_47.fig", None))
    return a, (await a.expect(SoldierCreated)).index


async def jcl_errors(c: Client, texts: tuple[str, ...]) -> list[Error]:
    """Send each JCL text; each must be answered by its own JCL_ERROR."""
    errors = []
    for k, text in enumerate(texts):
        await c.jcl(text, 10 + k)
        e = await c.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.JCL_ERROR, 10 + k)
        errors.append(e)
    return errors


async def test_a_non_owner_cannot_drive_remove_recreate_or_watch(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        a, i = await owner_and_soldier(server)
        b = await Client.open(port_of(server), "b", client_id="bravo")
        ready = await b.expect(Ready)
        assert i not in dict(ready.soldiers)  # another client's soldier is not listed
        assert {0, 9} <= set(dict(ready.soldiers))  # the shared start-up soldiers are
        # watch: refused, and no updates of it ever arrive
        await b.send(Subscribe((i, 0)))
        e = await b.expect(Error)
        assert e.code == ErrorCode.NOT_PERMITTED and f"soldier {i} belongs to another client" in e.message
        await a.requests(index=i, velocity=WALK)
        seen = [ev for ev in await b.drain(1.0) if isinstance(ev, JointUpdates)]
        assert seen and all(i not in ev.indices.tolist() for ev in seen)
        # drive: refused by name; the rows for the shared soldier in the same batch are applied
        await b.requests(index=[0, i, 600], velocity=[WALK, (0.0, 0.0, 0.0), WALK])
        e = await b.expect(Error)
        assert e.code == ErrorCode.NOT_PERMITTED and f"row 1: soldier {i} belongs" in e.message
        e = await b.expect(Error)  # row numbers are the batch's, whatever was refused before
        assert e.code == ErrorCode.UNKNOWN_SOLDIER and "row 2: no soldier 600" in e.message
        await trio.sleep(0.1)
        info = server.world.manager.soldier_info(i)
        assert info["mode"] != "static" or "walk" in str(info["clip"])  # still walking as its owner asked
        # remove: refused, the soldier stays; re-create at its index: it exists
        await b.send(RemoveSoldier(i))
        e = await b.expect(Error)
        assert e.code == ErrorCode.NOT_PERMITTED and f"soldier {i} is not this client's" in e.message
        assert server.world.manager.table.is_live(i)
        await b.send(CreateSoldier(2, "DI.fig", "AK_47.fig", i))
        assert (await b.expect(Error)).code == ErrorCode.SOLDIER_EXISTS
        # the owner removes it: whoever could see it is told
        obs = await Client.open(port_of(server), "o", role="observer")
        await obs.expect(Ready)
        await a.send(RemoveSoldier(i))
        gone = await obs.expect(SoldierRemoved)
        assert gone.index == i and "alpha" in gone.reason
        assert (await a.expect(SoldierRemoved)).index == i
        assert not [ev for ev in await b.drain(0.5) if isinstance(ev, SoldierRemoved)]


async def test_soldier_jcl_is_for_the_owner_only(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        a = await Client.open(port_of(server), "a", client_id="alpha")
        await a.expect(Ready)
        await a.jcl('create_soldier_state("mine", "Di2_0", "AK_47_0");', 1)
        await a.jcl('react_soldier_state("mine", "flinch");', 2)
        assert (await a.expect(Status, lambda s: '"reaction"' in s.text)).text
        mine = server.world.soldiers.index_of("mine")
        assert server.world.owners.owner_of(mine) == "alpha"
        b = await Client.open(port_of(server), "b", client_id="bravo")
        await b.expect(Ready)
        texts = ('remove_soldier_state("mine");', 'react_soldier_state("mine", "recoil");')
        texts += ('report_ttes_status("mine");', 'report_ttes_clips("mine");')
        for e in await jcl_errors(b, texts):
            assert "'mine'" in e.message and (
                "another client" in e.message or "not this client's" in e.message
            )
        # a report of every soldier lists only what this client may drive
        listed = {s["index"] for s in (await b.report("report_ttes_status();"))["soldiers"]}
        assert mine not in listed and 0 in listed
        assert server.world.manager.table.is_live(mine)


async def test_a_controller_cannot_change_what_others_get(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.0, report_interval=2.0) as server:
        a = await Client.open(port_of(server), "a")
        await a.expect(Ready)
        assert (await a.expect(Settings)) == Settings(0.0, 2.0)
        await a.send(Subscribe((0,)))
        await a.requests(index=0, velocity=WALK)
        b = await Client.open(port_of(server), "b")
        await b.expect(Ready)
        assert (await b.expect(Settings)) == Settings(0.0, 2.0)
        # the throttle of issue 17's attack: only b's own connection slows down, and b is told
        await b.jcl("set_ttes_soldier_throttle(60);", 1)
        assert (await b.expect(Settings)).throttle == 60.0
        # STATUS every microsecond: refused (the floor); a longer period is b's alone
        await b.jcl("set_ttes_report_interval(0.000001);", 2)
        e = await b.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.JCL_ERROR, 2) and "not in 0.1" in e.message
        await b.jcl("set_ttes_report_interval(7);", 3)
        assert (await b.expect(Settings)) == Settings(60.0, 7.0)
        # server-wide settings and loads are the operator's
        texts = ("set_ttes_blend_time(0.5);", "set_ttes_heading_offset(10, 0, 0);")
        texts += ('load_posture_graph("soldier_low.graph", "copy");', 'remove_soldier_state("s0");')
        for e in await jcl_errors(b, texts):
            assert "needs the operator role" in e.message or "not this client" in e.message, e
        assert server.world.settings.throttle == 0.0 and server.world.report_interval == 2.0
        assert "copy" not in server.world.graphs
        await a.drain(0.5)
        updates = [ev for ev in await a.drain(1.0) if isinstance(ev, JointUpdates)]
        assert len(updates) >= 29  # a still gets every 30 Hz tick
        statuses = [ev for ev in await a.drain(4.0) if isinstance(ev, Status)]
        assert len(statuses) == 2  # and its STATUS every 2 s
        # 'remove_soldier_state("s0")' above: s0 is shared, so a controller may not remove it
        assert server.world.manager.table.is_live(0)


async def test_a_clients_own_status_period_and_throttle_take_effect_at_once(
    autojump_clock: trio.abc.Clock,
) -> None:
    async with running_server(throttle=0.0, report_interval=30.0) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.jcl("set_ttes_report_interval(0.5);")
        await c.expect(Settings)
        t0 = trio.current_time()
        await c.expect(Status)
        await c.expect(Status)
        assert trio.current_time() - t0 == pytest.approx(1.0, abs=0.01)
        await c.jcl("set_ttes_soldier_throttle(0.5);")
        assert (await c.expect(Settings)).throttle == 0.5
        await c.send(Subscribe((0,)))
        await c.requests(index=0, velocity=WALK)
        await c.drain(1.0)
        n = sum(len(ev.indices) for ev in await c.drain(3.0) if isinstance(ev, JointUpdates))
        assert 5 <= n <= 7  # one update per 0.5 s instead of 30 per second
        del server


async def test_orphans_vanish_after_the_grace_period_unless_reclaimed(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(orphan_grace=12.0) as server:
        obs = await Client.open(port_of(server), "o", role="observer")
        await obs.expect(Ready)
        a, i = await owner_and_soldier(server, "alpha")
        b, j = await owner_and_soldier(server, "bravo")
        await a.requests(index=i, velocity=WALK)
        await a.send(Goodbye("bye"))
        await b.send(Goodbye("bye"))
        await a.until_closed()
        await b.until_closed()
        left = trio.current_time()
        # alpha comes back after 8 s and reclaims its soldier: listed, drivable, never removed
        await trio.sleep(8.0)
        a2 = await Client.open(port_of(server), "a", client_id="alpha")
        assert a2.accept is not None and a2.accept.client_id == "alpha"
        assert i in dict((await a2.expect(Ready)).soldiers)
        await a2.requests(index=i, velocity=(0.0, 0.0, 0.0))
        # bravo does not: its soldier is removed 12 s after it left, and the observer is told
        gone = await obs.expect(SoldierRemoved)
        assert gone.index == j and "bravo" in gone.reason
        assert trio.current_time() - left == pytest.approx(12.0, abs=0.1)
        await trio.sleep(10.0)
        assert server.world.manager.table.is_live(i) and not server.world.manager.table.is_live(j)
        assert not [e for e in a2.events if isinstance(e, Error)]


async def test_the_grace_period_starts_when_the_owner_leaves(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(orphan_grace=12.0) as server:
        a, i = await owner_and_soldier(server, "alpha")
        await a.aclose()  # the stub quits without a goodbye
        t0 = trio.current_time()
        await trio.sleep(11.5)
        assert server.world.manager.table.is_live(i)
        await trio.sleep(1.0)
        assert not server.world.manager.table.is_live(i)
        assert 11.5 < trio.current_time() - t0 < 12.6


async def test_the_per_client_cap_holds_for_jcl_and_across_reconnects(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(max_soldiers_per_client=3) as server:
        a = await Client.open(port_of(server), "a", client_id="alpha")
        await a.expect(Ready)
        await a.send(CreateSoldier(1, "DI.fig", "", None))
        await a.expect(SoldierCreated)
        await a.jcl('create_soldier_state("j1", "Di2_1"); create_soldier_state("j2", "Di2_2");', 2)
        await a.jcl('create_soldier_state("j3", "Di2_3");', 3)
        e = await a.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.JCL_ERROR, 3) and "owns 3 soldiers" in e.message
        await a.aclose()
        # reconnecting with the same id does not reset the count
        a2 = await Client.open(port_of(server), "a", client_id="alpha")
        await a2.expect(Ready)
        await a2.send(CreateSoldier(4, "DI.fig", "", None))
        e = await a2.expect(Error)
        assert (e.code, e.ref) == (ErrorCode.NO_FREE_SOLDIER, 4) and "owns 3 soldiers" in e.message
        assert len(server.world.owners.soldiers_of("alpha")) == 3


async def test_the_total_cap_holds_for_jcl(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(max_soldiers=12) as server:
        a = await Client.open(port_of(server), "a", client_id="alpha")
        await a.expect(Ready)
        await a.jcl('create_soldier_state("j1", "Di2_1"); create_soldier_state("j2", "Di2_2");', 1)
        await a.jcl('create_soldier_state("j3", "Di2_3");', 2)
        e = await a.expect(Error)
        assert e.ref == 2 and e.code == ErrorCode.JCL_ERROR
        assert server.world.manager.count == 12


async def refused(port: int, hello: Hello) -> Error:
    c = await Client.open(port, hello=False)
    await c.send(hello)
    await c.until_closed()
    errors = [e for e in c.events if isinstance(e, Error)]
    assert errors and errors[0].code == ErrorCode.NOT_PERMITTED
    return errors[0]


async def test_roles_come_only_from_tokens_when_tokens_are_configured(autojump_clock: trio.abc.Clock) -> None:
    tokens = {"controller_token": "c-secret-123", "operator_token": "o-secret-456"}
    async with running_server(**tokens) as server:
        port = port_of(server)
        e = await refused(port, Hello("x", "controller"))
        assert "needs its token" in e.message and "secret" not in e.message
        await refused(port, Hello("x", "operator", token="c-secret-123"))
        await refused(port, Hello("x", "observer", token="wrong-token"))  # no observer token: none granted
        op = await Client.open(port, "op", role="observer", token="o-secret-456")  # a higher role's token
        assert op.accept is not None and op.accept.role == "observer" and op.accept.client_id.startswith("~")
        c = await Client.open(port, "c", token="c-secret-123", client_id="me")
        assert c.accept is not None and (c.accept.role, c.accept.client_id) == ("controller", "me")
        await c.expect(Ready)


def test_without_tokens_the_server_listens_on_loopback_only() -> None:
    check_exposure(ServerConfig(host="127.0.0.1"))
    check_exposure(ServerConfig(host="::1"))
    check_exposure(ServerConfig(host="localhost"))
    with pytest.raises(ConfigError, match="no role tokens"):
        check_exposure(ServerConfig(host="0.0.0.0"))
    check_exposure(ServerConfig(host="0.0.0.0", operator_token="long-enough"))
    with pytest.raises(ConfigError, match="operator_token"):
        ServerConfig(operator_token="short")
    assert "long-enough" not in repr(ServerConfig(operator_token="long-enough"))


async def test_a_non_owner_cannot_make_anothers_soldier_react(autojump_clock: trio.abc.Clock) -> None:
    """REACT follows the drive rule: the shared soldier reacts, another client's is refused by name."""
    async with running_server() as server:
        _, i = await owner_and_soldier(server)
        b = await Client.open(port_of(server), "b", client_id="bravo")
        await b.expect(Ready)
        before = server.world.manager.stats["reactions"]
        await b.send(React(int(Reaction.FLINCH), (i, 0)))
        e = await b.expect(Error)
        assert (
            e.code == ErrorCode.NOT_PERMITTED and f"react: soldier {i} belongs to another client" in e.message
        )
        assert server.world.manager.stats["reactions"] == before + 1  # soldier 0's
