"""docker/: compose.yaml, the Dockerfile, the lock and .dockerignore checked as data (the development machines
have no Docker engine; docker/buildah_check.sh builds and runs the image there with buildah, by hand). Compose
passes the user's ``TTES_TOKEN`` to the server (its controller token, and to its healthcheck ping), the stub
and the gateway, refusing to start without it; the image's config plus that environment passes
``check_exposure`` (it binds 0.0.0.0). One image for every service; the stub writes into a volume the image's
user owns."""

from __future__ import annotations

import argparse
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


def test_one_image_for_every_service_built_once() -> None:
    services = _compose()
    image = services["server"]["image"]
    assert services["server"]["build"]["dockerfile"] == "docker/Dockerfile"
    for name in ("stub", "gateway"):
        assert services[name]["image"] == image and "build" not in services[name], name


def test_gateway_hears_udp_3000_on_every_interface_and_sends_the_token() -> None:
    gateway = _compose()["gateway"]
    args = build_parser().parse_args(gateway["command"][1:])
    assert (args.command, args.interface, args.dis_port, args.host, args.port) == (
        "gateway", "0.0.0.0", 3000, "server", 7000
    )  # fmt: skip
    assert gateway["ports"] == ["3000:3000/udp"]
    server_env = _compose()["server"]["environment"]
    assert gateway["environment"]["TTES_TOKEN"] == server_env["TTES_CONTROLLER_TOKEN"]
    assert "network_mode: host" in (DOCKER / "compose.yaml").read_text(encoding="utf-8")  # the broadcast note


def test_stub_writes_into_a_volume_the_image_user_owns() -> None:
    """A bind mount of ./out would be created root-owned by the engine; a named volume starts as a copy of the
    image's /out, which the Dockerfile makes the uid 1000 user's."""
    stub = _compose()["stub"]
    (volume,) = stub["volumes"]
    name, target = volume.split(":")
    assert "/" not in name and name in yaml.safe_load((DOCKER / "compose.yaml").read_text())["volumes"]
    assert stub["command"][stub["command"].index("--out") + 1].startswith(target + "/")
    text = (DOCKER / "Dockerfile").read_text(encoding="utf-8")
    assert "--uid 1000 ttes" in text and re.search(rf"install -d -o ttes -g ttes [^\n]*{target}\b", text)


def test_dockerfile_base_is_pinned_and_installs_the_lock_with_hashes() -> None:
    text = (DOCKER / "Dockerfile").read_text(encoding="utf-8")
    (base,) = re.findall(r"^ARG BASE=(\S+)$", text, re.M)
    assert re.fullmatch(r"python:3\.11\.\d+-slim-bookworm(@sha256:[0-9a-f]{64})?", base), base
    assert re.search(r"pip install --require-hashes --no-deps -r \S*requirements\.lock", text)
    assert "pip check" in text


def _requirement_names(specs: list[str]) -> set[str]:
    return {re.split(r"[<>=!~\[; ]", s, maxsplit=1)[0].lower().replace("_", "-") for s in specs}


def test_lock_pins_every_dependency_of_the_server_the_stub_fabric_and_fast_extras_with_hashes() -> None:
    import tomllib

    project = tomllib.loads((DOCKER.parent / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = project["optional-dependencies"]
    served = extras["stub"] + extras["fabric"] + extras["fast"]  # the scaled profile's processes
    wanted = _requirement_names(project["dependencies"] + served)
    lock = (DOCKER / "requirements.lock").read_text(encoding="utf-8")
    pinned = dict(re.findall(r"^([A-Za-z0-9_.-]+)==(\S+) \\\n\s+--hash=sha256:", lock, re.M))
    assert wanted <= {name.lower().replace("_", "-") for name in pinned}, wanted - set(pinned)
    assert pinned["PyOpenGL".lower()] == "3.1.10"  # pyproject pins it exactly


def test_dockerignore_sends_the_wheels_sources_and_nothing_else() -> None:
    lines = [ln for ln in (DOCKER.parent / ".dockerignore").read_text().splitlines() if ln and ln[0] != "#"]
    assert lines[0] == "*"  # everything out, then the wheel's inputs back in (setup.py, docker/Dockerfile)
    kept = {ln[1:].rstrip("/") for ln in lines if ln.startswith("!")}
    wheel_inputs = {"pyproject.toml", "setup.py", "README.md", "figures", "channelsets", "posture_graphs"}
    code = {"peabody", "protocol", "server", "authoring", "client_stub", "ttes"}
    assert wheel_inputs | code | {"docker/requirements.lock", "docker/server.toml"} <= kept
    assert not kept & {".venv", ".git", "out", "tests", "bench"}


# -- the scaled profile (issue 21): N shards + a front-end + the stub, on the fabric -------------------------
SCALED = ("front", "shard0", "shard1", "scaled-stub")


def _argv(service: dict) -> argparse.Namespace:
    """The service's command through ttes's own parser (an invalid one exits: SystemExit fails the test)."""
    assert service["command"][0] == "ttes"
    return build_parser().parse_args(service["command"][1:])


def test_scaled_profile_is_its_own_and_the_default_stays_one_server() -> None:
    services = _compose()
    assert {name for name, s in services.items() if s.get("profiles") == ["scaled"]} == set(SCALED)
    assert "profiles" not in services["server"] and "profiles" not in services["stub"]
    for name in SCALED:  # compose's one default network: they reach each other by service name
        assert not {"networks", "network_mode", "build"} & services[name].keys(), name
        assert services[name]["image"] == services["server"]["image"], name
    ports = [p for s in services.values() for p in s.get("ports", [])]
    assert len({p.rsplit(":", 1)[0] for p in ports}) == len(ports)  # no host port published twice


def test_scaled_commands_parse_and_the_shards_cover_the_front_ends_count() -> None:
    from server.fabric.nodes import Sharding

    services = _compose()
    front = _argv(services["front"])
    assert front.command == "front" and front.fabric == "zenoh" and front.config == "/etc/ttes/server.toml"
    listen_host, listen_port = front.fabric_listen.rsplit(":", 1)
    assert listen_host == "0.0.0.0" and 0 < int(listen_port) < 65536  # the shards' containers reach it
    shards = [name for name in services if name.startswith("shard")]
    seen = set()
    for name in shards:
        args = _argv(services[name])
        assert args.command == "server" and args.config == front.config, name
        sharding = Sharding.parse(args.shard)
        assert sharding.n == front.shards and args.fabric_connect == [f"front:{listen_port}"], name
        seen.add(sharding.k)
        assert services[name]["depends_on"]["front"]["condition"] == "service_healthy", name
    assert seen == set(range(front.shards))  # every shard K/N once
    stub = services["scaled-stub"]
    args = _argv(stub)
    assert (args.command, args.host, args.port, args.headless) == ("stub", "front", 7000, True)
    assert set(stub["depends_on"]) == {"front", *shards}
    assert services["front"]["ports"] == ["127.0.0.1:7001:7000"]  # 7000 in its container, as the server's


def test_every_scaled_process_starts_with_the_compose_token() -> None:
    """Each binds 0.0.0.0 in its container (docker/server.toml): each needs the controller token, and the
    stub sends it; never on a command line."""
    services, user = _compose(), {"TTES_TOKEN": "a-long-random-token"}
    for name in ("front", "shard0", "shard1"):
        env = {k: _interpolate(v, user) for k, v in services[name]["environment"].items()}
        cfg = with_env_tokens(load_config(DOCKER / "server.toml"), env)
        check_exposure(cfg)
        assert cfg.tokens == {"controller": "a-long-random-token"} and env["TTES_TOKEN"] == user["TTES_TOKEN"]
    stub_token = services["stub"]["environment"]["TTES_TOKEN"]
    assert services["scaled-stub"]["environment"]["TTES_TOKEN"] == stub_token
    assert not any("token" in a.lower() for name in SCALED for a in services[name]["command"])
