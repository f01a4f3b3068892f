"""Turns in place (issue 16): a standing figure that faces away from its heading turns on the spot."""

from __future__ import annotations

import math

from server.soldier.core import (
    _IDLE,
    _TRANSITION,
    ManagerCore,
)
from server.soldier.library import PathStep


class Turning(ManagerCore):
    """The turn-in-place path: pick the turn clip that fits, then fold its own move into the root offset."""

    def _turning(self, clip: int) -> bool:
        return self.library.clip_end_offset[clip, 2] != 0.0 and self.library.clip_graph[clip] != 0

    def _turn(self, i: int, t: float) -> bool:
        """A standing soldier whose figure faces away from its heading plays the turn in place that fits."""
        tb, lib = self.table, self.library
        if not lib.turn_clips or int(tb.node[i]) != self._home or int(tb.mode[i]) != _IDLE:
            return False
        want = -float(tb.root_yaw[i])  # compass degrees to turn
        clip, turn = min(  # the nearest turn; of two as near (180 both ways) the one turning the asked way
            lib.turn_clips, key=lambda c: (abs((c[1] - want + 180.0) % 360.0 - 180.0), c[1] * want < 0)
        )
        if abs((turn - want + 180.0) % 360.0 - 180.0) >= abs(want):
            return False
        step = PathStep(clip, True, float(lib.clip_duration[clip]), self._home, self._home)
        tb.blend_len[i] = 0.0
        tb.mode[i] = _TRANSITION
        self._paths[i] = [(step,), 0]
        self._play_step(i, step, t)
        tb.dirty[i] = True
        return True

    def _turn_end(self, i: int, t: float) -> None:
        """The turn's own move (``end_offset``) joins the root offset; the figure rests in its new heading."""
        tb, lib = self.table, self.library
        x, z, yaw = lib.clip_end_offset[int(tb.clip[i])]
        a = -math.radians(float(tb.root_yaw[i]))  # as blend.yaw_rotate turns the clip's placements
        self._rest(i, self._home, t)
        tb.root_off[i, 0] += math.cos(a) * x + math.sin(a) * z
        tb.root_off[i, 1] += math.cos(a) * z - math.sin(a) * x
        tb.root_yaw[i] = (float(tb.root_yaw[i]) - yaw + 180.0) % 360.0 - 180.0
