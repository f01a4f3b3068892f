"""What the server a load test drove says it is, from its STATUS text (issue 21): a single server, a shard
(``ttes server --shard K/N``), or a front-end naming its shards — so a report of a run against a
front-end says which shards stood behind it and whether each was up.

The texts are the server's (``server.fabric.nodes``: ``front-end of 2 shards: 0 up, 1 on 0 (gone)``,
``shard 0/2, 123 batches``); a STATUS without either is a single server's. The client asks for a STATUS a
second on its own connection (``set_ttes_report_interval``, a connection's own setting), so a run
shorter than the server's report interval (30 s by default) still hears one.
"""

from __future__ import annotations

import re
from typing import Any

STATUS_EVERY_S = 1.0  # the load tester's own STATUS period (its first connection's setting only)
STATUS_JCL = f"set_ttes_report_interval({STATUS_EVERY_S:g});"

_FRONT = re.compile(r"front-end of (\d+) shards: (.*)$")
_SHARD_PART = re.compile(r"(\d+) (?:up|on (\d+))( \(gone\))?")
_SHARD = re.compile(r"(?:^|; )shard (\d+)/(\d+)\b")


def server_role(text: str | None) -> dict[str, Any]:
    """``{"role": "front-end", "shards": [{"shard", "animated_by", "present"}, ...]}``, ``{"role": "shard",
    "shard": K, "of": N}``, ``{"role": "server"}``, or ``{"role": None}`` when no STATUS came; with the
    STATUS text itself under ``"status"``. Never raises on text it does not know (a newer server's)."""
    if text is None:
        return {"role": None, "status": None}
    if m := _FRONT.search(text):
        shards = [
            {"shard": int(k), "animated_by": int(on or k), "present": not gone}
            for k, on, gone in _SHARD_PART.findall(m.group(2))
        ]
        return {"role": "front-end", "shards": shards, "status": text}
    if m := _SHARD.search(text):
        return {"role": "shard", "shard": int(m.group(1)), "of": int(m.group(2)), "status": text}
    return {"role": "server", "status": text}


def role_line(server: dict[str, Any]) -> str:
    """The report's line for it: ``front-end of 2 shards (0 up; 1 on 0, gone)``, ``shard 1/2``, ``a single
    server``, or ``unknown (no STATUS)``."""
    match server.get("role"):
        case "front-end":
            parts = [
                f"{s['shard']} "
                + ("up" if s["animated_by"] == s["shard"] else f"on {s['animated_by']}")
                + ("" if s["present"] else ", gone")
                for s in server["shards"]
            ]
            return f"front-end of {len(parts)} shards ({'; '.join(parts)})"
        case "shard":
            return f"shard {server['shard']}/{server['of']}"
        case "server":
            return "a single server"
    return "unknown (no STATUS)"
