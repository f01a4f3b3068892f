"""The live DIS gateway: Entity State (and Update) / Remove Entity / Fire / Detonation PDUs from UDP into the
Jack/TTES server.

What the 1994 TTES did on the exercise network: listen to DIS, keep one soldier per lifeform entity, and
send Jack the posture and command tokens (seed 002, section 2). The translation is the replay's
(:class:`~client_stub.dis.translator.DisTranslator`, :class:`~client_stub.dis.sink.ServerSink`); only
the source differs. Datagrams are read in bursts: after each wake-up every datagram already queued in the
socket is taken without waiting (up to ``max_burst``) and the burst is decoded at once by the DIS library's
vectorised decoder, so a flood costs one decode per burst, not one per datagram. Entity State Update PDUs are
put on the entity's last Entity State PDU, heard in this burst or an earlier one (``bases``). Nothing a
sender puts in a datagram stops the gateway: malformed, truncated, foreign and unknown PDUs are counted in
:attr:`status`
(the decoder's own counters, added up burst after burst, and the gateway's).

The socket is bound to one interface, loopback by default (only this machine's senders are heard): ``0.0.0.0``
hears a LAN exercise's broadcasts on every interface; with ``group`` it joins that multicast group on
``interface``.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import socket
from collections import Counter
from dataclasses import dataclass, field

import trio

from client_stub.dis.cursor import EntityFilter
from client_stub.dis.sink import ServerSink
from client_stub.dis.translator import DIS_TIMEOUT, DisTranslator, Translation
from protocol.dis import DEFAULT_PORT, DisError, DisLog, LocalFrame, UpdateBases, read_datagrams

log = logging.getLogger("ttes.gateway")
MAX_DATAGRAM = 65535
HOUSEKEEPING = 0.1  # s between timeout / Fire-reaction checks when no datagram arrives
OWN_COUNTERS = ("bytes", "bursts", "max_burst", "filtered", "decode_failures", "receive_errors")


@dataclass
class GatewayConfig:
    port: int = DEFAULT_PORT
    interface: str = "127.0.0.1"
    group: str | None = None  # multicast group to join
    timeout: float = DIS_TIMEOUT
    origin: LocalFrame | None = None  # default: the first entity heard
    entity_filter: EntityFilter | None = None
    exercise: int | None = None  # only this DIS exercise's PDUs (the others are counted: other_exercise)
    max_burst: int = 4096  # datagrams decoded together at most
    receive_buffer: int = 4 << 20  # SO_RCVBUF asked for (the kernel may give less)


def open_dis_socket(cfg: GatewayConfig) -> socket.socket:
    """A non-blocking UDP socket for DIS (broadcasts allowed, address reusable, multicast joined if asked)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        with contextlib.suppress(OSError):  # else keep the default buffer
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, cfg.receive_buffer)
        if cfg.group:
            s.bind((cfg.group, cfg.port))
            mreq = socket.inet_aton(cfg.group) + socket.inet_aton(cfg.interface)
            s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
        else:
            s.bind((cfg.interface, cfg.port))
        s.setblocking(False)
    except BaseException:
        s.close()
        raise
    return s


@dataclass
class DisGateway:
    """Datagrams -> translator -> sink (see the module docstring)."""

    config: GatewayConfig = field(default_factory=GatewayConfig)
    translator: DisTranslator = field(init=False)
    status: Counter[str] = field(init=False)
    bases: UpdateBases = field(default_factory=UpdateBases)  # each entity's last Entity State PDU
    address: tuple[str, int] | None = None

    def __post_init__(self) -> None:
        self.translator = DisTranslator(self.config.origin, timeout=self.config.timeout)
        # the decoder's counters (datagrams, PDUs by type, problems) as it names them, then the gateway's own
        self.status = Counter(read_datagrams([], 0.0).counters)
        self.status.update(dict.fromkeys(OWN_COUNTERS, 0))

    # -- pure: a burst of datagrams ---------------------------------------------------------------
    def decode(self, datagrams: list[bytes], now: float) -> DisLog | None:
        """Decode a burst (each datagram one or more PDUs); counts everything; None if nothing decodable."""
        n = len(datagrams)
        if n == 0:
            return None
        st = self.status
        st["bursts"] += 1
        st["max_burst"] = max(st["max_burst"], n)
        st["bytes"] += sum(len(d) for d in datagrams)
        try:
            got = read_datagrams(datagrams, now, exercise=self.config.exercise, bases=self.bases)
        except (DisError, ValueError, IndexError) as exc:  # never expected: the decoder reports issues itself
            st.update(datagrams=n, decode_failures=1)
            log.warning("burst of %d datagrams not decoded: %s", n, exc)
            return None
        st.update(got.counters)
        for issue in got.issues[:3]:
            log.debug("datagram %s: %s", issue.record, issue)
        return got

    def handle(self, datagrams: list[bytes], now: float) -> Translation:
        """A burst of datagrams received at ``now`` -> what the server must hear."""
        got = self.decode(datagrams, now)
        if got is None:
            return self.translator.advance(now)
        batch, times = got.batch, got.times
        f = self.config.entity_filter
        if f is not None and len(batch):
            keep = f.mask(batch.records)
            self.status["filtered"] += int((~keep).sum())
            batch, times = batch.select(keep), times[keep]
        return self.translator.step(now, batch, times, got.events)

    def snapshot(self) -> dict[str, int]:
        return {**self.status, "alive": self.translator.alive, "entities": self.translator.count,
                **{f"translator_{k}": v for k, v in self.translator.stats.items()}}  # fmt: skip

    # -- the trio loop ----------------------------------------------------------------------------
    async def serve(
        self, sink: ServerSink, *, task_status: trio.TaskStatus[int] = trio.TASK_STATUS_IGNORED
    ) -> None:
        """Listen until cancelled; ``task_status.started(port)`` once bound. Afterwards apply :meth:`stop`'s
        translation (while the link is still open) to take the gateway's soldiers off the server."""
        sock = open_dis_socket(self.config)
        self.address = sock.getsockname()[:2]
        try:
            async with trio.open_nursery() as nursery:
                nursery.start_soon(self._housekeeping, sink)
                task_status.started(self.address[1])
                while True:
                    await trio.lowlevel.wait_readable(sock)
                    burst = self._drain(sock)
                    if burst:
                        sink.apply(self.handle(burst, trio.current_time()))
        finally:
            sock.close()

    def stop(self) -> Translation:
        """Remove every soldier (the end of a gateway session)."""
        return self.translator.reset()

    def _drain(self, sock: socket.socket) -> list[bytes]:
        burst: list[bytes] = []
        while len(burst) < self.config.max_burst:
            try:
                data = sock.recv(MAX_DATAGRAM)
            except BlockingIOError:
                break
            except OSError as exc:  # e.g. ICMP errors surfacing on a UDP socket: keep listening
                if exc.errno not in (errno.ECONNREFUSED, errno.EHOSTUNREACH, errno.ENETUNREACH):
                    log.warning("receive error: %s", exc)
                self.status["receive_errors"] += 1
                break
            burst.append(data)
        return burst

    async def _housekeeping(self, sink: ServerSink) -> None:
        while True:
            await trio.sleep(HOUSEKEEPING)
            sink.apply(self.translator.advance(trio.current_time()))
