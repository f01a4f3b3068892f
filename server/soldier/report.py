"""Reports on a soldier manager: one soldier's state and the periodic status (counts, tick statistics).

Read-only views for ``report_ttes_status``, the STATUS loop and tests; nothing here changes a soldier.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from server.soldier.state import LocoState, Mode

if TYPE_CHECKING:
    from server.soldier.manager import SoldierManager

_IDLE, _LOCO, _CRAWL = int(Mode.IDLE), int(Mode.LOCO), int(Mode.CRAWL)


def soldier_info(m: SoldierManager, index: int) -> dict[str, Any]:
    """One soldier's state, for status reports and tests."""
    tb = m.table
    if not tb.is_live(index):
        raise KeyError(f"no soldier {index}")
    i = int(index)
    mode = Mode(int(tb.mode[i]))
    return {
        "index": i,
        "name": m.names.get(i, ""),
        "mode": mode.name,
        "state": LocoState(int(tb.loco[i])).name,
        "posture": m.library.posture_names[int(tb.node[i])],
        "node": m.library.postures[int(tb.node[i])],
        "clip": m.library.clip_names[int(tb.clip[i])],
        "forward": bool(tb.direc[i] > 0),
        "clip_start": float(tb.start[i]),
        "clip_duration": float(tb.dur[i]),
        "goal": m.library.posture_names[d] if (d := m.goal_node(i)) >= 0 else None,
        "path": [m.library.posture_names[s.end] for s in m.path_steps(i)],
        "speed": float(tb.speed[i]),
        "backward": bool(tb.backward[i]),
        "heading": float(tb.heading[i]),
        "foot": "left" if tb.foot[i] == 0 else "right",
        "blending": bool(tb.blend_len[i] > 0),
    }


def _posture_counts(m: SoldierManager, per_node: np.ndarray) -> dict[str, int]:
    """Resting soldiers per posture name (the variants of a posture counted together)."""
    out: dict[str, int] = {}
    for k, v in enumerate(per_node.tolist()):
        if v:
            name = m.library.posture_names[k]
            out[name] = out.get(name, 0) + int(v)
    return out


def status(m: SoldierManager) -> dict[str, Any]:
    """Counts per mode, gait state and resting posture, tick statistics: the periodic status report."""
    tb = m.table
    live = tb.live
    mode = tb.mode[live]
    modes = {k.name.lower(): int((mode == k).sum()) for k in Mode}
    stepping = live[(mode == _LOCO) | (mode == _CRAWL)]
    states = np.bincount(tb.loco[stepping].astype(np.int64), minlength=len(LocoState))
    resting = live[mode == _IDLE]
    nodes = np.bincount(tb.node[resting].astype(np.int64), minlength=len(m.library.postures))
    ticks = max(m.ticks, 1)
    return {
        "soldiers": int(tb.count),
        "capacity": int(tb.capacity),
        "modes": modes,
        "gaits": {LocoState(k).name.lower(): int(v) for k, v in enumerate(states) if v},
        "postures": _posture_counts(m, nodes),
        "transitions": int((mode == Mode.TRANSITION).sum()),
        "ticks": m.ticks,
        "mean_tick_us": 1e6 * m.stats["tick_seconds"] / ticks,
        "last_tick_us": 1e6 * m.stats["last_tick_seconds"],
        "updates": m.stats["updates"],
        "requests": m.stats["requests"],
        "requests_unknown": m.stats["requests_unknown"],
        "requests_bad": m.stats["requests_bad"],
        "events": m.stats["events"],
        "clip_ends": m.stats["clip_ends"],
        "unreachable": m.stats["unreachable"],
        "answers": m.stats["answers"],  # updates sent between ticks (SoldierManager.answer)
        "throttle": m.settings.throttle,
        "every_frame": m.settings.every_frame,
        "heading_offsets": list(m.settings.heading_offsets),
        "walk_run_threshold": m.settings.walk_run_threshold,
        "blend_time": m.settings.blend_time,
    }
