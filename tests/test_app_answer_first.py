"""Issue 16, latency: a request that lands while the tick samples is answered as the tick's first frames.

The tick lets the readers in after it samples (``TtesServer.run_tick``); the soldiers whose requests they
applied are sampled again at the tick's time and published first (``TtesServer._answer_first``), and their
writers write them before the rest of the tick is quantised and encoded, so the request waits for the
sampling only, not for the whole tick. Under ``autojump_clock`` CPU time is free: these tests check the
order of the steps and what each frame carries, which set the latency on a real machine.
"""

from __future__ import annotations

import os

import numpy as np
import trio
from test_app_walkthrough import STEP, vel, watching
from test_server_support import frames_until, running_server

from protocol.entity import Appearance as A
from protocol.entity import WeaponState as W
from protocol.entity import make_entity_requests
from protocol.events import EntityRequests, JointUpdates, Subscribe
from server.soldier.core import TickUpdate

HZ = 30.0


async def test_a_request_landing_while_the_tick_samples_is_written_before_the_rest_of_the_tick(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Soldier 1 walks (in every tick's frames), soldier 0 rests; a kneel for soldier 0 lands while the tick
    samples. The client gets soldier 0 kneeling under that tick's number in a frame of its own, written
    before the tick's other poses are published, then soldier 1 under the same number (soldier 0 not
    again), and at the default throttle soldier 1 still gets every tick (the early write holds none back)."""
    async with running_server(throttle=0.04) as server:
        c = await watching(server)
        await c.requests(index=1, velocity=vel(1.4, 0.0), heading=0.0)
        await c.send(Subscribe((1,)))
        await trio.sleep_until(server._t0 + 1.51)
        rest = c.pose(1, 0)[0].copy()
        m, board = server.world.manager, server.board_ref.board
        session = next(iter(server.sessions.values()))
        order: list[str] = []
        publish, take, sample = board.publish, session.take_output, m.tick
        kneel = c.conn.send(EntityRequests(make_entity_requests(0, A.KNEEL, W.DEPLOYED)))

        def publishing(update, world, **kw):  # type: ignore[no-untyped-def]
            order.append(f"publish {sorted(set(update.indices.tolist()) & {0, 1})}")
            return publish(update, world, **kw)

        def taking(now: float | None = None) -> bytes:
            data = take(now)
            if data:
                order.append("write")
            return data

        def sampling(now: float):  # type: ignore[no-untyped-def]
            update = sample(now)
            os.write(c.stream.socket.fileno(), kneel)  # lands while the tick samples
            m.tick = sample
            return update

        board.publish, session.take_output = publishing, taking  # type: ignore[method-assign]
        c.events.clear()
        await c.drain(1.5 / HZ)  # the last tick before: soldier 1 only
        before, answers = board.ticks, server.answers
        order.clear()
        m.tick = sampling
        tick = before + 1
        frames = await frames_until(c, lambda fs: any(t >= tick + 2 and 1 in i for t, i, _ in fs))
        frames = [f for f in frames if f[0] > before]
        assert [(t, i) for t, i, _ in frames[:2]] == [(tick, [0]), (tick, [1])]
        assert [t for t, i, _ in frames if 1 in i] == [tick, tick + 1, tick + 2]  # every tick
        assert order[:2] == ["publish [0]", "write"]  # written before the rest of the tick is published
        assert order[2] in ("publish [1]", "publish [0, 1]")
        assert np.abs(frames[0][2].dofs[0] - rest).max() > STEP  # it shows the kneel already
        assert not m.table.requested[0] and server.answers == answers  # no answer after the tick


async def test_the_tick_frames_carry_the_answered_soldiers_new_pose(
    autojump_clock: trio.abc.Clock,
) -> None:
    """A walking soldier (in every tick's update) asked to kneel while the tick samples: answered as the
    tick's first frames, it is not sent a second time in that tick, and the board keeps its answered pose
    after the tick's publish (the tick's own row for it is replaced by the answer's: ``TickUpdate.take``)."""
    async with running_server(throttle=0.0) as server:
        c = await watching(server)
        await c.requests(index=0, velocity=vel(1.4, 0.0), heading=0.0)
        await trio.sleep_until(server._t0 + 1.51)
        m, board = server.world.manager, server.board_ref.board
        assert m is not None and board is not None
        sample, publish = m.tick, board.publish
        kneel = c.conn.send(EntityRequests(make_entity_requests(0, A.KNEEL, W.DEPLOYED)))
        sampled: list[bool] = []
        published: list[tuple[int, bool, np.ndarray]] = []  # (label, between, soldier 0's row) after each

        def sampling(now: float):  # type: ignore[no-untyped-def]
            update = sample(now)
            sampled.append(0 in update.indices.tolist())
            os.write(c.stream.socket.fileno(), kneel)
            m.tick = sample
            return update

        def publishing(update, world, **kw):  # type: ignore[no-untyped-def]
            changed = publish(update, world, **kw)
            published.append((board.tick, kw.get("between", False), board.dofs[0].copy()))
            return changed

        c.events.clear()
        await c.drain(1.5 / HZ)
        before = board.ticks
        m.tick, board.publish = sampling, publishing  # type: ignore[method-assign]
        ev = await c.expect(JointUpdates, lambda e: e.tick > before and 0 in e.indices.tolist())
        frames = await c.caught_up(server)  # all written by now (the next tick's frames too, if it ran)
        assert sampled == [True]  # the tick sampled it walking
        assert not [
            e for e in frames if isinstance(e, JointUpdates) and e.tick == ev.tick and 0 in e.indices.tolist()
        ]
        rows = [(between, row) for label, between, row in published if label == ev.tick]
        assert len(rows) >= 2 and not any(between for between, _ in rows)  # the answer, then the tick
        assert all(np.array_equal(row, rows[0][1]) for _, row in rows)  # the tick keeps the answered row


def test_tick_update_take_replaces_the_rows_of_the_soldiers_both_hold() -> None:
    """``TickUpdate.take``: the rows of soldiers in both updates become the later sample's; others stay."""
    n, ndof = 5, 3

    def update(indices: list[int], value: float) -> TickUpdate:
        k = len(indices)
        return TickUpdate(
            np.array(indices, np.int64),
            np.full((k, ndof), value, np.float32),
            np.full((k, 2, 7), value, np.float32),
            np.zeros(k, bool),
            np.full(k, int(value), np.int32),
            np.full(k, value),
            np.full(k, value),
        )

    tick = update(list(range(n)), 1.0)
    tick.take(update([1, 3, 7], 2.0))  # 7: not in the tick's update
    assert tick.joints[:, 0].tolist() == [1.0, 2.0, 1.0, 2.0, 1.0]
    assert tick.figures[:, 1, 6].tolist() == [1.0, 2.0, 1.0, 2.0, 1.0]
    assert tick.clips.tolist() == [1, 2, 1, 2, 1] and tick.frames.tolist() == [1.0, 2.0, 1.0, 2.0, 1.0]
