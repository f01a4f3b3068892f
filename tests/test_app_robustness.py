"""Clients behaving badly never hurt the others: a stalled reader, malicious bytes, 100 clients vanishing.

Real TCP over 127.0.0.1 with trio's autojump clock; a healthy "witness" client checks that it keeps getting
every tick's updates while the others misbehave."""

from __future__ import annotations

import socket
import struct

import numpy as np
import pytest
import trio
from test_server_support import Client, running_server

from protocol.entity import COUNT, WIRE_ENTITY_DTYPE
from protocol.errors import ErrorCode
from protocol.events import Error, Hello, Jcl, JointUpdates, Ping, Pong, Ready, Subscribe
from protocol.framing import encode_frame
from protocol.messages import CODECS, MessageType


def port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.addresses[0][1]


async def walking_crowd(c: Client, n: int) -> list[int]:
    """Create ``n`` soldiers (beyond the start-up's 10) and make all of them walk; returns all indices."""
    from protocol.events import CreateSoldier, SoldierCreated

    for k in range(n):
        await c.send(CreateSoldier(1000 + k, "DI.fig", "AK_47.fig", None))
    for _ in range(n):
        await c.expect(SoldierCreated)
    every = list(range(10 + n))
    speeds = np.linspace(0.8, 5.0, len(every))  # walkers and runners
    await c.requests(index=every, velocity=np.stack([np.zeros_like(speeds), speeds, 0 * speeds], 1))
    return every


async def witness_ticks(c: Client, seconds: float) -> list[int]:
    """The server ticks of the joint-update batches the witness received during ``seconds`` (an out-of-cycle
    answer to new requests carries the tick before it: a repeated tick number is listed once)."""
    ticks: list[int] = []
    with trio.move_on_after(seconds):
        while True:
            ev = await c.next_event()
            if isinstance(ev, JointUpdates) and (not ticks or ev.tick != ticks[-1]):
                ticks.append(ev.tick)
    return ticks


def raw_requests(rows: list[tuple[int, int, int, tuple, float, tuple, int]]) -> bytes:
    wire = np.zeros(len(rows), WIRE_ENTITY_DTYPE)
    for k, (i, a, w, v, h, p, imm) in enumerate(rows):
        wire[k] = (i, a, w, v, h, p, imm)
    return encode_frame(MessageType.ENTITY_REQUESTS, COUNT.pack(len(rows)) + wire.tobytes())


async def stalled_stream(port: int) -> trio.SocketStream:
    """A client socket with a tiny receive buffer: the server's writes block soon when it never reads."""
    sock = trio.socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    await sock.connect(("127.0.0.1", port))
    return trio.SocketStream(sock)


async def test_a_stalled_reader_neither_delays_nor_grows_the_server(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.0, write_timeout=8.0, report_interval=0.5) as server:
        witness = await Client.open(port_of(server), "witness")
        await witness.expect(Ready)
        every = await walking_crowd(witness, 90)
        await witness.send(Subscribe(tuple(every)))
        # the staller: handshakes, subscribes to everything, asks for STATUS every 0.5 s, never reads again
        from protocol.connection import CLIENT, Connection

        stream = await stalled_stream(port_of(server))
        conn = Connection(CLIENT)
        await stream.send_all(
            conn.send(Hello("staller"))
            + encode_frame(MessageType.SUBSCRIBE, CODECS[MessageType.SUBSCRIBE][1](Subscribe(tuple(every))))
        )
        await trio.sleep(0.1)
        staller = next(s for s in server.sessions.values() if s.name == "staller")
        t0, ticks0 = trio.current_time(), server.ticks
        peak_control = 0
        peak_bytes = 0

        async def watch() -> None:
            nonlocal peak_control, peak_bytes
            while staller.id in server.sessions:
                peak_control = max(peak_control, len(staller.control))
                peak_bytes = max(peak_bytes, staller.bytes_out)
                await trio.sleep(0.05)

        async with trio.open_nursery() as n:
            n.start_soon(watch)
            got = await witness_ticks(witness, 6.0)
            elapsed = trio.current_time() - t0
            # the witness got a batch on every tick: no gaps, no delay
            assert len(got) >= int(elapsed * 30) - 2
            assert np.all(np.diff(got) == 1), np.diff(got)
            assert server.ticks - ticks0 >= int(elapsed * 30) - 1
            # the staller's writer is blocked: its output stopped growing and its queue is bounded
            stuck_at = staller.bytes_out
            await witness_ticks(witness, 1.0)
            assert staller.bytes_out == stuck_at
            assert peak_control <= server.config.control_queue
            # ... and after write_timeout it is dropped, the witness unaffected
            got = await witness_ticks(witness, 4.0)
            assert np.all(np.diff(got) == 1)
            assert staller.id not in server.sessions
            assert staller.dropped and "write stalled" in staller.drop_reason
            n.cancel_scope.cancel()
        await stream.aclose()
        assert server.clients_dropped == 1


async def _fatal(port: int, data: bytes, handshake: bool = True) -> list[int]:
    """Send ``data`` (after a handshake) and return the error codes received before the server closed."""
    c = await Client.open(port, "evil", hello=handshake)
    await c.send_raw(data)
    await c.until_closed()
    return [e.code for e in c.events if isinstance(e, Error)]


NAN = float("nan")


@pytest.mark.parametrize(
    ("what", "data", "handshake", "code"),
    [
        ("garbage", bytes(range(7, 250, 3)) * 40, False, None),
        (
            "garbage after the handshake",
            b"\x00\x00\x00\x05\x77hello" * 10,
            True,
            ErrorCode.UNKNOWN_MESSAGE_TYPE,
        ),
        ("huge length", b"\xff\xff\xff\xf0\x30" + b"\x00" * 64, True, ErrorCode.FRAME_TOO_LARGE),
        ("zero length", b"\x00\x00\x00\x00", True, ErrorCode.MALFORMED_FRAME),
        (
            "index out of range",
            raw_requests([(65535, 2, 1, (0, 1, 0), 0.0, (0, 0, 0), 0)]),
            True,
            ErrorCode.BAD_VALUE,
        ),
        (
            "NaN velocity",
            raw_requests([(0, 2, 1, (NAN, 1, 0), 0.0, (0, 0, 0), 0)]),
            True,
            ErrorCode.BAD_VALUE,
        ),
        (
            "inf heading",
            raw_requests([(1, 2, 1, (0, 1, 0), float("inf"), (0, 0, 0), 0)]),
            True,
            ErrorCode.BAD_VALUE,
        ),
        (
            "bad appearance",
            raw_requests([(1, 9, 1, (0, 1, 0), 0.0, (0, 0, 0), 0)]),
            True,
            ErrorCode.BAD_VALUE,
        ),
        (
            "speed of sound",
            raw_requests([(2, 2, 1, (0, 340, 0), 0.0, (0, 0, 0), 0)]),
            True,
            ErrorCode.BAD_VALUE,
        ),
        (
            "rows cut short",
            encode_frame(MessageType.ENTITY_REQUESTS, COUNT.pack(3) + b"\x00" * 40),
            True,
            ErrorCode.MALFORMED_FRAME,
        ),
        (
            "subscribe out of range",
            encode_frame(MessageType.SUBSCRIBE, CODECS[MessageType.SUBSCRIBE][1](Subscribe((0, 70000)))),
            True,
            ErrorCode.BAD_VALUE,
        ),
        ("not msgpack", encode_frame(MessageType.JCL, b"\xc1\xc1\xc1"), True, ErrorCode.SCHEMA),
        ("a server message", encode_frame(MessageType.READY, b"\x80"), True, ErrorCode.UNEXPECTED_MESSAGE),
        (
            "JCL before HELLO",
            encode_frame(MessageType.JCL, CODECS[MessageType.JCL][1](Jcl("x();", 1))),
            False,
            ErrorCode.UNEXPECTED_MESSAGE,
        ),
        ("bad magic", encode_frame(MessageType.HELLO, b"HTTP\x00\x01\x80"), False, ErrorCode.BAD_MAGIC),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
async def test_malicious_clients_get_an_error_and_are_dropped(
    autojump_clock: trio.abc.Clock, what: str, data: bytes, handshake: bool, code: ErrorCode | None
) -> None:
    async with running_server(throttle=0.0) as server:
        witness = await Client.open(port_of(server), "witness")
        await witness.expect(Ready)
        await witness.requests(index=[0, 1, 2], velocity=(0.0, 1.5, 0.0))
        await witness.send(Subscribe((0, 1, 2)))
        await witness.expect(JointUpdates)
        codes = await _fatal(port_of(server), data, handshake)
        assert len(codes) == 1, what
        assert codes[0] < 100
        if code is not None:
            assert codes[0] == code, what
        await trio.sleep(0.1)
        assert [s.name for s in server.sessions.values()] == ["witness"]
        assert server.clients_dropped == 1
        # the witness never noticed
        got = await witness_ticks(witness, 1.0)
        assert len(got) >= 29 and np.all(np.diff(got) == 1)
        await witness.send(Ping(5))
        assert (await witness.expect(Pong)).nonce == 5


async def test_silent_and_truncating_clients_are_closed(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(handshake_timeout=3.0) as server:
        silent = await Client.open(port_of(server), hello=False)
        t0 = trio.current_time()
        await silent.until_closed()
        assert trio.current_time() - t0 == pytest.approx(3.0, abs=0.1)
        cut = await Client.open(port_of(server))
        await cut.send_raw(struct.pack(">IB", 100, 0x10) + b"\x81")  # a JCL frame cut short, then EOF
        await cut.stream.send_eof()
        await cut.until_closed()
        await trio.sleep(0.1)
        assert server.sessions == {}


async def test_hundred_clients_dropping_abruptly_under_load(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.0) as server:
        witness = await Client.open(port_of(server), "witness")
        await witness.expect(Ready)
        every = await walking_crowd(witness, 20)
        await witness.send(Subscribe(tuple(every)))
        crowd: list[Client] = []
        for k in range(100):
            c = await Client.open(port_of(server), f"ig-{k}", role="observer" if k % 2 else "controller")
            await c.send(Subscribe(tuple(every[k % 7 :: 3])))
            crowd.append(c)
        assert len(server.sessions) == 101

        async def busy(c: Client, k: int) -> None:
            with trio.move_on_after(0.4 + 0.01 * k):
                while True:
                    await c.next_event()
                    if k % 2 == 0 and trio.current_time() % 0.1 < 0.034:
                        await c.requests(index=every[k % 10], velocity=(0.0, 1.0 + (k % 5), 0.0))

        async with trio.open_nursery() as n:
            for k, c in enumerate(crowd):
                n.start_soon(busy, c, k)
        # everyone vanishes without GOODBYE: a third reset the connection (SO_LINGER 0), the rest just close
        for k, c in enumerate(crowd):
            if k % 3 == 0:
                c.stream.socket.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            await c.aclose()
        got = await witness_ticks(witness, 3.0)
        assert len(got) >= 85 and np.all(np.diff(got) == 1)
        assert [s.name for s in server.sessions.values()] == ["witness"]
        # soldiers the vanished clients created stay (other image generators may watch them)
        m = server.world.manager
        assert m is not None and m.count == len(every)
        await witness.send(Ping(9))
        assert (await witness.expect(Pong)).nonce == 9
