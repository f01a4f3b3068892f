"""Reactions (issue 16): a Fire PDU's recoil or a near detonation's flinch, played once in place."""

from __future__ import annotations

import numpy as np

from server.soldier.core import (
    _IDLE,
    _TRANSITION,
)
from server.soldier.events import Events
from server.soldier.library import PathStep


class Reactions(Events):
    """The reaction path: a resting soldier plays its posture's reaction clip and rests there again."""

    def react(self, index: int, kind: str, now: float) -> str | None:
        """A Fire PDU's ``"recoil"`` or a near detonation's ``"flinch"``: a soldier resting in a posture
        with that reaction plays it once (soldier_react.graph) and rests there again. A soldier stepping or
        changing posture, or with no such clip for its posture, does not react (None); else the clip."""
        tb, lib = self.table, self.library
        if not tb.is_live(index):
            raise KeyError(f"no soldier {index}")
        if not self._settings.every_frame:
            tb.clock[index] = now
        self._advance(np.array([index], np.int64))
        if int(tb.mode[index]) != _IDLE:
            return None
        clip = lib.reaction.get((lib.posture_names[int(tb.node[index])], kind))
        if clip is None:
            return None
        node = int(tb.node[index])
        step = PathStep(clip, True, float(lib.clip_duration[clip]), node, node)
        tb.blend_len[index] = 0.0
        tb.mode[index] = _TRANSITION
        self._paths[index] = [(step,), 0]
        self._play_step(index, step, float(tb.clock[index]))
        tb.dirty[index] = True
        return lib.clip_names[clip]
