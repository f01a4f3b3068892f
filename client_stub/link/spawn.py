"""The one server spawner: ``ttes server`` as a child process on loopback, and CPU accounting from ``/proc``.

The child runs ``python -m ttes server --host 127.0.0.1 --port 0 --json ARGS`` and we read its JSON ready
line (``{"event": "ready", "host": ..., "port": ...}``) for the address, so no port is ever guessed. What the
server needs (``--data-dir``, ``--synthetic``, ``--tick-hz`` ...) goes through its command line: the spawner
knows nothing of the server's data layout. Its log (stderr) goes to a temporary file whose tail explains a
failed start. CPU time comes from ``/proc/PID/stat`` (utime + stime); off Linux it is unknown (nan).
"""

from __future__ import annotations

import json
import math
import os
import re
import selectors
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from client_stub.link.client import LinkError

ROOT = Path(__file__).resolve().parents[2]  # where ``python -m ttes`` is importable from
_SERVER_TOKEN_VAR = re.compile(r"TTES_\w+_TOKEN")  # TTES_CONTROLLER_TOKEN ..., not a client's TTES_TOKEN
_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class SpawnError(LinkError):
    """The server child did not start (its log's tail is in the message)."""


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of a process so far (nan if ``/proc`` cannot tell)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return math.nan
    fields = text[text.rfind(")") + 2 :].split()  # after "pid (comm) ": state is field 3
    try:
        return (int(fields[11]) + int(fields[12])) / _TICKS  # utime, stime: fields 14 and 15
    except (IndexError, ValueError):
        return math.nan


def self_cpu_seconds() -> float:
    t = os.times()
    return t.user + t.system


def child_env() -> dict[str, str]:
    """The spawned server's environment: ours, with the repository importable and without the server's
    role token variables (``TTES_*_TOKEN``, server.config.TOKEN_ENV): a spawned server is a private one on
    loopback, which local clients join with no token, whatever the caller's shell holds for another server."""
    env = {k: v for k, v in os.environ.items() if not _SERVER_TOKEN_VAR.fullmatch(k)}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    return env


class ServerProcess:
    """A ``ttes server`` child process (see the module docstring); use as a context manager."""

    def __init__(self, args: Sequence[str] = (), *, timeout: float = 90.0, command: str = "server") -> None:
        """``command``: ``server``, or ``front`` (``ttes front``: the same flags, a front-end's process)."""
        self.cmd = [sys.executable, "-m", "ttes", command, "--host", "127.0.0.1", "--port", "0", "--json"]
        self.cmd += list(args)
        self.synthetic = "--synthetic" in args
        self.timeout = timeout
        self.host = "127.0.0.1"
        self.port = 0
        self.ready: dict = {}
        self._log = tempfile.TemporaryFile(mode="w+b", prefix="ttes-server-")  # noqa: SIM115 (closed in close)
        env = child_env()
        self.proc = subprocess.Popen(self.cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=self._log)
        self.pid = self.proc.pid

    def wait_ready(self, waiting: Callable[[float], None] | None = None) -> tuple[str, int]:
        """Block until the JSON ready line (SpawnError on exit or timeout); returns ``(host, port)``.
        ``waiting(seconds)``: told the seconds waited so far, twice a second (a progress line)."""
        assert self.proc.stdout is not None
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        start = time.monotonic()
        deadline = start + self.timeout
        buf = b""
        try:
            while time.monotonic() < deadline:
                if waiting is not None:
                    waiting(time.monotonic() - start)
                if not sel.select(timeout=min(0.5, max(0.0, deadline - time.monotonic()))):
                    if self.proc.poll() is not None:
                        break
                    continue
                chunk = os.read(self.proc.stdout.fileno(), 4096)
                if not chunk:
                    break
                buf += chunk
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    try:
                        obj = json.loads(line)
                    except ValueError:
                        continue
                    if isinstance(obj, dict) and obj.get("event") == "ready":
                        self.ready = obj
                        self.host, self.port = str(obj["host"]), int(obj["port"])
                        return self.host, self.port
        finally:
            sel.close()
        self.stop()
        raise SpawnError(f"ttes server did not become ready ({' '.join(self.cmd[2:])}): {self.log_tail()}")

    def cpu_seconds(self) -> float:
        return cpu_seconds(self.pid)

    def log_tail(self, chars: int = 1500) -> str:
        """The end of what the server wrote to stderr."""
        try:
            self._log.seek(0, os.SEEK_END)
            size = self._log.tell()
            self._log.seek(max(0, size - chars))
            return self._log.read().decode("utf-8", "replace").strip()
        except (OSError, ValueError):
            return ""

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGTERM (the server says GOODBYE and stops), then SIGKILL if it lingers; returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return self.proc.returncode

    def close(self) -> None:
        self.stop()
        self._log.close()

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def spawn_server(
    args: Sequence[str] = (),
    *,
    data: str = "auto",
    timeout: float = 90.0,
    waiting: Callable[[float], None] | None = None,
) -> ServerProcess:
    """A ready ``ttes server`` child. ``data``: ``default`` (what ``args`` say), ``synthetic`` (its generated
    motion library), ``auto`` (the default, else the synthetic library when the default does not start).
    ``waiting(seconds)`` is told how long it has waited (a progress line while the library loads)."""
    if data not in ("auto", "synthetic", "default"):
        raise ValueError(f"data must be auto, synthetic or default, not {data!r}")
    args = [*args, "--synthetic"] if data == "synthetic" else list(args)
    server = ServerProcess(args, timeout=timeout)
    try:
        server.wait_ready(waiting)
    except SpawnError:
        server.close()
        if data != "auto":
            raise
        server = ServerProcess([*args, "--synthetic"], timeout=timeout)
        try:
            server.wait_ready(waiting)
        except SpawnError:
            server.close()
            raise
    return server
