"""Cyclone DDS nodes (``server.fabric.dds_node``) in one process: a node hears the others of its domain, never
its own samples (a front-end writing to a topic it reads hung in ``write``), and nothing of another domain."""

from __future__ import annotations

import queue
import random
import time

import pytest

from server.fabric import DDS_DOMAIN_MAX, FabricConfig, Kind

pytest.importorskip("cyclonedds")

from server.fabric.dds_node import DdsFabric

DEADLINE = 30.0  # s to discover each other and deliver: a bound on a hang, not a timing


def _heard(fabric: DdsFabric, topic: str) -> queue.Queue[bytes]:
    got: queue.Queue[bytes] = queue.Queue()
    fabric.subscribe(topic, Kind.REQUESTS, got.put)
    return got


def test_a_node_hears_its_domain_not_itself_nor_another_domain() -> None:
    mine = random.randrange(1, DDS_DOMAIN_MAX)  # not another run's on this host
    config = FabricConfig("dds", "127.0.0.1:7400", domain=mine)
    a, b = DdsFabric(config), DdsFabric(config)
    other = DdsFabric(FabricConfig("dds", "127.0.0.1:7400", domain=mine + 1))
    try:
        topic = "ttes/test/dds"
        at_a, at_b, at_other = _heard(a, topic), _heard(b, topic), _heard(other, topic)
        send = a.publisher(topic, Kind.REQUESTS)
        end = time.monotonic() + DEADLINE
        while at_b.empty() and time.monotonic() < end:  # until b's reader is matched, samples may be lost
            send(b"hello")
            time.sleep(0.05)
        assert at_b.get_nowait() == b"hello"
        send(b"last")
        while (msg := at_b.get(timeout=DEADLINE)) != b"last":
            assert msg == b"hello"
        assert at_a.empty() and at_other.empty()
    finally:
        for f in (a, b, other):
            f.close()
