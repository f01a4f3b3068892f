"""Issue 21: a front-end's merge costs what its clients watch, not every soldier of every shard.

Its clients subscribe to a part of the soldiers; the rows no client watches are kept aside (their newest
codes, :mod:`server.fabric.watch`), not merged into the pose board, and a client that subscribes to one
later gets its current pose at once."""

from __future__ import annotations

import numpy as np
import trio
from test_fabric_inprocess import cluster, crowd, moving
from test_server_support import Client

from protocol.events import JointUpdates, Ready, Subscribe, Unsubscribe
from server.fabric.batch import Batch
from server.fabric.nodes import merge
from server.fabric.watch import Watch
from server.pose_board import PoseBoard

MADE = 30  # soldiers the client creates (10..39: the start-up script's are 0..9)
WATCHED = (10, 11, 12, 13, 14)
LATE = 20  # walks unwatched, stops, then an observer subscribes to it


async def test_only_watched_rows_reach_the_board_and_a_late_subscriber_gets_the_current_pose(
    autojump_clock: trio.abc.Clock,
) -> None:
    async with cluster() as (front, node, shards, _):
        c = await crowd(front, MADE, WATCHED)
        board = front.board_ref.board
        assert board is not None
        serial, rows, batches = board.serial, board.rows_published, node.batches
        await moving(c, 10, 10)
        # every shard batch carries the 30 walkers; only the 5 watched were published (main: all of them)
        assert node.batches - batches >= 10
        assert board.rows_published - rows <= len(WATCHED) * (node.batches - batches)
        unwatched = np.setdiff1d(np.arange(40), WATCHED)
        assert board.version[list(WATCHED)].min() > serial and board.version[unwatched].max() <= serial

        await c.requests(index=[LATE], velocity=(0.0, 0.0, 0.0))  # it stops, unwatched
        await trio.sleep(5.0)
        shard = shards[LATE % 2].board_ref.board
        assert shard is not None
        obs = await Client.open(front.addresses[0][1], "obs", role="observer")
        await obs.expect(Ready)
        await obs.send(Subscribe((LATE,)))
        first = await obs.expect(JointUpdates)  # the next update: the soldier, as the shard has it now
        assert LATE in first.indices.tolist()
        assert board.valid[LATE] and (board.codes[LATE] == shard.codes[LATE]).all()
        assert node.watching.watched[LATE]

        await obs.send(Unsubscribe((LATE,)))  # no client watches it again: held, not merged, from now on
        await trio.sleep(0.5)
        assert not node.watching.watched[LATE] and node.watching.watched[list(WATCHED)].all()
        await obs.aclose()
        await c.aclose()


def batch(indices: list[int], codes: int, key: bool = False) -> Batch:
    n = len(indices)
    idx = np.array(indices, np.uint32)
    return Batch(0, 1, 0, 0, 0.0, idx, np.ones(n, np.uint8), np.full((n, 4), codes, np.uint16), key)


def test_a_held_row_comes_onto_the_board_newest_first_and_only_for_the_living() -> None:
    board, watch = PoseBoard(3, 2, 1000), Watch(1000)
    alive = np.ones(1000, bool)
    watch.watch(np.arange(10), board, alive)
    merge(board, [batch(list(range(1000)), 1, key=True), batch([5, 500, 600], 2)], 1, alive, watch)
    assert board.rows_published == 10 and not board.valid[10:].any()  # 10 of 1,000 rows merged
    assert board.codes[5].tolist() == [2, 2, 2, 2]
    alive[600] = False
    watch.forget(700)  # a soldier re-created at 700: the codes held there were another's
    serial = board.serial
    assert watch.watch(np.array([500, 600, 700, 501]), board, alive) == 2  # 500 and 501, once
    assert board.codes[500].tolist() == [2, 2, 2, 2] and board.codes[501].tolist() == [1, 1, 1, 1]
    assert board.version[500] == board.serial > serial and not board.valid[[600, 700]].any()
    watch.watch(np.array([500]), board, alive)  # already watched: nothing again
    assert board.serial == serial + 1
