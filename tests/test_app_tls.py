"""TLS on the TTES port (issue 17's option): a server with ``tls_cert`` speaks only TLS; the client link
with a context that trusts the certificate shakes hands and gets READY; a plain-TCP client gets no protocol
at all."""

from __future__ import annotations

import shutil
import ssl
import subprocess
from pathlib import Path

import pytest
import trio
from test_server_support import Client, running_server

from client_stub.link.client import Client as Link
from protocol.events import Hello
from server.config import ConfigError, ServerConfig
from server.tls import server_context

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command")


async def test_tls_link_gets_ready_and_plain_tcp_gets_nothing(
    autojump_clock: trio.abc.Clock, cert: tuple[Path, Path]
) -> None:
    async with running_server(tls_cert=str(cert[0]), tls_key=str(cert[1])) as server:
        port = server.addresses[0][1]
        link = Link("tls-client")
        link.tls = ssl.create_default_context(cafile=str(cert[0]))
        async with trio.open_nursery() as nursery:
            await link.open(nursery, "127.0.0.1", port, soldierprefix=None, timeout=10.0)
            assert link.accept is not None and link.accept.role == "controller"
            assert link.ready_event is not None and len(link.ready_soldiers) == 10
            nursery.cancel_scope.cancel()
        plain = await Client.open(port, hello=False)
        await plain.send(Hello("plain"))
        events = await plain.until_closed(timeout=20.0)
        assert all(type(e).__name__ in ("ConnectionClosed", "ProtocolError") for e in events), events


def test_tls_config_errors_name_the_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="tls_key"):
        ServerConfig(tls_key="k.pem")
    with pytest.raises(ConfigError, match="tls_cert"):
        server_context(ServerConfig(tls_cert=str(tmp_path / "missing.pem")))
    assert server_context(ServerConfig()) is None


def test_ping_command_speaks_tls_with_tls_ca(
    cert: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`ttes ping --tls-ca CERT` (the shared client options) against a `ttes server` process serving TLS."""
    import os
    import signal
    import sys

    from test_server_cli import _read_line
    from test_server_support import shared_library, synthetic_dir

    from ttes.cli import main

    shared_library()  # channelset caches written: the server starts fast
    config = tmp_path / "tls.toml"
    config.write_text(
        f'port = 0\ndata_dir = "{synthetic_dir().path}"\ntls_cert = "{cert[0]}"\ntls_key = "{cert[1]}"\n'
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "ttes", "server", "--config", str(config)], cwd=Path(__file__).parents[1],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    try:
        line = _read_line(proc, 60.0)
        port = line.split("127.0.0.1:")[1].split()[0]
        assert main(["ping", "--port", port, "--tls-ca", str(cert[0]), "--timeout", "5"]) == 0
        assert "pong from" in capsys.readouterr().out
        assert main(["ping", "--port", port, "--timeout", "2"]) == 1  # plain TCP gets no protocol
        assert main(["ping", "--port", port, "--tls", "--timeout", "5"]) == 1  # not signed by a system CA
        err = capsys.readouterr().err
        assert f"server 127.0.0.1:{port}: TLS: self" in err and "certificate" in err, err  # self[- ]signed
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
