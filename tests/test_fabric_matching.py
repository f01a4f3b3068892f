"""Issue 21: each engine tells a publisher whether its topic has a subscriber (Zenoh's matching listener,
Cyclone DDS's publication-matched status): a shard publishes no pose stream that no front-end hears. Two
nodes in one process on 127.0.0.1: a subscriber appears (True) and goes (False); another topic's does not
count."""

from __future__ import annotations

import queue

import pytest

from client_stub.link.spawn import free_port
from server.fabric import FabricConfig, Kind, open_fabric

DEADLINE = 30.0  # s to discover each other: a bound on a hang, not a timing


def _next(told: queue.Queue[bool]) -> bool:
    return told.get(timeout=DEADLINE)


@pytest.mark.parametrize("engine", ["zenoh", "dds"])
def test_a_publisher_is_told_when_its_topic_gains_and_loses_a_subscriber(engine: str) -> None:
    pytest.importorskip("zenoh" if engine == "zenoh" else "cyclonedds")
    end = f"127.0.0.1:{free_port()}"
    domain = free_port() % 200 + 20  # (DDS: a domain of its own, away from other runs on this machine)
    shard = open_fabric(FabricConfig(engine, listen=end, domain=domain))
    front = open_fabric(FabricConfig(engine, connect=(end,), domain=domain))
    try:
        told: queue.Queue[bool] = queue.Queue()
        shard.publisher("ttes/test/match/all", Kind.POSES, on_match=told.put)
        assert _next(told) is False  # the state at declaration: nobody hears it yet
        front.subscribe("ttes/test/match/0", Kind.POSES, lambda data: None)  # another topic: no match
        stop = front.subscribe("ttes/test/match/all", Kind.POSES, lambda data: None)
        assert _next(told) is True
        stop()
        assert _next(told) is False
    finally:
        front.close()
        shard.close()
