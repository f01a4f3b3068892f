"""Server settings (TOML, validation, overrides) and the structured log formats."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from server.config import DEFAULT_DATA_DIR, ConfigError, ServerConfig, config_from_mapping, load_config
from server.logging import JsonFormatter, KeyValueFormatter, get_logger


def test_defaults_bind_loopback_and_follow_the_seed() -> None:
    c = ServerConfig()
    assert (c.host, c.port, c.tick_hz) == ("127.0.0.1", 7000, 30.0)
    assert c.startup_script == "jack-ttes-soldier_low.jcl"
    assert c.data_dir == DEFAULT_DATA_DIR and (DEFAULT_DATA_DIR / "server").is_dir()
    assert c.throttle is None and c.report_interval is None  # the start-up script decides


def test_toml_file_top_level_or_server_table(tmp_path: Path) -> None:
    f = tmp_path / "ttes.toml"
    f.write_text('host = "0.0.0.0"\nport = 7100\ndata_dir = "data"\ntick_hz = 60\nthrottle = 0.05\n')
    c = load_config(f)
    assert (c.host, c.port, c.tick_hz, c.throttle) == ("0.0.0.0", 7100, 60, 0.05)
    assert c.data_dir == tmp_path / "data"  # relative to the file
    f.write_text('[server]\nmax_clients = 8\nmax_frame = 65536\nstartup_script = ""\njson_logs = true\n')
    c = load_config(f)
    assert (c.max_clients, c.max_frame, c.startup_script, c.json_logs) == (8, 65536, "", True)
    # flags override the file; None means "flag not given"
    c2 = c.with_overrides(port=0, host=None, data_dir=str(tmp_path))
    assert (c2.port, c2.host, c2.data_dir, c2.max_clients) == (0, c.host, tmp_path, 8)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("prot = 7000", r"unknown key\(s\) \['prot'\]"),
        ("port = 70000", r"port: 70000 is outside"),
        ('port = "7000"', r"port: must be a number"),
        ("port = 7000.5", r"port: must be an integer"),
        ("tick_hz = 0", r"tick_hz: 0 is outside"),
        ("throttle = -1", r"throttle: -1 is outside"),
        ("max_frame = 100", r"max_frame: 100 is outside"),
        ("json_logs = 1", r"json_logs: must be true or false"),
        ("host = ''", r"host: must be a non-empty string"),
        ("port = 1\n[server]\nport = 2", r"keys outside \[server\]"),
        ("port = = 3", r"not valid TOML"),
    ],
)
def test_bad_settings_name_the_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        load_config(f)
    assert str(f) in str(info.value)


def test_missing_file_and_direct_construction_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="max_clients"):
        ServerConfig(max_clients=0)
    with pytest.raises(ConfigError, match="data_dir: must be a non-empty string"):
        config_from_mapping({"data_dir": 3})


def _record(event: str, **fields: object) -> logging.LogRecord:
    r = logging.LogRecord("ttes.server.app", logging.INFO, __file__, 1, event, None, None)
    r.fields = fields
    return r


def test_key_value_and_json_log_lines() -> None:
    line = KeyValueFormatter().format(
        _record("client_closed", peer="127.0.0.1:5", reason="write stalled for 30 s")
    )
    assert " level=info event=client_closed peer=127.0.0.1:5 " in line
    assert line.endswith('reason="write stalled for 30 s"')
    obj = json.loads(JsonFormatter().format(_record("status", soldiers=10, rate=29.97, modes={"idle": 10})))
    assert obj["event"] == "status" and obj["soldiers"] == 10 and obj["modes"] == {"idle": 10}


def test_event_logger_carries_fields(caplog: pytest.LogCaptureFixture) -> None:
    log = get_logger("test")
    with caplog.at_level(logging.INFO, logger="ttes.server"):
        log.info("soldier_created", index=3, figure="DI.fig")
    (rec,) = [r for r in caplog.records if r.getMessage() == "soldier_created"]
    assert rec.fields == {"index": 3, "figure": "DI.fig"}  # type: ignore[attr-defined]


def test_docker_files_match_the_cli() -> None:
    """docker/Dockerfile runs `ttes server --config docker/server.toml` and pings with `ttes ping`."""
    import re

    from ttes.cli import build_parser

    repo = Path(__file__).resolve().parents[1]
    c = load_config(repo / "docker" / "server.toml")
    assert (c.host, c.port, c.data_dir) == ("0.0.0.0", 7000, Path("/srv/ttes"))
    text = (repo / "docker" / "Dockerfile").read_text()
    parser = build_parser()
    for cmd in re.findall(r"CMD (\[.*?\])", text):
        argv = json.loads(cmd)
        assert argv[0] == "ttes"
        args = parser.parse_args(argv[1:])  # exits (SystemExit) on an option the CLI lacks
        if args.command == "server":
            assert args.config == "/srv/ttes/docker/server.toml"
        else:
            assert (args.command, args.port) == ("ping", c.port)
    compose = (repo / "docker" / "compose.yaml").read_text()
    assert '"127.0.0.1:7000:7000"' in compose


def test_role_tokens_from_the_environment_win_over_the_file(tmp_path: Path) -> None:
    from server.config import TOKEN_ENV, with_env_tokens

    assert TOKEN_ENV == {
        "observer": "TTES_OBSERVER_TOKEN",
        "controller": "TTES_CONTROLLER_TOKEN",
        "operator": "TTES_OPERATOR_TOKEN",
    }
    f = tmp_path / "ttes.toml"
    f.write_text('observer_token = "file-observer"\ncontroller_token = "file-controller"\n')
    c = with_env_tokens(
        load_config(f), {"TTES_CONTROLLER_TOKEN": "env-controller", "TTES_OPERATOR_TOKEN": ""}
    )
    assert c.tokens == {"observer": "file-observer", "controller": "env-controller"}  # empty: not given
    assert with_env_tokens(ServerConfig(), {}) == ServerConfig()
    with pytest.raises(ConfigError, match="TTES_OPERATOR_TOKEN: must be a string of at least 8") as exc:
        with_env_tokens(ServerConfig(), {"TTES_OPERATOR_TOKEN": "short"})
    assert "short" not in str(exc.value)  # a secret is never echoed, not even a bad one


def test_server_command_reads_tokens_from_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Beyond loopback an env token lets `ttes server` past check_exposure (then it fails on the data)."""
    from ttes.cli import main

    monkeypatch.delenv("TTES_CONTROLLER_TOKEN", raising=False)
    argv = ["server", "--host", "0.0.0.0", "--port", "0", "--data-dir", str(tmp_path)]
    assert main(argv) == 2
    assert "no role tokens are configured" in capsys.readouterr().err
    monkeypatch.setenv("TTES_CONTROLLER_TOKEN", "env-controller")
    assert main(argv) == 1  # past the check: the data dir has no start-up script (a runtime error)
    err = capsys.readouterr().err
    assert "start-up script" in err and "env-controller" not in err


def test_spawned_private_servers_ignore_role_tokens_in_the_environment(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A spawned `ttes server` is a private loopback server: the caller's TTES_*_TOKEN must not lock it."""
    from client_stub.link.spawn import child_env

    monkeypatch.setenv("TTES_CONTROLLER_TOKEN", "env-controller")
    monkeypatch.setenv("TTES_TOKEN", "client-token")
    env = child_env()
    assert "TTES_CONTROLLER_TOKEN" not in env and env["TTES_TOKEN"] == "client-token"


def test_the_flow_limits_are_settings_and_listed_in_help() -> None:
    from server.config import LIMITS, limits_help

    c = config_from_mapping({"frame_timeout": 2.5, "max_clients_per_host": 4, "cache_dir": "/tmp/x"})
    assert (c.frame_timeout, c.max_clients_per_host, c.cache_dir) == (2.5, 4, Path("/tmp/x"))
    with pytest.raises(ConfigError, match="frame_timeout"):
        ServerConfig(frame_timeout=0.0)
    with pytest.raises(ConfigError, match="max_clients_per_host"):
        ServerConfig(max_clients_per_host=0)
    assert all(f"  {k} = " in limits_help() for k in LIMITS)
