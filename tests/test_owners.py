"""server.world.owners without sockets: rights by role, the per-id cap, grace deadlines, bounded id table."""

from __future__ import annotations

import numpy as np
import pytest

from server.world.owners import Owners


def test_rights_by_role() -> None:
    o = Owners(8, per_owner=4)
    o.add(0, None)  # shared
    o.add(1, "a")
    o.add(2, "b")
    idx = np.arange(3)
    assert o.drivable(idx, "a", "controller").tolist() == [True, True, False]
    assert o.visible(idx, "a", "controller").tolist() == [0, 1]
    assert o.visible(idx, "a", "observer").tolist() == [0, 1, 2]
    assert not o.drivable(idx, "a", "observer").any() and o.drivable(idx, "x", "operator").all()
    assert [o.may_remove(i, "a", "controller") for i in range(3)] == [False, True, False]
    assert o.may_remove(2, "a", "operator") and o.owner_of(2) == "b" and o.owner_of(0) is None


def test_the_cap_counts_live_soldiers_per_id() -> None:
    o = Owners(8, per_owner=2)
    o.add(0, "a")
    o.add(1, "a")
    with pytest.raises(ValueError, match="owns 2 soldiers"):
        o.check_cap("a")
    o.check_cap("b")
    o.check_cap(None)  # the start-up script is not capped per client
    o.discard(1)
    o.check_cap("a")


def test_grace_starts_when_the_last_connection_leaves_and_ends_when_it_joins() -> None:
    o = Owners(8, per_owner=4)
    o.join("a")
    o.join("a")
    o.add(3, "a")
    assert o.leave("a", 1.0, 12.0) is None  # one connection of "a" is still open
    assert o.leave("a", 2.0, 12.0) == 14.0
    assert o.expired(13.9) == []
    assert o.join("a") == [3]  # reclaimed
    assert o.expired(20.0) == []
    assert o.leave("a", 30.0, 12.0) == 42.0 and o.expired(42.0) == ["a"]


def test_ids_that_come_and_go_do_not_grow_the_table() -> None:
    o = Owners(4, per_owner=4)
    for k in range(1000):
        cid = f"~anon-{k}"
        o.join(cid)
        o.add(k % 4, cid)
        o.discard(k % 4)
        o.leave(cid, float(k), 12.0)
    assert o.known == 0
    o.add(1, "kept")
    assert o.known == 1 and o.owner_of(1) == "kept"
