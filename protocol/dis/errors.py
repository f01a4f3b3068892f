"""The one exception the DIS decoders raise.

Every parser under :mod:`protocol.dis` turns bad bytes into a :class:`DisError` carrying *where* the problem
is, so a logfile reader can report the record and skip it instead of crashing.
"""

from __future__ import annotations


class DisError(ValueError):
    """Bad DIS bytes (or an unencodable value).

    ``offset`` is the byte offset of the offending field: inside the PDU for the codecs, inside the file for
    raw PDU streams, inside the UDP payload (or the log line's PDU bytes) for captures. ``record`` is the
    1-based packet number (pcap/pcapng, as Wireshark counts) or line number (``.dislog``) where known.
    """

    def __init__(self, message: str, offset: int = 0, record: int | None = None) -> None:
        self.message = message
        self.offset = int(offset)
        self.record = record
        where = f"offset {self.offset}" if record is None else f"record {record}, offset {self.offset}"
        super().__init__(f"{message} ({where})")

    def at(self, base: int = 0, record: int | None = None) -> DisError:
        """The same error moved by ``base`` bytes and attached to ``record`` (for readers wrapping codecs)."""
        return DisError(self.message, self.offset + base, self.record if record is None else record)
