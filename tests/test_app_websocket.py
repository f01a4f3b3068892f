"""The TTES stream over WebSocket (``ws_port``, server.websocket): a WS client shakes hands and gets the same
JOINT_UPDATES as a TCP client; bad WebSocket input (text, an oversized message, garbage, a foreign page's
Origin) ends that client only; the adapter's parser path under Hypothesis (any bytes after the upgrade, any
split of valid client frames)."""

from __future__ import annotations

import os
import shutil
import ssl
import struct
from pathlib import Path

import pytest
import trio
import trio.testing
from hypothesis import given, settings
from hypothesis import strategies as st
from test_server_support import Client, running_server
from wsproto.events import TextMessage

from protocol.connection import CLIENT, Connection
from protocol.entity import Appearance
from protocol.errors import ErrorCode
from protocol.events import Accept, Error, Hello, JointUpdates, Ready, Subscribe
from server.config import ConfigError, ServerConfig, config_from_mapping
from server.websocket import WebSocketError, WebSocketStream, origin_allowed


def ws_port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.ws_addresses[0][1]


async def open_ws(port: int, *, origin: str | None = None, max_message: int = 1 << 22) -> WebSocketStream:
    tcp = await trio.open_tcp_stream("127.0.0.1", port)
    ws = WebSocketStream(tcp, client=True, max_message=max_message)
    await ws.connect(f"127.0.0.1:{port}", "/", origin=origin)
    return ws


async def ws_client(port: int, name: str = "ws", version: int = 2) -> Client:
    c = Client(await open_ws(port), Connection(CLIENT))  # type: ignore[arg-type]
    await c.send(Hello(name, "controller", version=version))
    c.accept = await c.expect(Accept)
    return c


def _frames(events: list[object]) -> list[tuple[int, list[int], list[list[bool]]]]:
    ups = [e for e in events if isinstance(e, JointUpdates)]
    return [(u.tick, u.indices.tolist(), u.changed.tolist() if u.changed is not None else []) for u in ups]


async def _drain_both(a: Client, b: Client, seconds: float) -> list[list[object]]:
    got: list[list[object]] = [[], []]

    async def one(k: int, c: Client) -> None:
        got[k] = list(await c.drain(seconds))

    async with trio.open_nursery() as n:
        n.start_soon(one, 0, a)
        n.start_soon(one, 1, b)
    return got


async def test_a_websocket_client_gets_the_joint_updates_of_a_tcp_client(
    autojump_clock: trio.abc.Clock,
) -> None:
    async with running_server(ws_port=0) as server:
        tcp = await Client.open(server.addresses[0][1], "tcp")
        ws = await ws_client(ws_port_of(server))
        assert ws.accept is not None and ws.accept.role == "controller" and ws.accept.version == 2
        for c in (tcp, ws):
            await c.expect(Ready)
            await c.send(Subscribe((0, 1)))
        await _drain_both(tcp, ws, 0.5)  # the full updates
        await tcp.requests(index=0, appearance=Appearance.UPRIGHT, velocity=(0.0, 1.4, 0.0), heading=0.0)
        got = await _drain_both(tcp, ws, 2.0)
        assert len(_frames(got[0])) >= 20
        assert _frames(got[0]) == _frames(got[1])  # the same frames, tick by tick
        for a, b in zip(
            [e for e in got[0] if isinstance(e, JointUpdates)],
            [e for e in got[1] if isinstance(e, JointUpdates)],
            strict=True,
        ):
            assert (a.dofs == b.dofs).all() and (a.positions == b.positions).all()
        assert len(server.sessions) == 2


async def _ended(ws: WebSocketStream, seconds: float = 20.0) -> bytes:
    """Everything received until the server ends the WebSocket."""
    got = bytearray()
    with trio.fail_after(seconds):
        while data := await ws.receive_some():
            got += data
    return bytes(got)


async def test_bad_websocket_input_closes_that_client_only(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(ws_port=0, max_frame=4096) as server:
        port = ws_port_of(server)
        good = await ws_client(port, "good")
        await good.expect(Ready)
        # a text message: close 1003
        text = await open_ws(port)
        await text._send(text.ws.send(TextMessage("HELLO")))
        await _ended(text)
        assert text.close_code == 1003
        # a binary message longer than max_frame + 5: close 1009, before the HELLO is even looked at
        big = await open_ws(port)
        await big.send_all(b"\0" * (4096 + 6))
        await _ended(big)
        assert big.close_code == 1009
        # garbage instead of a WebSocket frame (an unmasked client frame, a bad opcode): close 1002
        junk = await open_ws(port)
        await junk.transport.send_all(b"\x83\x05hello")
        await _ended(junk)
        assert junk.close_code == 1002
        # a TTES protocol error inside good WebSocket messages: the TTES ERROR, then a normal close
        bad = await open_ws(port)
        await bad.send_all(b"\0\0\0\0")
        answer = Connection(CLIENT)
        answer.receive_data(await _ended(bad))
        error = answer.next_event()
        assert isinstance(error, Error) and error.code == ErrorCode.MALFORMED_FRAME, error
        assert bad.close_code == 1000
        # a plain HTTP request on the WebSocket port: 400, no upgrade
        plain = await trio.open_tcp_stream("127.0.0.1", port)
        await plain.send_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        with trio.fail_after(10):
            assert (await plain.receive_some(4096)).startswith(b"HTTP/1.1 400")
        # a page of another site: 403
        with pytest.raises(WebSocketError, match="403"):
            await open_ws(port, origin="http://evil.example")
        # the good client is still served
        await good.send(Subscribe((0,)))
        assert 0 in (await good.expect(JointUpdates)).indices.tolist()
        assert server.ws_addresses and not good.closed


def test_origin_policy_and_config() -> None:
    assert (
        origin_allowed(None)
        and origin_allowed("http://127.0.0.1:8080")
        and origin_allowed("http://localhost")
    )
    assert origin_allowed("http://[::1]:9") and not origin_allowed("http://evil.example")
    assert not origin_allowed("null") and not origin_allowed("file://")
    assert origin_allowed("https://ig.example", ("https://ig.example",))
    assert not origin_allowed("http://127.0.0.1:8080", ("https://ig.example",))
    assert origin_allowed("http://anything", ("*",))
    cfg = config_from_mapping({"ws_port": 7001, "ws_origins": ["https://ig.example"]})
    assert cfg.ws_port == 7001 and cfg.ws_origins == ("https://ig.example",)
    with pytest.raises(ConfigError, match="ws_port"):
        ServerConfig(ws_port=70000)
    with pytest.raises(ConfigError, match="ws_origins"):
        config_from_mapping({"ws_origins": [""]})


# -- the adapter's parser path, fuzzed ----------------------------------------------------------------------
def _client_frame(payload: bytes, opcode: int = 2, fin: bool = True) -> bytes:
    """A masked client → server WebSocket frame (RFC 6455 §5.2)."""
    head = bytes([(0x80 if fin else 0) | opcode])
    n = len(payload)
    if n < 126:
        head += bytes([0x80 | n])
    elif n < 65536:
        head += bytes([0x80 | 126]) + struct.pack(">H", n)
    else:
        head += bytes([0x80 | 127]) + struct.pack(">Q", n)
    mask = os.urandom(4)
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


UPGRADE = (
    b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
)


async def _serve_bytes(chunks: list[bytes], max_message: int = 1 << 16) -> tuple[bytes, WebSocketStream]:
    """Feed ``chunks`` to a server-side adapter over a memory stream; what it passed on, and the adapter."""
    ours, theirs = trio.testing.memory_stream_pair()
    ws = WebSocketStream(ours, max_message=max_message)
    got = bytearray()
    async with trio.open_nursery() as n:

        async def feed() -> None:
            for c in chunks:
                await theirs.send_all(c)
            await theirs.send_eof()

        async def drain() -> None:  # the server's answers (101, pongs, closes)
            while await theirs.receive_some(65536):
                pass

        n.start_soon(feed)
        n.start_soon(drain)
        while data := await ws.receive_some(7):
            got += data
        await ws.aclose()
        n.cancel_scope.cancel()
    return bytes(got), ws


def _split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    return [data[a:b] for a, b in zip([0, *points], [*points, len(data)], strict=True) if b > a]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(max_size=300), max_size=6), st.lists(st.integers(0, 10_000), max_size=12))
def test_fuzz_any_split_of_binary_messages_is_their_concatenation(
    payloads: list[bytes], cuts: list[int]
) -> None:
    wire = UPGRADE + b"".join(_client_frame(p) for p in payloads) + _client_frame(b"", 8)
    got, ws = trio.run(_serve_bytes, _split(wire, cuts))
    assert got == b"".join(payloads)
    assert ws.open and ws.close_code in (1000, 1005)


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=400), st.booleans())
def test_fuzz_garbage_after_or_instead_of_the_upgrade_ends_quietly(junk: bytes, upgraded: bool) -> None:
    got, ws = trio.run(_serve_bytes, [UPGRADE + junk if upgraded else junk], 64)
    assert ws.ended and len(got) <= len(junk)


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command")
async def test_wss_when_the_server_serves_tls(
    autojump_clock: trio.abc.Clock, cert: tuple[Path, Path]
) -> None:
    """With ``tls_cert`` the WebSocket port speaks TLS too (wss://): TLS, then the upgrade, then HELLO."""
    async with running_server(ws_port=0, tls_cert=str(cert[0]), tls_key=str(cert[1])) as server:
        port = ws_port_of(server)
        tls = trio.SSLStream(
            await trio.open_tcp_stream("127.0.0.1", port),
            ssl.create_default_context(cafile=str(cert[0])),
            server_hostname="127.0.0.1",
        )
        ws = WebSocketStream(tls, client=True)
        await ws.connect(f"127.0.0.1:{port}")
        c = Client(ws, Connection(CLIENT))  # type: ignore[arg-type]
        await c.send(Hello("wss", "observer"))
        assert (await c.expect(Accept)).role == "observer"
        await c.expect(Ready)
        await c.aclose()
