"""bench/bench_scaleout.py starts its cluster again on new fabric ports when a front-end's port was taken
between its pick and the front-end's listen (the 16-core run7: "Address already in use")."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

import pytest

from client_stub.link.spawn import SpawnError


def _bench() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "bench" / "bench_scaleout.py"
    spec = importlib.util.spec_from_file_location("bench_scaleout_under_test", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


class FakeProcess:
    """A server that never starts: the first front-end's listen fails once (``taken`` times)."""

    started: ClassVar[list[list[str]]] = []
    taken = 1
    stopped = 0

    def __init__(self, args: list[str], command: str = "server", timeout: float = 0.0) -> None:
        self.args = args
        FakeProcess.started.append(args)

    def wait_ready(self) -> None:
        if "0/2" in self.args and FakeProcess.taken > 0:
            FakeProcess.taken -= 1
            raise SpawnError("zenoh.ZError: Can not create a new TCP listener: Address already in use")

    def stop(self) -> None:
        FakeProcess.stopped += 1


def test_a_taken_fabric_port_starts_the_cluster_again_on_new_ports(monkeypatch: Any) -> None:
    bench = _bench()
    monkeypatch.setattr(bench, "ServerProcess", FakeProcess)
    FakeProcess.started, FakeProcess.taken, FakeProcess.stopped = [], 1, 0
    with bench.cluster([], 2, 2) as procs:
        assert sorted(procs) == ["front0", "front1", "shard0", "shard1"]
    first, second = FakeProcess.started[:4], FakeProcess.started[4:]
    assert len(second) == 4 and FakeProcess.stopped == 8  # the failed start's 4, then the run's 4
    listen = [a[a.index("--fabric-listen") + 1] for a in (first[0], second[0])]
    assert listen[0] != listen[1]  # a new port
    ports = Path("/proc/sys/net/ipv4/ip_local_port_range")
    low = int(ports.read_text().split()[0]) if ports.exists() else 65536
    assert int(listen[1].rsplit(":", 1)[1]) < low  # below the ephemeral range: no connection takes it
    FakeProcess.taken = 5  # taken every time: gives up after PORT_TRIES
    with pytest.raises(SpawnError, match="Address already in use"), bench.cluster([], 2, 2):
        pass
