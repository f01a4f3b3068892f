"""A front-end wakes its clients' writers once a tick, not once per shard's batch (issue 21): a shard's batch
is merged at once but its soldiers' writers wait for every shard's tick, except an answer to what the
front-end relayed (it waits for no later batch) and a shard that is late."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from server.fabric.nodes import FrontNode


def _front(shards: int = 2) -> SimpleNamespace:
    clock = [0.0]
    node = SimpleNamespace(
        server=SimpleNamespace(now=lambda: clock[0]),
        asked=np.zeros(100, bool),
        _held=[],
        _held_since=math.inf,
        _ticked=set(),
        route=list(range(shards)),
        hold_s=0.05,
        clock=clock,
    )
    return node


def _hold(node: SimpleNamespace, rows: list[int], ticked: int | None = None) -> list[int]:
    if ticked is not None:  # its pulse was heard by the feed (FrontNode._pulse)
        node._ticked.add(ticked)
    return sorted(FrontNode.hold(node, np.asarray(rows, np.int64)).tolist())  # type: ignore[arg-type]


def test_a_tick_wakes_once_every_shard_is_in() -> None:
    node = _front()
    assert _hold(node, [0, 2], ticked=0) == []  # shard 0's tick: held for shard 1's
    assert _hold(node, [1, 3], ticked=1) == [0, 1, 2, 3]  # both in: one wake
    assert _hold(node, [4], ticked=0) == []  # the next tick starts over
    assert _hold(node, [], ticked=1) == [4]  # a pulse with no changed soldier ends it too


def test_an_answer_waits_for_no_other_shard() -> None:
    node = _front()
    assert _hold(node, [0, 2], ticked=0) == []
    node.asked[5] = True  # a request relayed for soldier 5
    assert _hold(node, [5]) == [0, 2, 5]  # its first rows go at once, with those held
    assert not node.asked[5]
    assert _hold(node, [7]) == []  # the next rows of shard 1 wait again


def test_a_late_shard_holds_the_others_no_longer_than_hold_s() -> None:
    node = _front()
    assert _hold(node, [0], ticked=0) == []
    node.clock[0] = 0.04
    assert _hold(node, []) == []
    node.clock[0] = 0.06  # shard 1 silent (gone, or hung): the front-end's own tick lets them go
    assert _hold(node, []) == [0]
