"""DIS logfile replay and the DIS -> Jack/TTES translation shared with the live gateway (issue 9).

``translator`` (pure: PDUs in, soldiers and entity requests out), ``cursor`` (pacing, entity filter),
``replayer`` (a paced log through the translator), ``sink`` (translations -> protocol messages on any
:class:`~client_stub.link.api.Link`), ``drive`` (the async replay loop), ``soldiers`` (the stub's soldiers
driven by DIS), ``gateway`` (live DIS over UDP).
"""

from client_stub.dis.cursor import EntityFilter, FilterError, LogCursor
from client_stub.dis.replayer import Replayer
from client_stub.dis.translator import SOLDIER_DTYPE, DisTranslator, RemoveReason, Translation

__all__ = [
    "SOLDIER_DTYPE",
    "DisTranslator",
    "EntityFilter",
    "FilterError",
    "LogCursor",
    "RemoveReason",
    "Replayer",
    "Translation",
]
