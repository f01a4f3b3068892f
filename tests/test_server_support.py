"""Shared helpers for the server tests (a synthetic data dir, a running server, a trio test client), and the
tests of the start-up itself: the seed's JCL start-up script over a real data dir → ready.

Other test modules import the helpers: ``from test_server_support import ...``.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trio
import trio.testing

from protocol.connection import CLIENT, NEED_DATA, Connection
from protocol.entity import make_entity_requests
from protocol.events import (
    PROTOCOL_VERSION,
    Accept,
    ConnectionClosed,
    EntityRequests,
    Event,
    Hello,
    Jcl,
    JointUpdates,
    ProtocolError,
    Status,
)
from server.app import TtesServer
from server.config import ServerConfig
from server.jcl import JclError
from server.session import Session
from server.soldier.library import MotionLibrary
from server.startup import ServerWorld, SyntheticDataDir, write_synthetic_data_dir

REPO = Path(__file__).resolve().parents[1]
_GENERATORS = (
    "server/soldier/synthetic.py",
    "server/startup.py",
    "server/motion/channelset_file.py",
    "server/motion/posture_graph.py",
    "server/motion/cache.py",
    "peabody/writer.py",
)


@functools.cache
def synthetic_dir() -> SyntheticDataDir:
    """The synthetic data dir, shared by the test processes of one checkout: written once (atomically, under
    the temp dir, keyed by the generators' source) so its channelset caches stay warm between runs."""
    digest = hashlib.sha256()
    for name in _GENERATORS:
        digest.update((REPO / name).read_bytes())
    path = Path(tempfile.gettempdir()) / f"ttes-server-test-{os.getuid()}-{digest.hexdigest()[:16]}"
    if not (path / "complete").exists():
        work = Path(tempfile.mkdtemp(prefix=path.name + ".", dir=path.parent))
        write_synthetic_data_dir(work, soldiers=10)
        (work / "complete").write_text("")
        try:
            work.rename(path)
        except OSError:  # another process won the race: use its copy
            shutil.rmtree(work, ignore_errors=True)
    return SyntheticDataDir(path, "jack-ttes-soldier_low.jcl", [f"s{i}" for i in range(10)])


@functools.cache
def shared_library() -> MotionLibrary:
    """The data dir's motion library, bound once: servers built with it skip re-reading the channelsets."""
    world = ServerWorld(synthetic_dir().path)
    world.run_startup(synthetic_dir().startup_script)
    assert world.library is not None
    return world.library


def make_server(*, share_library: bool = True, **overrides: Any) -> TtesServer:
    d = synthetic_dir()
    cfg = ServerConfig(port=0, data_dir=d.path, startup_script=d.startup_script).with_overrides(**overrides)
    world = ServerWorld(
        cfg.data_dir,
        max_soldiers=cfg.max_soldiers,
        record_clips=cfg.record_clips,
        library=shared_library() if share_library else None,
    )
    return TtesServer(cfg, world)


@contextlib.asynccontextmanager
async def running_server(**overrides: Any) -> AsyncIterator[TtesServer]:
    server = make_server(**overrides)
    async with trio.open_nursery() as nursery:
        await nursery.start(server.serve)
        yield server
        server.shutdown()


@dataclass
class Client:
    """A test client: a real TCP stream, the sans-IO protocol, and a log of everything received."""

    stream: trio.SocketStream
    conn: Connection
    events: list[Event] = field(default_factory=list)
    closed: bool = False
    bytes_in: int = 0
    accept: Accept | None = None

    @classmethod
    async def open(
        cls,
        port: int,
        name: str = "test",
        role: str = "controller",
        hello: bool = True,
        client_id: str = "",
        token: str = "",
        version: int = PROTOCOL_VERSION,
    ) -> Client:
        stream = await trio.open_tcp_stream("127.0.0.1", port)
        c = cls(stream, Connection(CLIENT))
        if hello:
            await c.send(Hello(name, role, version=version, client_id=client_id, token=token))
            c.accept = await c.expect(Accept)
        return c

    async def send(self, event: Event) -> None:
        await self.stream.send_all(self.conn.send(event))

    async def send_raw(self, data: bytes) -> None:
        await self.stream.send_all(data)

    async def requests(self, **columns: Any) -> None:
        await self.send(EntityRequests(make_entity_requests(**columns)))

    def buffered_event(self) -> Event | None:
        """The next event among the bytes already received (None: it needs more)."""
        ev = self.conn.next_event()
        if ev is NEED_DATA:
            return None
        assert isinstance(ev, Event)
        if not isinstance(ev, ConnectionClosed):
            self.events.append(ev)
        else:
            self.closed = True
        return ev

    async def next_event(self) -> Event:
        """The next event (ConnectionClosed at the end)."""
        while True:
            if (ev := self.buffered_event()) is not None:
                return ev
            try:
                data = await self.stream.receive_some(65536)
            except (trio.BrokenResourceError, trio.ClosedResourceError):
                data = b""
            self.bytes_in += len(data)
            self.conn.receive_data(bytes(data))

    async def expect(
        self, kind: type, where: Callable[[Any], bool] = lambda e: True, timeout: float = 60.0
    ) -> Any:
        """Skip events until one of ``kind`` (matching ``where``) arrives; fail on close or timeout."""
        with trio.fail_after(timeout):
            while True:
                ev = await self.next_event()
                if isinstance(ev, kind) and where(ev):
                    return ev
                if isinstance(ev, ConnectionClosed | ProtocolError):
                    raise AssertionError(f"connection ended waiting for {kind.__name__}: {self.events[-3:]}")

    async def drain(self, seconds: float) -> list[Event]:
        """Everything that arrives within ``seconds`` (of trio time)."""
        out: list[Event] = []
        with trio.move_on_after(seconds):
            while True:
                ev = await self.next_event()
                out.append(ev)
                if isinstance(ev, ConnectionClosed):
                    break
        return out

    def session(self, server: TtesServer) -> Session:
        """This client's session on ``server`` (by its address)."""
        host, port = self.stream.socket.getsockname()[:2]
        return next(s for s in server.sessions.values() if s.peer == f"{host}:{port}")

    def writes(self, server: TtesServer) -> list[tuple[float, int]]:
        """(server time, ticks run) each time from now on that the server encodes bytes for this client: when
        a frame was written, whenever its bytes arrive (under ``autojump_clock`` the clock jumps while they
        are on their way, so the time a frame is read says little)."""
        session, out = self.session(server), []
        take = session.take_output

        def taking(now: float | None = None) -> bytes:
            data = take(now)
            if data:
                out.append((server.now(), server.ticks))
            return data

        session.take_output = taking  # type: ignore[method-assign]
        return out

    async def caught_up(self, server: TtesServer) -> list[Event]:
        """Every event the server has written to this client by now (its session's ``bytes_out``), however
        late the bytes arrive. Under ``autojump_clock`` the clock jumps as soon as no task can run, also
        while bytes are still on their way over the loopback (a loaded machine delivers them late), so a
        time box (:meth:`drain`) may end before a frame written well within it arrives."""
        session = self.session(server)
        out: list[Event] = []
        while True:
            await trio.testing.wait_all_tasks_blocked()  # the writers have written what they owe
            while (ev := self.buffered_event()) is not None:
                out.append(ev)
            if self.closed or self.bytes_in >= session.bytes_out:
                return out
            out.append(await self.next_event())

    async def until_closed(self, timeout: float = 30.0) -> list[Event]:
        with trio.fail_after(timeout):
            out = []
            while True:
                ev = await self.next_event()
                out.append(ev)
                if isinstance(ev, ConnectionClosed):
                    return out

    async def jcl(self, text: str, id: int = 1) -> None:
        await self.send(Jcl(text, id))

    async def report(self, text: str, id: int = 99) -> dict[str, Any]:
        """Run a report command (``report_ttes_status(...)``) and return its JSON."""
        await self.jcl(text, id)
        st = await self.expect(Status, lambda s: s.text.startswith("{"))
        return json.loads(st.text)

    def pose(self, table: int, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        dec = self.conn.decoder(table)
        assert dec is not None
        d, p, q = dec.current(np.array([index]))
        return d[0], p[0], q[0]

    async def aclose(self) -> None:
        await self.stream.aclose()


Frame = tuple[int, list[int], JointUpdates]


async def frames_until(c: Client, done: Callable[[list[Frame]], bool], timeout: float = 2.0) -> list[Frame]:
    """``c``'s frames (tick, soldiers, event) until ``done`` holds for them (say, a tick number seen), never a
    time box: under ``autojump_clock`` the clock jumps while a frame's bytes are still on their way, and
    trio runs each batch of ready tasks in either order (so the writers' order varies), so a time box ends
    at a different point of the server's output from run to run."""
    out: list[Frame] = []
    with trio.fail_after(timeout):
        while not done(out):
            ev = await c.next_event()
            if isinstance(ev, JointUpdates):
                out.append((ev.tick, ev.indices.tolist(), ev))
    return out


# -- tests of the start-up ------------------------------------------------------------------------------
def test_startup_script_over_the_data_dir_makes_the_world_ready() -> None:
    d = synthetic_dir()
    world = ServerWorld(d.path)  # reads the env, graphs and channelsets from files
    world.run_startup(d.startup_script)
    assert world.ready
    assert world.manager is not None and world.manager.count == 10
    assert sorted(world.manager.names.values()) == sorted(d.soldiers)
    assert [(s.figure, s.weapon, s.table.table_id) for s in world.sets] == [("DI.fig", "AK_47.fig", 1)]
    assert set(world.graphs) == {"soldier_low", "soldier_loco", "soldier_crawl"}
    assert world.manager.settings.throttle == pytest.approx(0.04)
    assert world.report_interval == 30.0 and not world.graphics
    lib = world.library
    assert lib is not None and lib.can_walk and lib.can_run and lib.can_crawl
    # a 1994 client sends the same read_file again: harmless, nothing duplicated
    world.run_jcl('read_file("jack-ttes-soldier_low.jcl");')
    assert world.manager.count == 10


def test_read_file_uses_the_search_path_but_stays_in_the_data_dir(tmp_path: Path) -> None:
    d = synthetic_dir()
    world = ServerWorld(d.path, library=shared_library())
    # DI.fig lives in figures/, soldier_low.graph in posture_graphs/: found by bare name
    assert world.jcl.resolve_path("DI.fig") == (d.path / "figures" / "DI.fig").resolve()
    assert world.jcl.resolve_path("soldier_low.graph") == (d.path / "posture_graphs" / "soldier_low.graph")
    world.run_jcl('load_posture_graph("soldier_crawl.graph", "crawl_copy");')
    assert "crawl_copy" in world.graphs
    outside = tmp_path / "secret.jcl"
    outside.write_text("disable_graphics();")
    for bad in ("../secret.jcl", str(outside), "figures/../../x.jcl"):
        with pytest.raises(JclError, match=r"outside the data directory|no such file"):
            world.run_jcl(f'read_file("{bad}");')


def test_jcl_settings_reach_the_manager_and_bad_commands_are_located() -> None:
    world = ServerWorld(synthetic_dir().path, library=shared_library())
    m = world.manager
    assert m is not None
    world.run_jcl(
        "set_ttes_heading_offset(256.00,0.00,256.00); set_ttes_soldier_throttle(0.065); "
        'set_channelset_parameters("yes"); set_ttes_report_interval(5);'
    )
    assert m.settings.heading_offsets == (256.0, 0.0, 256.0)
    assert m.settings.throttle == pytest.approx(0.065) and m.settings.every_frame
    assert world.report_interval == 5.0
    with pytest.raises(JclError, match=r"<jcl>:1:1: unknown command 'system'"):
        world.run_jcl('system("rm -rf /");')
    with pytest.raises(JclError, match='expected "yes" or "no"'):
        world.run_jcl('set_channelset_parameters("maybe");')
    with pytest.raises(JclError, match="no figure"):
        world.run_jcl('create_soldier_state("x", "NoSuchFigure", "AK_47_0");')
    with pytest.raises(JclError, match="positive"):
        world.run_jcl("set_ttes_report_interval(0);")
    assert not world.ready
    world.run_jcl("start_ttes_socket_simulation();")
    assert world.ready


def test_missing_startup_script_is_a_clear_error(tmp_path: Path) -> None:
    world = ServerWorld(tmp_path)
    with pytest.raises(JclError, match=r"start-up script 'jack-ttes-soldier_low\.jcl' not found"):
        world.run_startup("jack-ttes-soldier_low.jcl")
    with pytest.raises(JclError, match=r"soldier_low\.graph' not found"):
        world.run_jcl("start_ttes_socket_simulation();")
