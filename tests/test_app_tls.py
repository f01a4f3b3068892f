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


@pytest.fixture(scope="module")
def cert(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("tls")
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
         "-keyout", str(d / "key.pem"), "-out", str(d / "cert.pem"), "-days", "2", "-subj", "/CN=localhost",
         "-addext", "subjectAltName=IP:127.0.0.1,DNS:localhost"],
        check=True, capture_output=True,
    )  # fmt: skip
    return d / "cert.pem", d / "key.pem"


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
