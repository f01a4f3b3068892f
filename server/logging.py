"""Structured logs: every server log line is an event name plus key=value fields (or one JSON object).

Operators grep ``event=client_dropped``; log collectors parse ``--json-logs``. Built on the standard library's
:mod:`logging` (handlers, levels), so tests can capture records with ``caplog`` and read ``record.fields``.
Every ``ttes`` command logs in this format (``ttes.cli`` hands the formatter to the clients' loggers), and
values print plainly (``a,b``, ``true``, ``none``), never as Python reprs.
"""

from __future__ import annotations

import json
import logging
import math
import sys
import time
from typing import Any, TextIO

LOGGER_NAME = "ttes.server"


def plain(v: Any, depth: int = 0) -> str:
    """A field's value without Python's reprs: ``a,b`` for a list (``a+b`` one level down: ``DI.fig+AK_47.fig,
    DI.fig+M16.fig``), ``idle:10,loco:0`` for a dict, ``true``/``false``/``none``, floats to 6 digits."""
    if v is None or isinstance(v, bool):
        return {None: "none", True: "true", False: "false"}[v]
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else str(v)
    sep = "," if depth == 0 else "+"
    if isinstance(v, dict):
        return sep.join(f"{k}:{plain(x, depth + 1)}" for k, x in v.items())
    if isinstance(v, list | tuple | set | frozenset):
        return sep.join(plain(x, depth + 1) for x in v)
    return str(v)


def _text(v: Any) -> str:
    s = plain(v)
    if not s or any(c in s for c in ' "=\n\t'):
        return json.dumps(s)
    return s


class KeyValueFormatter(logging.Formatter):
    """``2026-01-01T12:00:00.123Z level=info event=client_accepted peer=127.0.0.1:5123 name=ig``"""

    def format(self, record: logging.LogRecord) -> str:
        fields: dict[str, Any] = getattr(record, "fields", {}) or {}
        ts = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created)) + f".{int(record.msecs):03d}Z"
        parts = [ts, f"level={record.levelname.lower()}", f"event={_text(record.getMessage())}"]
        parts += [f"{k}={_text(v)}" for k, v in fields.items()]
        if not record.name.startswith(LOGGER_NAME):  # a client's line (ttes.stub, ttes.link, ...): say whose
            parts.append(f"src={record.name}")
        if record.exc_info:
            parts.append(f"exc={_text(self.formatException(record.exc_info))}")
        return " ".join(parts)


class JsonFormatter(logging.Formatter):
    """One JSON object per line: ``{"time": ..., "level": ..., "event": ..., **fields}``."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {
            "time": record.created,
            "level": record.levelname.lower(),
            "event": record.getMessage(),
        }
        out.update(getattr(record, "fields", {}) or {})
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        return json.dumps(out, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))


class _CurrentStderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at emit time, so a replaced (and later closed) stderr — an
    embedding program's or a test runner's capture — never leaves the server logging into a closed file."""

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass


def configure(*, json_logs: bool = False, level: int = logging.INFO, stream: TextIO | None = None) -> None:
    """Send the server's logs to ``stream`` (stderr) in one of the two formats; idempotent."""
    logger = logging.getLogger(LOGGER_NAME)
    for h in list(logger.handlers):
        if getattr(h, "_ttes", False):
            logger.removeHandler(h)
    handler = logging.StreamHandler(stream) if stream is not None else _CurrentStderrHandler()
    handler.setFormatter(JsonFormatter() if json_logs else KeyValueFormatter())
    handler._ttes = True  # type: ignore[union-attr]  # marks our handlers (a plain attribute)
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False


class EventLogger:
    """``log.info("client_accepted", peer=..., name=...)``: an event name and structured fields."""

    def __init__(self, name: str = LOGGER_NAME) -> None:
        self.logger = logging.getLogger(name)

    def _log(self, level: int, event: str, fields: dict[str, Any], exc_info: bool = False) -> None:
        if self.logger.isEnabledFor(level):
            self.logger.log(level, event, extra={"fields": fields}, exc_info=exc_info)

    def debug(self, event: str, **fields: Any) -> None:
        self._log(logging.DEBUG, event, fields)

    def info(self, event: str, **fields: Any) -> None:
        self._log(logging.INFO, event, fields)

    def warning(self, event: str, **fields: Any) -> None:
        self._log(logging.WARNING, event, fields)

    def error(self, event: str, *, exc_info: bool = False, **fields: Any) -> None:
        self._log(logging.ERROR, event, fields, exc_info)


def get_logger(suffix: str = "") -> EventLogger:
    return EventLogger(f"{LOGGER_NAME}.{suffix}" if suffix else LOGGER_NAME)
