"""`ttes server` and `ttes ping` as a user runs them: a real process, the ready line, ping, SIGTERM."""

from __future__ import annotations

import json
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_server_support import shared_library, synthetic_dir

from protocol.events import PROTOCOL_VERSION
from ttes.cli import main

REPO = Path(__file__).resolve().parents[1]


def _read_line(proc: subprocess.Popen[str], timeout: float) -> str:
    assert proc.stdout is not None
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if sel.select(deadline - time.monotonic()):
            return proc.stdout.readline()
    raise AssertionError("no line from the server in time")


def test_server_prints_ready_answers_ping_and_stops_on_sigterm(capsys: pytest.CaptureFixture[str]) -> None:
    d = synthetic_dir()
    shared_library()  # channelset caches written: the server starts fast
    proc = subprocess.Popen(
        [sys.executable, "-m", "ttes", "server", "--port", "0", "--data-dir", str(d.path), "--json-logs"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        line = _read_line(proc, 60.0)
        assert "ready" in line and "127.0.0.1:" in line, line
        port = int(line.split("127.0.0.1:")[1].split()[0])
        assert main(["ping", "--port", str(port), "--json"]) == 0
        info = json.loads(capsys.readouterr().out)
        assert info["ok"] and info["server"] == "jack-ttes" and info["version"] == PROTOCOL_VERSION
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
        logs = [json.loads(x) for x in proc.stderr.read().splitlines() if x.startswith("{")]  # type: ignore[union-attr]
        events = [x["event"] for x in logs]
        assert "simulation_ready" in events and "listening" in events
        assert events[-2:] == ["signal", "stopped"] or events[-1] == "stopped"
        closed = [x for x in logs if x["event"] == "client_closed"]
        assert closed and closed[0]["name"] == "ttes-ping" and closed[0]["reason"] == "goodbye"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_ping_fails_cleanly_without_a_server(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["ping", "--port", str(port), "--timeout", "1"]) == 1
    assert "cannot connect" in capsys.readouterr().err


def test_server_refuses_bad_settings_before_listening(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "ttes.toml"
    bad.write_text("tick_hz = -3\n")
    assert main(["server", "--config", str(bad)]) == 1  # a file that cannot be used: a runtime error
    assert "tick_hz: -3 is outside" in capsys.readouterr().err
    assert main(["server", "--data-dir", str(tmp_path), "--port", "0"]) == 1
    assert "start-up script 'jack-ttes-soldier_low.jcl' not found" in capsys.readouterr().err
