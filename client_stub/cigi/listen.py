"""The host's ear: Start of Frame datagrams from the IG, counted (the host still runs free, not in lock-step).

A CIGI 3.3 IG answers every frame with a message that opens with Start of Frame (``protocol.cigi``): its own
frame number and the last Host Frame Number it read from our IG Control. Counting them tells the operator the
IG is alive and how far behind it reads; a datagram that is not a Start of Frame is counted, never fatal.
"""

from __future__ import annotations

from dataclasses import dataclass

import trio

from protocol import cigi

MAX_DATAGRAM = 65535


@dataclass
class SofCounter:
    """What the IG has told us so far: sans I/O, :meth:`feed` takes one datagram."""

    received: int = 0
    malformed: int = 0
    ig_frame: int | None = None  # the newest Start of Frame's IG Frame Number
    last_host_frame: int | None = None  # ... and its Last Host Frame Number
    ig_status: int | None = None

    def feed(self, datagram: bytes) -> cigi.StartOfFrame | None:
        try:
            sof = cigi.decode_start_of_frame(datagram)
        except cigi.CigiError:
            self.malformed += 1
            return None
        self.received += 1
        self.ig_frame, self.last_host_frame, self.ig_status = sof.ig_frame, sof.last_host_frame, sof.ig_status
        return sof

    def stats(self) -> dict[str, int | None]:
        return {
            "sof_received": self.received,
            "sof_malformed": self.malformed,
            "ig_frame": self.ig_frame,
            "ig_last_host_frame": self.last_host_frame,
            "ig_status": self.ig_status,
        }


async def receive(sock: trio.socket.SocketType, counter: SofCounter) -> None:
    """Feed ``counter`` every datagram ``sock`` receives, until cancelled."""
    while True:
        datagram = await sock.recv(MAX_DATAGRAM)
        counter.feed(datagram)
