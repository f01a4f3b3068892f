"""Issue 18 over the real server: REQUEST_FIGURE is answered with FIGURE (or a request error), a standing
soldier drawn from FIGURE alone is where Peabody puts him (the test data dir's synthetic figures), and HELLO
refuses a max_frame below the minimum."""

from __future__ import annotations

import msgpack
import numpy as np
import trio
from test_server_support import Client, running_server

from peabody.fk import FigureKinematics
from protocol import coords
from protocol.errors import ErrorCode
from protocol.events import Error, FigureMsg, JointUpdates, Ready, RequestFigure, Subscribe, UpdateTableMsg
from protocol.framing import MIN_CLIENT_MAX_FRAME, encode_frame
from protocol.messages import HANDSHAKE_PREFIX, MAGIC, MessageType
from protocol.update_table import JointEntry


def port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.addresses[0][1]


async def test_request_figure_is_answered_and_draws_a_live_soldier(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.0) as server:
        c = await Client.open(port_of(server), "ig", role="observer")
        table = (await c.expect(UpdateTableMsg)).table
        await c.expect(Ready)
        await c.send(RequestFigure(5, table.table_id))
        fig = await c.expect(FigureMsg)
        assert [f.name for f in fig.figures] == ["soldier", "rifle"]
        await c.send(RequestFigure(6, 999))
        err = await c.expect(Error)
        assert (err.code, err.ref) == (ErrorCode.UNKNOWN_FIGURE, 6)
        await c.send(RequestFigure(7, table.table_id, meshes=True))
        with_meshes = await c.expect(FigureMsg)  # the synthetic figures have no surfaces: an empty list
        assert [f.name for f in with_meshes.figures] == ["soldier", "rifle"]
        # a FIGURE over the client's max_frame (here: padded by a key receivers ignore) is a request error
        big = FigureMsg(fig.table, fig.figures, {**fig.body, "padding": "x" * (1 << 20)})
        server.world.soldiers._figure_msgs[(table.table_id, True)] = big
        await c.send(RequestFigure(8, table.table_id, meshes=True))
        err = await c.expect(Error)
        assert (err.code, err.ref) == (ErrorCode.FIGURE_TOO_LARGE, 8)
        await c.send(Subscribe((0,)))
        upd = await c.expect(JointUpdates, lambda u: 0 in u.indices.tolist())
        row = upd.indices.tolist().index(0)
        placements = coords.pose7_to_transform(upd.positions[row], upd.orientations[row])
        # the reference: the server's own figures, in Jack units, on the decoded values
        figures = server.world.library.sets[0].prototypes
        start = 0
        for k, (wire, figure) in enumerate(zip(fig.figures, figures, strict=True)):
            kin = FigureKinematics(figure)
            q = upd.dofs[row, start : start + kin.ndof].copy()
            start += kin.ndof
            q[~kin.rotational] *= coords.CM_PER_M
            root = coords.transforms_performer_to_jack(placements[k])
            ref = coords.points_jack_to_performer(kin.site_globals(q, root)[:, :3, 3])
            got = wire.site_globals(table, upd.dofs[row], placements[k])[:, :3, 3]
            assert np.abs(got - ref).max() < 1e-3
        assert sum(isinstance(e, JointEntry) for e in table.entries) == sum(
            len(f.joints) for f in fig.figures
        )


async def test_hello_below_the_least_max_frame_is_refused_clearly(autojump_clock: trio.abc.Clock) -> None:
    async with running_server() as server:
        c = await Client.open(port_of(server), hello=False)
        body = msgpack.packb({"name": "tiny", "role": "observer", "max_frame": 256})
        await c.send_raw(encode_frame(MessageType.HELLO, HANDSHAKE_PREFIX.pack(MAGIC, 1) + body))
        await c.until_closed()
        (err,) = [e for e in c.events if isinstance(e, Error)]
        assert err.code == ErrorCode.BAD_VALUE
        assert f"max_frame 256 is below {MIN_CLIENT_MAX_FRAME}" in err.message


def test_figure_with_meshes_reads_the_surfaces_the_server_loads_without() -> None:
    """The server reads figures without psurfs (it never draws): a FIGURE with meshes reads them again, from
    the file its search path resolves (an empty list before: the browser page had nothing to draw)."""
    from peabody.loader import read_figure
    from server.world.soldiers import _with_surfaces
    from ttes.paths import FIGURES

    bare = read_figure(FIGURES / "DI.fig", load_psurfs=False)
    assert all(s.psurf is None for s in bare.segments.values())
    full = _with_surfaces(bare, lambda name: FIGURES / name)
    assert sum(s.psurf is not None for s in full.segments.values()) == 19
    assert list(full.segments) == list(bare.segments) and full.name == bare.name
    assert _with_surfaces(bare, lambda name: FIGURES / "missing.fig") is bare  # unreadable: as it was
