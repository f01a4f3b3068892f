"""Role tokens on the command line (issue 17 follow-up): every `ttes` client command sends ``--token``
(default ``$TTES_TOKEN``) and can speak TLS (``--tls-ca``); a refused handshake names the address and the
reason and exits 1. The server here is a real `ttes server` process whose controller token comes from its
environment."""

from __future__ import annotations

import argparse
import os
import signal
import ssl
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_replay_support import exercise
from test_server_cli import _read_line
from test_server_support import shared_library, synthetic_dir

from client_stub.link.auth import Credentials
from client_stub.link.client import Client
from protocol.dis.synth import write_pcap
from ttes.cli import build_parser, main
from ttes.link_options import TOKEN_ENV, link_credentials

REPO = Path(__file__).resolve().parents[1]
TOKEN = "controller-secret-1"
CLIENT_COMMANDS = ["ping", "stub", "replay", "gateway", "loadtest", "crowd"]


@pytest.fixture(scope="module")
def token_server() -> Iterator[int]:
    """A loopback `ttes server` whose controller token comes from TTES_CONTROLLER_TOKEN; yields its port."""
    d = synthetic_dir()
    shared_library()  # channelset caches written: the server starts fast
    env = {k: v for k, v in os.environ.items() if k != TOKEN_ENV}
    env.update(PYTHONUNBUFFERED="1", TTES_CONTROLLER_TOKEN=TOKEN)
    proc = subprocess.Popen(
        [sys.executable, "-m", "ttes", "server", "--port", "0", "--data-dir", str(d.path)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        line = _read_line(proc, 60.0)
        assert "ready" in line and "127.0.0.1:" in line, line
        yield int(line.split("127.0.0.1:")[1].split()[0])
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
        assert TOKEN not in proc.stderr.read()  # type: ignore[union-attr]  # never logged
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def squad_pcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("tokens") / "squad.pcap"
    write_pcap(path, exercise())
    return path


@pytest.fixture
def no_env_token(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(TOKEN_ENV, raising=False)


@pytest.mark.usefixtures("no_env_token")
def test_ping_without_a_token_is_refused_naming_address_and_reason(
    token_server: int, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["ping", "--port", str(token_server), "--timeout", "5"]) == 1
    err = capsys.readouterr().err
    assert f"127.0.0.1:{token_server}" in err and "needs its token" in err, err
    assert main(["ping", "--port", str(token_server), "--timeout", "5", "--token", "wrong-token-9"]) == 1
    assert "needs its token" in capsys.readouterr().err


def test_ping_takes_the_token_from_the_environment_or_the_flag(
    token_server: int, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(TOKEN_ENV, TOKEN)
    assert main(["ping", "--port", str(token_server), "--timeout", "5"]) == 0  # observer by a higher token
    monkeypatch.setenv(TOKEN_ENV, "wrong-token-9")
    assert main(["ping", "--port", str(token_server), "--timeout", "5", "--token", TOKEN]) == 0  # flag wins
    assert "pong from" in capsys.readouterr().out


@pytest.mark.usefixtures("no_env_token")
def test_gateway_and_loadtest_send_the_token(token_server: int, capsys: pytest.CaptureFixture[str]) -> None:
    port = str(token_server)
    gateway = ["gateway", "--host", "127.0.0.1", "--port", port, "--dis-port", "0", "--seconds", "0.3"]
    assert main(gateway) == 1
    assert f"127.0.0.1:{port}" in capsys.readouterr().err
    assert main([*gateway, "--token", TOKEN]) == 0
    load = ["loadtest", "--host", "127.0.0.1", "--port", port, "--soldiers", "2", "--clients", "1",
            "--seconds", "0.5", "--warmup", "0.2", "--json"]  # fmt: skip
    assert main(load) == 1
    assert "needs its token" in capsys.readouterr().err
    assert main([*load, "--token", TOKEN]) == 0
    assert TOKEN not in capsys.readouterr().out  # the JSON report's config leaves the credentials out


@pytest.mark.usefixtures("no_env_token")
def test_replay_and_stub_are_refused_without_the_token(
    token_server: int,
    capsys: pytest.CaptureFixture[str],
    squad_pcap: Path,
    tmp_path: Path,
) -> None:
    port = str(token_server)
    replay = ["replay", str(squad_pcap), "--no-stub", "--speed", "0", "--host", "127.0.0.1", "--port", port]
    assert main(replay) == 1
    assert f"127.0.0.1:{port}" in capsys.readouterr().err
    assert main([*replay, "--token", TOKEN]) == 0
    stub = ["stub", "--headless", "--host", "127.0.0.1", "--port", port, "--out", str(tmp_path / "s.png")]
    assert main(stub) == 1
    err = capsys.readouterr().err
    assert f"127.0.0.1:{port}" in err and "needs its token" in err, err


@pytest.mark.parametrize("name", CLIENT_COMMANDS)
def test_every_client_command_documents_token_and_tls(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main([name, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--token" in text and TOKEN_ENV in text and "--tls-ca" in text


@pytest.mark.usefixtures("no_env_token")
def test_credentials_from_the_shared_options(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = build_parser()
    args = parser.parse_args(["ping"])
    assert link_credentials(args) == Credentials()
    monkeypatch.setenv(TOKEN_ENV, "from-the-env")
    creds = link_credentials(parser.parse_args(["stub"]))
    assert creds.token == "from-the-env" and creds.tls is None
    assert "from-the-env" not in repr(creds)
    link = creds.apply(Client("t"))
    assert (link.token, link.tls) == ("from-the-env", None)
    tls = link_credentials(parser.parse_args(["ping", "--tls"])).tls
    assert isinstance(tls, ssl.SSLContext) and tls.verify_mode == ssl.CERT_REQUIRED and tls.check_hostname
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["ping", "--tls-ca", str(tmp_path / "missing.pem")])
    assert exc.value.code == 2
    assert "--tls-ca" in capsys.readouterr().err


def test_the_token_flag_default_is_read_when_the_command_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """Not at parse time, and never put into the parsed defaults (so `--help` never shows a secret)."""
    monkeypatch.setenv(TOKEN_ENV, "secret-in-env")
    args = build_parser().parse_args(["gateway"])
    assert isinstance(args, argparse.Namespace) and args.token is None
