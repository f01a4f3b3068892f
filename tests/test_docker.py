"""docker/compose.yaml and the image's server config with tokens (issue 17 follow-up): there is no Docker
engine on the development machines, so the files are checked as data. Compose passes the user's
``TTES_TOKEN`` to the server (its controller token, and to its healthcheck ping) and to the stub, refusing to
start without it; the image's config plus that environment passes ``check_exposure`` (it binds 0.0.0.0)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from server.app import check_exposure
from server.config import ConfigError, load_config, with_env_tokens
from ttes.cli import build_parser

DOCKER = Path(__file__).resolve().parents[1] / "docker"
REQUIRED = re.compile(r"^\$\{TTES_TOKEN:\?[^}]+\}$")  # ${TTES_TOKEN:?message}: compose stops, says why


def _compose() -> dict:
    data = yaml.safe_load((DOCKER / "compose.yaml").read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data["services"]


def _interpolate(value: str, env: dict[str, str]) -> str:
    """Compose's ``${VAR:?message}``: the variable's value, or an error naming it."""

    def sub(m: re.Match[str]) -> str:
        if not env.get(m.group(1)):
            raise KeyError(f"{m.group(1)}: {m.group(2)}")
        return env[m.group(1)]

    return re.sub(r"\$\{(\w+):\?([^}]*)\}", sub, value)


def test_compose_gives_server_and_stub_the_same_required_token() -> None:
    services = _compose()
    server_env, stub_env = services["server"]["environment"], services["stub"]["environment"]
    assert REQUIRED.match(server_env["TTES_CONTROLLER_TOKEN"]), server_env
    assert server_env["TTES_TOKEN"] == server_env["TTES_CONTROLLER_TOKEN"]  # the healthcheck's ttes ping
    assert stub_env["TTES_TOKEN"] == server_env["TTES_CONTROLLER_TOKEN"]
    assert "TTES_OPERATOR_TOKEN" not in server_env  # nobody in the compose setup may load data or write files
    with pytest.raises(KeyError, match="TTES_TOKEN"):
        _interpolate(stub_env["TTES_TOKEN"], {})
    assert not any("token" in a.lower() for a in services["stub"]["command"])  # never on a command line (ps)


def test_compose_stub_command_parses_and_reaches_the_server() -> None:
    services = _compose()
    args = build_parser().parse_args(services["stub"]["command"][1:])
    assert (args.command, args.host, args.port) == ("stub", "server", 7000)
    assert services["server"]["ports"] == ["127.0.0.1:7000:7000"]


def test_image_config_with_the_compose_environment_starts() -> None:
    base = load_config(DOCKER / "server.toml")
    assert base.host == "0.0.0.0" and not base.tokens  # no secret in the committed file
    with pytest.raises(ConfigError, match="no role tokens"):
        check_exposure(base)  # started without compose's environment it refuses, saying why
    user = {"TTES_TOKEN": "a-long-random-token"}
    env = {k: _interpolate(v, user) for k, v in _compose()["server"]["environment"].items()}
    cfg = with_env_tokens(base, env)
    check_exposure(cfg)
    assert cfg.tokens == {"controller": "a-long-random-token"}


def test_dockerfile_healthcheck_pings_with_the_token_from_the_environment() -> None:
    text = (DOCKER / "Dockerfile").read_text(encoding="utf-8")
    (check,) = re.findall(r"HEALTHCHECK .*?CMD (\[.*?\])", text, re.S)
    args = build_parser().parse_args(json.loads(check)[1:])
    assert args.command == "ping" and args.token is None  # so TTES_TOKEN is sent
