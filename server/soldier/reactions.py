"""Reactions (issue 16): a Fire PDU's recoil or a near detonation's flinch, played once in place.

A soldier resting in a posture with that reaction (``soldier_react.graph``) plays it at once. One changing
posture, turning or already reacting keeps the latest reaction asked for and plays it when that ends, if it
is then resting in a posture that has it and the reaction is not older than MAX_REACTION_DELAY: the first
shot of a standing soldier raises his rifle and recoils once it is up, and a burst recoils shot after shot.
A stepping soldier does not react (a reaction would cut his step).
"""

from __future__ import annotations

from server.soldier.core import _IDLE, _TRANSITION, ManagerCore
from server.soldier.library import PathStep

MAX_REACTION_DELAY = 1.5  # s: a reaction waiting for a posture change or turn longer than this is dropped


class Reactions(ManagerCore):
    """The reaction path: pick the posture's reaction clip, play it, or keep it for when the soldier rests."""

    def _react_now(self, i: int, kind: str, t: float) -> str | None:
        """Play reaction ``kind`` for a soldier at ``t`` (IDLE) or keep it (TRANSITION); the clip started."""
        tb, lib = self.table, self.library
        mode = int(tb.mode[i])
        if mode == _TRANSITION:
            self._pending[i] = (kind, t)
            return None
        if mode != _IDLE:
            return None
        node = int(tb.node[i])
        clip = lib.reaction.get((lib.posture_names[node], kind))
        if clip is None:
            return None
        step = PathStep(clip, True, float(lib.clip_duration[clip]), node, node)
        tb.blend_len[i] = 0.0
        tb.mode[i] = _TRANSITION
        self._paths[i] = [(step,), 0]
        self._play_step(i, step, t)
        tb.dirty[i] = True
        return lib.clip_names[clip]

    def _react_pending(self, i: int, t: float) -> None:
        """A soldier that just came to rest at ``t``: the reaction it kept, if still fresh."""
        kind, asked = self._pending.pop(i, ("", 0.0))
        if kind and t - asked <= MAX_REACTION_DELAY:
            self._react_now(i, kind, t)
