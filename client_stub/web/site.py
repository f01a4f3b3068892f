"""The page's HTTP server (``ttes web``): the static files of ``client_stub/web``, the village and a config.

h11 over trio streams, GET and HEAD only, keep-alive. What it serves, and nothing else:

* ``/`` and ``/index.html``, ``/js/*.js``, ``/vendor/...`` (three.js, msgpack: :mod:`client_stub.web.vendor`);
* ``/data/village.glb`` and ``/data/village.json``: the stub's terrain and its landmarks;
* ``/config.json``: where the page connects (the server's WebSocket URL) and its defaults (soldiers, version);
* ``/entities.json`` while ``ttes web --replay`` drives the server: where each replayed soldier is and his DIS
  force (the wire carries neither entity positions nor forces: a page that only watches could not place them,
  nor colour them by force as the stub does).

The page then talks to the Jack/TTES server's WebSocket port itself (docs/PROTOCOL.md §2.1): this process
never touches the protocol.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from email.utils import formatdate
from pathlib import Path
from typing import Any

import h11
import trio

from client_stub.data_paths import DEFAULT_TERRAIN

WEB = Path(__file__).resolve().parent
JS = "text/javascript; charset=utf-8"
TYPES = {".html": "text/html; charset=utf-8", ".js": JS, ".mjs": JS, ".json": "application/json",
         ".glb": "model/gltf-binary"}  # fmt: skip
MAX_REQUEST = 16384  # bytes of request head (h11's incomplete-event limit)
IDLE_TIMEOUT_S = 30.0


@dataclass
class Site:
    """What the page is served with: its config (``/config.json``) and where its files are."""

    config: dict[str, Any] = field(default_factory=dict)
    root: Path = WEB
    terrain: Path = DEFAULT_TERRAIN
    requests: int = 0
    # the replayed soldiers' last requests (ENTITY_REQUEST_DTYPE) and DIS force ids (1 friendly, 2 opposing)
    entities: Callable[[], tuple[Any, Any]] | None = None

    def resolve(self, target: str) -> Path | None:
        """The file a request path names, or None (outside the served folders, or missing)."""
        path = target.split("?", 1)[0].split("#", 1)[0]
        if path in ("/", ""):
            path = "/index.html"
        if path.startswith("/data/"):
            name = path[len("/data/") :]
            allowed = {self.terrain.name: self.terrain, self.terrain.with_suffix(".json").name: None}
            if name not in allowed:
                return None
            found = allowed[name] or self.terrain.with_suffix(".json")
            return found if found.is_file() else None
        parts = [p for p in path.split("/") if p]
        if not parts or any(p in (".", "..") or p.startswith(".") for p in parts):
            return None
        if parts[0] not in ("index.html", "js", "vendor") or Path(parts[-1]).suffix not in TYPES:
            return None
        found = self.root.joinpath(*parts)
        return found if found.is_file() else None

    def body(self, target: str) -> tuple[int, str, bytes]:
        """(status, content type, body) for a GET of ``target``."""
        path = target.split("?", 1)[0]
        if path == "/config.json":
            return 200, TYPES[".json"], json.dumps(self.config).encode()
        if path == "/entities.json" and self.entities is not None:
            return 200, TYPES[".json"], json.dumps(entity_rows(*self.entities())).encode()
        found = self.resolve(target)
        if found is None:
            if target.startswith("/vendor/"):
                text = b"three.js and msgpack are not vendored: run `make vendor` (npm) in the checkout\n"
                return 404, "text/plain; charset=utf-8", text
            return 404, "text/plain; charset=utf-8", b"not found\n"
        return 200, TYPES[found.suffix], found.read_bytes()

    async def serve_client(self, stream: trio.abc.Stream) -> None:
        """One HTTP/1.1 connection: answer its requests until it closes, errs or idles."""
        conn = h11.Connection(h11.SERVER, max_incomplete_event_size=MAX_REQUEST)
        try:
            while conn.our_state is not h11.MUST_CLOSE and conn.their_state is not h11.DONE:
                event = await self._next(conn, stream)
                if isinstance(event, h11.Request):
                    await self._answer(conn, stream, event)
                elif event is None or isinstance(event, h11.ConnectionClosed):
                    break
                if conn.our_state is h11.DONE and conn.their_state is h11.DONE:
                    conn.start_next_cycle()
        except (h11.RemoteProtocolError, trio.BrokenResourceError, trio.ClosedResourceError):
            pass
        finally:
            await trio.aclose_forcefully(stream)

    async def _next(self, conn: h11.Connection, stream: trio.abc.Stream) -> Any:
        while True:
            event = conn.next_event()
            if event is h11.NEED_DATA:
                with trio.move_on_after(IDLE_TIMEOUT_S):
                    conn.receive_data(bytes(await stream.receive_some(65536)))
                    continue
                return None
            if isinstance(event, h11.Request | h11.ConnectionClosed):
                return event
            # Data / EndOfMessage of a request: bodies are ignored

    async def _answer(self, conn: h11.Connection, stream: trio.abc.Stream, req: h11.Request) -> None:
        self.requests += 1
        method, target = req.method.decode(), req.target.decode("latin-1")
        if method not in ("GET", "HEAD"):
            status, kind, body = 405, "text/plain; charset=utf-8", b"GET or HEAD only\n"
        else:
            status, kind, body = self.body(target)
        headers = [("content-type", kind), ("content-length", str(len(body))), ("cache-control", "no-store"),
                   ("date", formatdate(usegmt=True)), ("x-content-type-options", "nosniff")]  # fmt: skip
        while conn.their_state is h11.SEND_BODY:  # drain a request body we do not read
            if conn.next_event() is h11.NEED_DATA:
                conn.receive_data(bytes(await stream.receive_some(65536)))
        await stream.send_all(conn.send(h11.Response(status_code=status, headers=headers)) or b"")
        if method != "HEAD":
            await stream.send_all(conn.send(h11.Data(data=body)) or b"")
        await stream.send_all(conn.send(h11.EndOfMessage()) or b"")


def entity_rows(rows: Any, forces: Any) -> dict[str, Any]:
    """``{"soldiers": [[index, x, y, z, heading, vx, vy, vz, appearance, weapon, force], ...]}`` (metres,
    degrees, m/s, Performer axes; the DIS force id) from entity request rows and their soldiers' forces."""
    out = []
    for r, force in zip(rows, forces, strict=True):
        p, v = r["position"], r["velocity"]
        out.append([int(r["index"]), *(round(float(x), 3) for x in (*p, r["heading"], *v)),
                    int(r["appearance"]), int(r["weapon"]), int(force)])  # fmt: skip
    return {"soldiers": out}


async def serve_site(site: Site, sockets: list[Any], *, task_status: Any = trio.TASK_STATUS_IGNORED) -> None:
    """Serve ``site`` on listening stdlib ``sockets`` (bound by the caller, so that a taken port fails before
    anything loads) until cancelled; ``task_status.started((host, port))`` of the first."""
    listeners = [trio.SocketListener(trio.socket.from_stdlib_socket(s)) for s in sockets]
    bound = listeners[0].socket.getsockname()[:2]
    async with trio.open_nursery() as nursery:
        task_status.started((bound[0], bound[1]))
        await trio.serve_listeners(site.serve_client, listeners, handler_nursery=nursery)


__all__ = ["Site", "serve_site"]
