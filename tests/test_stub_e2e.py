"""End to end: the real Jack/TTES server (in-process, trio) and the stub's JackProc over TCP."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
import trimesh
import trio

from client_stub.stub.app import StubApp
from client_stub.stub.jack import JackProc
from client_stub.stub.live import LiveSoldiers
from client_stub.stub.simsoldier import Behaviour, Force
from client_stub.stub.terrain import terrain_from_mesh
from protocol.entity import Appearance

server_app = pytest.importorskip("server.app")


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from ttes.commands.stub import stand_in_data_dir

    return stand_in_data_dir(tmp_path_factory.mktemp("server-data"))


async def test_stub_and_real_server(nursery: trio.Nursery, data_dir: Path, tmp_path: Path) -> None:
    from server.config import ServerConfig

    server = server_app.TtesServer(ServerConfig(host="127.0.0.1", port=0, data_dir=data_dir))
    addresses = await nursery.start(functools.partial(server.serve))
    host, port = addresses[0]
    terrain = terrain_from_mesh(trimesh.creation.box(extents=(200, 200, 2)), {"office": [30.0, -20.0]})
    live = LiveSoldiers()
    app = StubApp(terrain, live, artic_dir=tmp_path)
    app.add_soldier((0.0, 0.0), 0.0)
    app.add_soldier((8.0, 0.0), 0.0, speed=1.4, behaviour=Behaviour.SQUARE, size=6.0)
    app.add_soldier((-8.0, 0.0), 90.0, force=Force.OPPOSING)
    jack = JackProc()
    try:
        with trio.fail_after(30):
            await trio.to_thread.run_sync(jack.initsocketconnection, host, port)
            assert await trio.to_thread.run_sync(live.connect, app, jack, 20.0)
        assert len(jack.ready_soldiers) >= 3
        assert (app.server_of[:3] >= 0).all() and len(set(app.server_of[:3].tolist())) == 3
        kinds = {app.kinds[k].figure + "+" + app.kinds[k].weapon for k in app.slot_kind[:3]}
        assert kinds == {"DI.fig+AK_47.fig"}  # the server's soldiers carry AK-47s; colour tells the force
        kind = app.kinds[app.slot_kind[0]]
        (binding,) = kind.bindings.values()
        assert binding.agrees, binding.missing  # our articulation file and the server built the same table
        # soldier 0 kneels: the server plays the transition and its joint updates reach the scene graph
        await trio.to_thread.run_sync(app.handle_key, "3")
        start = kind.crowd.dofs[0].copy()
        moved = False
        with trio.fail_after(20):
            while not moved:
                await trio.to_thread.run_sync(jack.wait_updates, 1.0)
                await trio.to_thread.run_sync(app.frame, 1 / 30)
                moved = np.abs(kind.crowd.dofs[0] - start).max() > 0.05
        world = kind.crowd.world(np.arange(3))
        assert np.isfinite(world).all()
        np.testing.assert_allclose(world[:, 0, 2, 3], 1.0)  # every entity stands on the box top
        assert jack.failure is None and not [e for e in jack.errors if getattr(e, "code", 0) < 100]
        assert app.soldiers.appearance[0] == Appearance.KNEEL
    finally:
        await trio.to_thread.run_sync(app.close)
        server.shutdown()
    with trio.fail_after(10):
        await server.stopped.wait()
    assert jack.closed.is_set()
