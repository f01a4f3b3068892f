"""The server-wide settings a front-end hands its shards (issue 21: JCL changed the front-end's world only).

A front-end animates nothing: its soldier settings (``set_ttes_heading_offset``, ``set_ttes_blend_time``,
``set_ttes_walk_run_threshold``, ``set_channelset_parameters``: an operator's JCL; ``--throttle`` and the
start-up script's throttle) and its report interval are the cluster's, and go to every shard when they
change and before each sync (a shard heard late, back, or standing in). The tick period stays each
process's own, and so does clip recording (a debugging aid: ``report_ttes_clips`` reads it where the
soldiers animate, a shard's own config).

Settings travel with a *stamp* (:data:`Stamp`), and a node takes only settings at least as new as those it
holds: a front-end's start-up settings are :data:`START`, below every change made since (an operator's
through any front-end: :func:`stamp`), so a front-end that starts later no longer undoes such a change with
its first syncs; it learns the change from the shards' answers to its ``books`` (a shard's own start-up
settings are :data:`OWN`, below every front-end's) and from the other front-ends.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from server.fabric.stamps import after
from server.soldier.settings import SoldierSettings

if TYPE_CHECKING:
    from server.startup import ServerWorld

OWN = frozenset({"tick_period", "record_clips"})  # each process's own (its tick; what it records)
SHARED = tuple(f.name for f in dataclasses.fields(SoldierSettings) if f.name not in OWN)

Stamp = tuple[int, int]  # (:func:`server.fabric.stamps.after`; the front-end that made it)
OWN_STAMP: Stamp = (-1, -1)  # a shard's own start-up settings: any front-end's replace them
START: Stamp = (0, -1)  # a front-end's start-up settings: below any change made since


def stamp(newest: Stamp, front: int) -> Stamp:
    """The stamp of a change made now through front-end ``front``: newer than ``newest`` (the newest it
    holds), and by the wall clock than changes made elsewhere before (a restarted front-end that has heard
    of none yet)."""
    return (after(newest[0]), front)


def stamp_of(msg: dict[str, Any]) -> Stamp:
    """The stamp a ``settings`` operation or a books answer carries (:data:`START` without one)."""
    told = msg.get("stamp")
    if isinstance(told, (list, tuple)) and len(told) == 2 and all(isinstance(t, int) for t in told):
        return (int(told[0]), int(told[1]))
    return START


def of(world: ServerWorld) -> dict[str, Any]:
    """The settings of ``world`` a shard takes (plain values: they travel as msgpack)."""
    s = world.settings
    values: dict[str, Any] = {name: getattr(s, name) for name in SHARED}
    values["heading_offsets"] = list(s.heading_offsets)
    values["report_interval"] = world.report_interval
    return values


def apply(world: ServerWorld, values: dict[str, Any]) -> None:
    """Take a front-end's settings (ValueError for a bad one: nothing changes)."""
    changes = {name: values[name] for name in SHARED if name in values}
    if "heading_offsets" in changes:
        changes["heading_offsets"] = tuple(changes["heading_offsets"])
    world.settings.replace(**changes)  # (validated whole before the report interval changes)
    if "report_interval" in values:
        world.set_report_interval(float(values["report_interval"]))
    world.soldiers.configure(**changes)
