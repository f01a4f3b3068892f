"""DIS logfile replay and the DIS -> Jack/TTES translation shared with the live gateway (issue 9).

``translator`` (pure: PDUs in, soldiers and entity requests out), ``cursor`` (pacing, entity filter),
``replayer`` (a paced log through the translator), ``link`` (a trio-native server connection), ``sink``
(translations -> protocol messages), ``drive`` (the async replay loop), ``stubapp`` (the stub window and
headless renderer driven by DIS).
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
