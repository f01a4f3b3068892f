"""The update path: the vectorised tick, the between-tick answer, snapshots and the poses they send."""

from __future__ import annotations

import time

import numpy as np

from protocol.bitpack import set_rows
from server.soldier import root_motion
from server.soldier.blend import blend_into, smoothstep, yaw_rotate
from server.soldier.core import (
    _CRAWL,
    _EPS_T,
    _IDLE,
    _LOCO,
    TickUpdate,
)
from server.soldier.events import Events


class Ticking(Events):
    """Ticks out: every soldier advanced to ``now``, the due ones sampled in one call per figure set."""

    def tick(self, now: float) -> TickUpdate:
        """Advance every soldier to ``now`` and return the poses of those due for an update.

        A soldier is due when its last update by a tick is at least ``settings.min_interval`` old (the
        throttle as a rate cap on the tick grid; an :meth:`answer` between ticks does not move the soldier
        off that grid) and its pose may have changed (playing a clip, cross-fading, a new resting
        pose, or a pending heading-only change).
        """
        self.tick_advance_rows(self.tick_start(now))
        return self.tick_emit(now)

    def tick_start(self, now: float) -> np.ndarray:
        """A tick's first step: every live soldier's clock set to ``now``; returns those whose clip ends by
        then, to be advanced (:meth:`tick_advance_rows`, in pieces if the caller likes: a shard lets its
        requests in between, and a request brings its soldier up to date itself) before :meth:`tick_emit`
        samples them."""
        t0 = time.perf_counter()
        self.ticks += 1
        tb = self.table
        live = tb.live
        if len(live):
            if self._settings.every_frame:
                nfr = self.library.clip_nframes[tb.clip[live]]
                tb.clock[live] += tb.dur[live] / np.maximum(nfr - 1, 1)
            else:
                tb.clock[live] = now
        ending = live[(tb.mode[live] != _IDLE) & (tb.clock[live] >= tb.end[live])]  # _advance's first test
        dt = time.perf_counter() - t0
        self.stats["tick_seconds"] += dt
        self.stats["last_tick_seconds"] = dt
        return ending

    def tick_advance_rows(self, rows: np.ndarray) -> None:
        """Handle the clip ends up to their clocks of those of ``rows`` still live (:meth:`tick_start`)."""
        t0 = time.perf_counter()
        self._advance(rows[self.table.live_mask(rows)])
        dt = time.perf_counter() - t0
        self.stats["tick_seconds"] += dt
        self.stats["last_tick_seconds"] += dt

    def tick_emit(self, now: float) -> TickUpdate:
        """A tick's second half: the poses of the soldiers due at ``now``."""
        t0 = time.perf_counter()
        tb = self.table
        live = tb.live
        if len(live):
            active = (
                (tb.mode[live] != _IDLE)
                | tb.dirty[live]
                | tb.heading_pending[live]
                | (tb.blend_len[live] > 0)
            )
            due = live[active & self._due(tb.tick_sent[live], now)]
        else:
            due = live
        out = self._emit(due, now)
        tb.tick_sent[due] = now
        dt = time.perf_counter() - t0
        self.stats["tick_seconds"] += dt
        self.stats["last_tick_seconds"] += dt
        return out

    def answer(self, now: float, at: float | None = None) -> TickUpdate:
        """An out-of-cycle update, between ticks, for just the soldiers whose requests changed what they show.

        Requests are applied when they arrive (:meth:`apply_requests`: a new clip, rate or heading), so the
        pose the next tick would send is known now: this releases that update early. The soldiers are
        sampled at ``at`` (the next tick's time; never before ``now``), so the update that reflects a request
        shows its motion already (a clip a request starts begins at its first moving frame,
        :mod:`server.soldier.lead_in`, so even a request just before ``at`` changes the wire) and the tick at
        ``at`` finds nothing new to send. It is the next tick's update, so
        the throttle is the tick's: a soldier not due at ``at`` waits for its tick. Nothing in every-frame
        mode (its clock steps one frame per tick).
        """
        tb = self.table
        at = now if at is None else max(now, at)
        idx = np.flatnonzero(tb.requested).astype(np.int64)
        if self._settings.every_frame or len(idx) == 0:
            return self._emit(idx[:0], now)
        tb.clock[idx] = np.maximum(tb.clock[idx], now)
        self._advance(idx)
        due = idx[self._due(tb.tick_sent[idx], at)]
        self.stats["answers"] += len(due)
        out = self._emit(due, at)
        tb.tick_sent[due] = at
        return out

    def _due(self, tick_sent: np.ndarray, at: float) -> np.ndarray:
        """The throttle: a tick's update ``min_interval`` after the last one, or that same tick's again."""
        return (at - tick_sent >= self._settings.min_interval - _EPS_T) | (tick_sent >= at - _EPS_T)

    def _emit(self, due: np.ndarray, now: float) -> TickUpdate:
        """The poses of ``due`` at ``now`` as a :class:`TickUpdate`; clears the flags that asked for it."""
        tb = self.table
        joints, figures, clips, frames = self._pose(due, now)
        heading_only = tb.heading_pending[due] & ~tb.dirty[due] & (tb.mode[due] == _IDLE)
        heading_only &= tb.blend_len[due] <= 0
        out = TickUpdate(
            due.copy(), joints, figures, heading_only, clips, frames, tb.heading[due].copy(), now, self.ticks
        )
        tb.last_sent[due] = now
        tb.dirty[due] = False
        tb.heading_pending[due] = False
        tb.requested[due] = False
        self.stats["updates"] += len(due)
        return out

    def snapshot(self, indices: np.ndarray | list[int] | None = None) -> TickUpdate:
        """The current poses of live soldiers (all if None), ignoring the throttle: for a new subscriber."""
        tb = self.table
        idx = tb.live if indices is None else np.asarray(indices, np.int64)
        idx = np.unique(idx[tb.live_mask(idx)])
        joints, figures, clips, frames = self._pose(idx)
        return TickUpdate(
            idx,
            joints,
            figures,
            np.zeros(len(idx), bool),
            clips,
            frames,
            tb.heading[idx].copy(),
            float(tb.clock[idx].max()) if len(idx) else 0.0,
            self.ticks,
        )

    def _pose(
        self, idx: np.ndarray, at: float | None = None, *, folded: bool = False
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Poses shown by soldiers ``idx`` at their clocks (or at ``at``, if later: an :meth:`answer`): one
        sample per figure set, heading offsets, cross-fades. ``folded``: their root offsets and turns were
        just brought up to their clocks (a request's, :meth:`apply_requests`): a second fold at the same time
        turns nothing and moves nothing, so it is not done."""
        tb, lib = self.table, self.library
        n = len(idx)
        clip = tb.clip[idx]
        clock = tb.clock[idx] if at is None or self._settings.every_frame else np.maximum(tb.clock[idx], at)
        args = (clip, tb.start[idx], tb.direc[idx], tb.dur[idx], clock)
        fset = tb.fset[idx] if len(lib.sets) > 1 and n else np.zeros(1, np.int16)
        kinds = _kinds(fset)
        if len(kinds) == 1:  # one figure set (the usual crowd): sampled straight, no per-set gather/scatter
            s = lib.sets[kinds[0]].sample(*args, interpolate=self._settings.interpolate)
            joints, figures, frames = s.joints, s.figures, s.position
        else:
            joints = np.empty((n, lib.ndof), np.float32)
            figures = np.empty((n, lib.nfig, 7), np.float32)
            frames = np.empty(n, np.float64)
            for k in kinds:
                sel = np.flatnonzero(fset == k)
                s = lib.sets[k].sample(*(a[sel] for a in args), interpolate=self._settings.interpolate)
                joints[sel], figures[sel], frames[sel] = s.joints, s.figures, s.position
        if n:  # the root offset and yaw: every figure of the soldier moves with it (docs/PROTOCOL.md)
            if not folded:
                mode = tb.mode[idx]
                turning = (tb.root_yaw[idx] != 0.0) & ((mode == _LOCO) | (mode == _CRAWL))
                root_motion.fold(tb, lib, idx[turning], clock[turning])
                p = np.flatnonzero(tb.pivot_rest[idx] != 0.0)
                if len(p):
                    root_motion.pivot(tb, lib, idx[p], clock[p])
            # the figure's yaw and offset from the heading: its frame's (``face``, turning.py) and in it
            face = tb.face[idx]
            yaw = tb.root_yaw[idx] + face
            yawed = np.flatnonzero(yaw != 0.0)
            if len(yawed):
                f = np.take(figures, yawed, axis=0)
                yaw_rotate(f, yaw[yawed])
                _set_rows(figures, yawed, f)
            off = root_motion.offset_at(tb, lib, idx, clock, frames)
            about = np.flatnonzero(face != 0.0)
            if len(about):
                set_rows(off, about, root_motion.yawed(np.take(off, about, axis=0), face[about]))
            off = off.astype(np.float32)
            for k in range(figures.shape[1]):  # (a figure at a time: an (n, 1) broadcast over nfig is dearer)
                figures[:, k, 0] += off[:, 0]
                figures[:, k, 2] += off[:, 1]
        if n and self._offsets.any():
            off = self._offsets[lib.clip_graph[clip]]
            turn = np.flatnonzero(off != 0.0)
            if len(turn):
                f = np.take(figures, turn, axis=0)
                yaw_rotate(f, off[turn])
                _set_rows(figures, turn, f)
        if n:
            blending = np.flatnonzero(tb.blend_len[idx] > 0)
            if len(blending):
                b = idx[blending]
                u = (clock[blending] - tb.blend_t0[b]) / tb.blend_len[b]
                j, f = np.take(joints, blending, axis=0), np.take(figures, blending, axis=0)
                src_j, src_f = np.take(tb.blend_joints, b, axis=0), np.take(tb.blend_figs, b, axis=0)
                blend_into(j, f, src_j, src_f, smoothstep(u))
                set_rows(joints, blending, j)
                _set_rows(figures, blending, f)
                tb.blend_len[b[u >= 1.0]] = 0.0
        return joints, figures, clip.astype(np.int32), frames


def _set_rows(figures: np.ndarray, rows: np.ndarray, values: np.ndarray) -> None:
    """``figures[rows] = values`` for (n, nfig, 7) placements, each row moved whole (:func:`set_rows`: numpy's
    fancy assignment steps through a row's fields, ~10 times dearer here)."""
    if not figures.flags.c_contiguous:  # (a reshape would copy)
        figures[rows] = values
        return
    set_rows(figures.reshape(len(figures), -1), rows, values.reshape(len(values), -1))


def _kinds(fset: np.ndarray) -> list[int]:
    """The distinct figure sets of ``fset`` (non-empty), ascending: one comparison when all are equal."""
    lo, hi = int(fset.min()), int(fset.max())
    if lo == hi:
        return [lo]
    return (np.flatnonzero(np.bincount(fset - lo)) + lo).tolist()
