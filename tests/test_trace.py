"""server/trace.py: the bench's request trace stamps only the traced soldiers, and only when asked."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from server.trace import Tracer, from_env


def test_a_tracer_stamps_only_the_traced_soldiers(tmp_path: Path) -> None:
    tracer = Tracer(str(tmp_path / "t"), below=5)
    tracer.stamp("shard_take", np.array([7, 1, 3]), "answer")
    tracer.stamp("encode", [9])  # none traced: no line
    tracer.stamp("sent", np.zeros(0, np.int64))
    tracer.close()
    (line,) = (tmp_path / "t").read_text().splitlines()
    when, stage, indices, note = line.split()
    assert (stage, indices, note) == ("shard_take", "1,3", "answer")
    assert abs(float(when) - time.monotonic()) < 60  # the host's monotonic clock: processes' stamps line up


def test_tracing_is_off_unless_the_environment_asks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("TTES_TRACE", raising=False)
    assert from_env() is None
    monkeypatch.setenv("TTES_TRACE", str(tmp_path / "trace"))
    monkeypatch.setenv("TTES_TRACE_BELOW", "3")
    tracer = from_env()
    assert tracer is not None and tracer.below == 3
    tracer.stamp("fe_request", [2])
    tracer.close()
    assert (tmp_path / f"trace.{os.getpid()}").read_text().split()[1:] == ["fe_request", "2"]
