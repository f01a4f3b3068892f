"""The Trio server's core: soldier states in a struct-of-arrays table, run as Figures 5 and 12 of seed 002.

* :mod:`~server.soldier.state` — modes, Figure-5 states, the request → posture mapping;
* :mod:`~server.soldier.table` — :class:`SoldierTable` (columns, capacity growth, free-list reuse);
* :mod:`~server.soldier.library` — :class:`MotionLibrary`: the three graphs bound into ClipLibraries;
* :mod:`~server.soldier.locomotion` — Figure 5 as a table, vectorised;
* :mod:`~server.soldier.blend` — cross-fades and heading offsets;
* :mod:`~server.soldier.settings` — :class:`SoldierSettings`: the manager's one frozen, validated settings;
* :mod:`~server.soldier.manager` — :class:`SoldierManager` (Figure 12), assembled from its parts
  (``core``, ``stepping``, ``turning``, ``events``, ``ticking``, ``requests``, ``reactions``);
* :mod:`~server.soldier.wire` — TickUpdate → protocol ``JointUpdates`` and the update table;
* :mod:`~server.soldier.synthetic` — a small library with the real names, for tests and benches.
"""

from __future__ import annotations

from server.soldier.library import MotionLibrary
from server.soldier.manager import (
    REQUEST_BAD_VALUE,
    REQUEST_OK,
    REQUEST_UNKNOWN_SOLDIER,
    ClipStart,
    SoldierManager,
    TickUpdate,
)
from server.soldier.settings import SoldierSettings
from server.soldier.state import LocoState, Mode
from server.soldier.table import SoldierTable

__all__ = [
    "REQUEST_BAD_VALUE",
    "REQUEST_OK",
    "REQUEST_UNKNOWN_SOLDIER",
    "ClipStart",
    "LocoState",
    "Mode",
    "MotionLibrary",
    "SoldierManager",
    "SoldierSettings",
    "SoldierTable",
    "TickUpdate",
]
