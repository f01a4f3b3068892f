"""Stamps that order what front-ends decide apart (issue 21): an index's generations (its creations and
removals, :func:`server.fabric.requests.sync`) and the settings' (:mod:`server.fabric.settings`).

A stamp counts past the newest the process holds, and is at least the wall clock's ms: a front-end that
restarted holds none of the stamps given before, and still stamps past them (on main a restarted front-end
counted an index's generations again from 1, and another front-end's sync, with the removal it had made
before its restart, removed the soldier it created there again). Clocks of other hosts that are behind by
more than the time between two changes of one thing still order those two wrongly.
"""

from __future__ import annotations

import time


def after(newest: int) -> int:
    """A stamp newer than ``newest`` (the newest held here) and than the wall clock's ms now."""
    return max(int(newest) + 1, time.time_ns() // 1_000_000)
