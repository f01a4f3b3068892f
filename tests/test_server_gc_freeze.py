"""A server process keeps its loaded library out of the garbage collector's full collections (issue 21:
each full collection walked the start-up's objects for 30-37 ms of a shard's or front-end's loop)."""

from __future__ import annotations

import gc
from collections.abc import Iterator

import pytest

from tests.test_server_support import make_server


@pytest.fixture
def unfrozen() -> Iterator[None]:
    """Each test starts and ends with nothing frozen (this test process makes many servers)."""
    gc.unfreeze()
    yield
    gc.unfreeze()


def test_a_server_process_freezes_what_its_start_up_loaded(unfrozen: None) -> None:
    server = make_server()
    server.freeze_gc = True  # as ttes server / ttes front set it
    server.start_world()
    library = server.world.soldiers.library
    assert library is not None
    frozen = gc.get_freeze_count()
    assert frozen > 0
    assert not any(o is library for o in gc.get_objects())  # no collection walks it now
    server.world.start()  # a READY with the same library freezes nothing more
    assert gc.get_freeze_count() == frozen


def test_a_server_made_in_a_process_of_many_freezes_nothing(unfrozen: None) -> None:
    server = make_server()
    server.start_world()
    assert gc.get_freeze_count() == 0
