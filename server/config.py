"""The server's settings: one dataclass, loaded from TOML (``tomllib``) and validated field by field.

A TOML file may hold the keys at the top level or in a ``[server]`` table. Unknown keys, wrong types and
out-of-range values are :class:`ConfigError` naming the file and the key, so a typo never silently falls back
to a default. Command-line flags override the file (:meth:`ServerConfig.with_overrides`). The role tokens have
no flags (a command line shows in ``ps``): they come from the file or, winning over it, from the environment
(:func:`with_env_tokens`, ``TTES_OBSERVER_TOKEN`` / ``TTES_CONTROLLER_TOKEN`` / ``TTES_OPERATOR_TOKEN``), as a
container or a service manager hands secrets over.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.events import DEFAULT_MAX_SOLDIERS
from server.data_root import DATA_ROOT

DEFAULT_DATA_DIR = DATA_ROOT  # the checkout's root, or an install's copy of the shipped data folders
DEFAULT_STARTUP_SCRIPT = "jack-ttes-soldier_low.jcl"
MAX_SOLDIERS_LIMIT = 65536
# the environment variable of each role's token (ttes server; the env wins over the config file)
TOKEN_ENV = {
    "observer": "TTES_OBSERVER_TOKEN",
    "controller": "TTES_CONTROLLER_TOKEN",
    "operator": "TTES_OPERATOR_TOKEN",
}


class ConfigError(ValueError):
    """A bad setting; ``where`` names the file and key."""

    def __init__(self, message: str, where: str = "") -> None:
        self.message = message
        self.where = where
        super().__init__(f"{where}: {message}" if where else message)


@dataclass(frozen=True)
class ServerConfig:
    """Everything ``ttes server`` can be told. Times in seconds, rates per second."""

    host: str = "127.0.0.1"  # loopback by default: exposing the server is an explicit choice
    port: int = 7000  # 0 = any free port (tests)
    ws_port: int | None = None  # also serve the protocol over WebSocket here (browsers; 0 = any free port)
    ws_origins: tuple[str, ...] = ()  # browser pages allowed to connect over WebSocket; () = loopback pages
    data_dir: Path = field(default_factory=lambda: DEFAULT_DATA_DIR)
    startup_script: str = DEFAULT_STARTUP_SCRIPT  # "" = none: a client's JCL starts the simulation
    tick_hz: float = 30.0
    throttle: float | None = None  # None: what the start-up script sets (set_ttes_soldier_throttle)
    report_interval: float | None = None  # None: what the script sets (set_ttes_report_interval), else 30
    max_clients: int = 256
    max_soldiers: int = DEFAULT_MAX_SOLDIERS  # soldier indices 0 .. max_soldiers-1 (announced in ACCEPT)
    max_soldiers_per_client: int = 4096  # soldiers one client may create (CREATE_SOLDIER)
    max_frame: int = 1 << 20  # largest frame we accept (announced in ACCEPT)
    max_requests_per_s: float = 1e6  # entity rows + other messages per client and second; more: slower reads
    handshake_timeout: float = 10.0  # a connection that sends no HELLO in time is closed
    frame_timeout: float = 10.0  # a frame begun after HELLO must be whole this soon, else the client goes
    max_clients_per_host: int = 128  # connections from one peer address (it never holds every slot)
    write_timeout: float = 30.0  # a client that takes no bytes for this long is dropped
    control_queue: int = 256  # control messages waiting for one client; a full queue stops reading its socket
    name: str = "jack-ttes"
    json_logs: bool = False
    record_clips: bool = False  # keep every soldier's clip starts (debug; report_ttes_clips)
    cache_dir: Path | None = None  # channelset .npz caches (None: $TTES_CACHE_DIR or the XDG cache dir)
    orphan_grace: float = 12.0  # seconds a gone client's soldiers wait for it to reconnect (the DIS timeout)
    min_report_interval: float = 0.1  # the shortest STATUS period a client may ask for
    # a credential per role (HELLO token); any set: roles come only from tokens. Never logged or printed.
    observer_token: str = field(default="", repr=False)
    controller_token: str = field(default="", repr=False)
    operator_token: str = field(default="", repr=False)
    tls_cert: str = ""  # PEM certificate (chain) file: serve TLS (server.tls); "" = plain TCP
    tls_key: str = ""  # its PEM private key file ("" = in tls_cert)

    def __post_init__(self) -> None:
        validate(self)

    @property
    def tokens(self) -> dict[str, str]:
        """The configured tokens by role (only those set)."""
        given = {"observer": self.observer_token, "controller": self.controller_token}
        given["operator"] = self.operator_token
        return {role: t for role, t in given.items() if t}

    def with_overrides(self, **changes: Any) -> ServerConfig:
        """A copy with the given fields replaced (``None`` values are ignored: flag not given)."""
        given = {k: v for k, v in changes.items() if v is not None}
        for key in ("data_dir", "cache_dir"):
            if key in given:
                given[key] = Path(given[key])
        return dataclasses.replace(self, **given)


_FIELDS = {f.name: f for f in dataclasses.fields(ServerConfig)}

# what a peer may do and what it costs (docs/PROTOCOL.md §15; `ttes server --help` lists them with defaults)
LIMITS = {
    "max_clients": "connections; the next HELLO is refused",
    "max_clients_per_host": "connections from one peer address; the next HELLO is refused",
    "handshake_timeout": "seconds to send HELLO, else closed",
    "frame_timeout": "seconds to finish a frame begun after HELLO, else dropped",
    "write_timeout": "seconds one write to a client may stall, else dropped",
    "control_queue": "answers waiting for a client; a full queue stops reading it (backpressure)",
    "max_requests_per_s": "requests per client and second; more: its socket is read more slowly",
    "max_frame": "bytes in one frame",
    "max_soldiers_per_client": "soldiers one client id may own",
    "min_report_interval": "the shortest STATUS period a client may ask for",
    "orphan_grace": "seconds a gone client's soldiers wait for it to come back",
}


def limits_help() -> str:
    """The limits with their defaults, one per line (for ``--help``)."""
    d = ServerConfig()
    return "\n".join(f"  {k} = {getattr(d, k)!r}: {v}" for k, v in LIMITS.items())


def _check_number(
    name: str, v: Any, lo: float, hi: float, *, integer: bool = False, lo_open: bool = False
) -> None:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ConfigError(f"must be a number, not {type(v).__name__}", name)
    if integer and not isinstance(v, int):
        raise ConfigError("must be an integer", name)
    if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
        bound = f"({lo}, {hi}]" if lo_open else f"[{lo}, {hi}]"
        raise ConfigError(f"{v!r} is outside {bound}", name)


def _validate_websocket(c: ServerConfig) -> None:
    if c.ws_port is not None:
        _check_number("ws_port", c.ws_port, 0, 65535, integer=True)
    if not isinstance(c.ws_origins, tuple) or not all(isinstance(o, str) and o for o in c.ws_origins):
        raise ConfigError('must be a list of origins ("http://host:port") or ["*"]', "ws_origins")


def validate(c: ServerConfig) -> None:
    """Raise :class:`ConfigError` for the first bad field."""
    if not isinstance(c.host, str) or not c.host:
        raise ConfigError("must be a non-empty string", "host")
    _check_number("port", c.port, 0, 65535, integer=True)
    _validate_websocket(c)
    if not isinstance(c.data_dir, Path):
        raise ConfigError("must be a path", "data_dir")
    if c.cache_dir is not None and not isinstance(c.cache_dir, Path):
        raise ConfigError("must be a path", "cache_dir")
    if not isinstance(c.startup_script, str):
        raise ConfigError("must be a string", "startup_script")
    _check_number("tick_hz", c.tick_hz, 0.0, 1000.0, lo_open=True)
    if c.throttle is not None:
        _check_number("throttle", c.throttle, 0.0, 60.0)
    if c.report_interval is not None:
        _check_number("report_interval", c.report_interval, 0.0, 86400.0, lo_open=True)
    _check_number("max_clients", c.max_clients, 1, 100_000, integer=True)
    _check_number("max_soldiers", c.max_soldiers, 1, MAX_SOLDIERS_LIMIT, integer=True)
    _check_number("max_soldiers_per_client", c.max_soldiers_per_client, 0, MAX_SOLDIERS_LIMIT, integer=True)
    _check_number("max_frame", c.max_frame, 4096, 2**32 - 1, integer=True)
    _check_number("max_requests_per_s", c.max_requests_per_s, 0.0, 1e9, lo_open=True)
    _check_number("handshake_timeout", c.handshake_timeout, 0.0, 3600.0, lo_open=True)
    _check_number("write_timeout", c.write_timeout, 0.0, 3600.0, lo_open=True)
    _check_number("frame_timeout", c.frame_timeout, 0.0, 3600.0, lo_open=True)
    _check_number("max_clients_per_host", c.max_clients_per_host, 1, 100_000, integer=True)
    _check_number("control_queue", c.control_queue, 8, 1_000_000, integer=True)
    if not isinstance(c.name, str) or not c.name:
        raise ConfigError("must be a non-empty string", "name")
    _check_number("orphan_grace", c.orphan_grace, 0.0, 86400.0)
    _check_number("min_report_interval", c.min_report_interval, 0.0, 3600.0, lo_open=True)
    for role in ("observer", "controller", "operator"):
        token = getattr(c, f"{role}_token")
        if not isinstance(token, str) or (token and len(token) < 8):
            raise ConfigError("must be a string of at least 8 characters (or empty: none)", f"{role}_token")
    for key in ("tls_cert", "tls_key"):
        if not isinstance(getattr(c, key), str):
            raise ConfigError("must be a path string", key)
    if c.tls_key and not c.tls_cert:
        raise ConfigError("a key without tls_cert", "tls_key")
    for flag in ("json_logs", "record_clips"):
        if not isinstance(getattr(c, flag), bool):
            raise ConfigError("must be true or false", flag)


def config_from_mapping(
    values: dict[str, Any], source: str = "<config>", base_dir: Path | None = None
) -> ServerConfig:
    """A config from a TOML-like mapping; a relative ``data_dir`` is taken relative to ``base_dir``."""
    if "server" in values and isinstance(values["server"], dict):
        rest = {k: v for k, v in values.items() if k != "server"}
        if rest:
            raise ConfigError(f"keys outside [server]: {sorted(rest)}", source)
        values = values["server"]
    unknown = sorted(set(values) - set(_FIELDS))
    if unknown:
        raise ConfigError(f"unknown key(s) {unknown}; known: {sorted(_FIELDS)}", source)
    kwargs = dict(values)
    if isinstance(kwargs.get("ws_origins"), list):
        kwargs["ws_origins"] = tuple(kwargs["ws_origins"])
    for key in ("data_dir", "cache_dir"):
        if key in kwargs:
            if not isinstance(kwargs[key], str) or not kwargs[key]:
                raise ConfigError("must be a non-empty string", f"{source}: {key}")
            p = Path(kwargs[key]).expanduser()
            kwargs[key] = p if p.is_absolute() or base_dir is None else base_dir / p
    try:
        return ServerConfig(**kwargs)
    except ConfigError as exc:
        raise ConfigError(exc.message, f"{source}: {exc.where}") from None


def load_config(path: str | Path) -> ServerConfig:
    """Read a TOML config file (``ConfigError`` with the file name on any problem)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror or exc}", str(p)) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"not valid TOML: {exc}", str(p)) from None
    return config_from_mapping(data, str(p), p.resolve().parent)


def with_env_tokens(config: ServerConfig, environ: Mapping[str, str]) -> ServerConfig:
    """``config`` with each role token that ``environ`` sets (:data:`TOKEN_ENV`; empty = not set) in place of
    the file's. A bad one is a ConfigError naming the variable, never its value."""
    given = {f"{role}_token": environ[var] for role, var in TOKEN_ENV.items() if environ.get(var)}
    try:
        return config.with_overrides(**given)
    except ConfigError as exc:
        var = {f"{role}_token": v for role, v in TOKEN_ENV.items()}.get(exc.where, exc.where)
        raise ConfigError(exc.message, var) from None
