"""The server-wide settings a front-end hands its shards (issue 21: JCL changed the front-end's world only).

A front-end animates nothing: its soldier settings (``set_ttes_heading_offset``, ``set_ttes_blend_time``,
``set_ttes_walk_run_threshold``, ``set_channelset_parameters``: an operator's JCL; ``--throttle`` and the
start-up script's throttle) and its report interval are the cluster's, and go to every shard when they
change and before each sync (a shard heard late, back, or standing in). The tick period stays each
process's own, and so does clip recording (a debugging aid: ``report_ttes_clips`` reads it where the
soldiers animate, a shard's own config).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from server.soldier.settings import SoldierSettings

if TYPE_CHECKING:
    from server.startup import ServerWorld

OWN = frozenset({"tick_period", "record_clips"})  # each process's own (its tick; what it records)
SHARED = tuple(f.name for f in dataclasses.fields(SoldierSettings) if f.name not in OWN)


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
