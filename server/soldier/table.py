"""The soldier table: every soldier state as one row of struct-of-arrays columns.

Per-tick work runs over whole columns (``table.mode[live]`` …), never over Python objects per soldier. Rows
are soldier indices (the wire's soldier index): :meth:`allocate` takes the lowest free index (or a requested
one), :meth:`free` returns it to the free list for reuse, and the columns double in capacity when an index
beyond them is needed, up to ``max_soldiers``.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from protocol.events import DEFAULT_MAX_SOLDIERS

# name: (dtype, trailing shape, initial value)
_COLUMNS: dict[str, tuple[type | str, tuple[int, ...], float]] = {
    "alive": (np.bool_, (), False),
    "fset": (np.int16, (), 0),  # figure set (MotionLibrary.sets)
    # what plays
    "mode": (np.int8, (), 0),  # state.Mode
    "loco": (np.int8, (), 0),  # state.LocoState
    "foot": (np.int8, (), 1),  # foot of the last step (the next step uses the other one)
    "node": (np.int16, (), 0),  # posture node: resting in, base of the gait, or last reached on a path
    "clip": (np.int32, (), 0),
    "start": (np.float64, (), 0.0),  # soldier time at which the clip started
    "dur": (np.float64, (), 1.0),  # seconds the clip plays over
    "direc": (np.int8, (), 1),  # +1 forwards, -1 backwards
    "end": (np.float64, (), 0.0),  # start + dur: the clip-end event time
    "clock": (np.float64, (), 0.0),  # soldier time (real time, or frame-stepped in every-frame mode)
    # the last request (Jack coordinates)
    "appearance": (np.uint8, (), 2),
    "weapon": (np.uint8, (), 1),
    "velocity": (np.float32, (3,), 0.0),  # cm/s, Jack axes
    "position": (np.float64, (3,), 0.0),  # cm, Jack axes (feet)
    "heading": (np.float64, (), 0.0),  # compass degrees as received
    "yaw": (np.float64, (), 0.0),  # Jack yaw, radians
    "speed": (np.float64, (), 0.0),  # horizontal m/s
    "backward": (np.bool_, (), False),
    "side": (np.int8, (), 0),  # locomotion.Side: moving across the heading (side-steps)
    "vlocal": (np.float64, (2,), 0.0),  # velocity in the soldier's frame (Jack X, Z cm/s: forwards is -Z)
    # root offset (root_motion): the figure's offset from the entity (X, Z cm, soldier frame) at root_t,
    # when the clip's own travel was root_ref; the clip's travel counts stride times
    "root_off": (np.float64, (2,), 0.0),
    "root_t": (np.float64, (), 0.0),
    "root_ref": (np.float64, (2,), 0.0),
    "stride": (np.float64, (), 1.0),
    "root_yaw": (np.float64, (), 0.0),  # the figure's yaw from the entity's heading (compass degrees)
    "has_heading": (np.bool_, (), False),  # a request gave the heading (the first one turns nothing)
    "face": (np.float64, (), 0.0),  # the figure's frame from the heading: 0, or 180 (turning.py), degrees
    "reversing": (np.bool_, (), False),  # walking the other way: stop, pivot, walk away (turning.py)
    "pivot_rest": (np.float64, (), 0.0),  # degrees a pivot turns beyond its turn clip (turning.py; 0: none)
    # output bookkeeping
    "last_sent": (np.float64, (), -math.inf),  # last update of either kind (tick or answer)
    "tick_sent": (np.float64, (), -math.inf),  # last update by a tick: what the tick's throttle counts from
    "dirty": (np.bool_, (), False),  # pose changed while resting: send it once
    "heading_pending": (np.bool_, (), False),
    "requested": (np.bool_, (), False),  # a request changed what it shows since its last update
    "blend_t0": (np.float64, (), 0.0),
    "blend_len": (np.float64, (), 0.0),  # 0 = not cross-fading
    "created": (np.float64, (), 0.0),
}


class SoldierTable:
    """Struct-of-arrays soldier states with capacity growth and free-list reuse of indices."""

    def __init__(
        self, ndof: int, nfig: int, capacity: int = 16, max_soldiers: int = DEFAULT_MAX_SOLDIERS
    ) -> None:
        if max_soldiers < 1:
            raise ValueError("max_soldiers must be >= 1")
        self.ndof, self.nfig = int(ndof), int(nfig)
        self.max_soldiers = int(max_soldiers)
        self.capacity = 0
        self._free: list[int] = []  # heap of free indices below capacity (and of some taken: see allocate)
        self.count = 0
        self._live: np.ndarray | None = np.zeros(0, np.int64)
        for name, (dtype, shape, _) in _COLUMNS.items():
            setattr(self, name, np.zeros((0, *shape), dtype))
        # the pose a cross-fade starts from (frozen at the interrupt)
        self.blend_joints = np.zeros((0, self.ndof), np.float32)
        self.blend_figs = np.zeros((0, self.nfig, 7), np.float32)
        self._grow(min(max(capacity, 1), self.max_soldiers))

    # typed column attributes (set in __init__/_grow); declared for type checkers
    alive: np.ndarray
    fset: np.ndarray
    mode: np.ndarray
    loco: np.ndarray
    foot: np.ndarray
    node: np.ndarray
    clip: np.ndarray
    start: np.ndarray
    dur: np.ndarray
    direc: np.ndarray
    end: np.ndarray
    clock: np.ndarray
    appearance: np.ndarray
    weapon: np.ndarray
    velocity: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    backward: np.ndarray
    side: np.ndarray
    vlocal: np.ndarray
    root_off: np.ndarray
    root_t: np.ndarray
    root_ref: np.ndarray
    stride: np.ndarray
    root_yaw: np.ndarray
    has_heading: np.ndarray
    face: np.ndarray
    reversing: np.ndarray
    pivot_rest: np.ndarray
    last_sent: np.ndarray
    tick_sent: np.ndarray
    dirty: np.ndarray
    heading_pending: np.ndarray
    requested: np.ndarray
    blend_t0: np.ndarray
    blend_len: np.ndarray
    created: np.ndarray

    def _grow(self, capacity: int) -> None:
        old = self.capacity
        if capacity <= old:
            return
        for name, (dtype, shape, init) in _COLUMNS.items():
            col = np.full((capacity, *shape), init, dtype)
            col[:old] = getattr(self, name)
            setattr(self, name, col)
        for name, shape in (("blend_joints", (self.ndof,)), ("blend_figs", (self.nfig, 7))):
            col = np.zeros((capacity, *shape), np.float32)
            col[:old] = getattr(self, name)
            setattr(self, name, col)
        for i in range(old, capacity):
            heapq.heappush(self._free, i)
        self.capacity = capacity

    def _reset_row(self, i: int) -> None:
        for name, (_, _, init) in _COLUMNS.items():
            getattr(self, name)[i] = init
        self.blend_joints[i] = 0.0
        self.blend_figs[i] = 0.0

    def allocate(self, index: int | None = None) -> int:
        """Take ``index`` (must be free) or the lowest free index; ValueError if impossible.

        An index taken by number stays in the heap of free ones until it comes up, and is skipped then: a
        shard creates every soldier by the index its front-end chose, and taking each out of a heap of
        ~20,000 (remove, heapify) cost 0.2 ms a creation at 20,000 soldiers (issue 21)."""
        if index is None:
            while True:
                if not self._free:
                    if self.capacity >= self.max_soldiers:
                        raise ValueError(f"soldier table full ({self.max_soldiers} soldiers)")
                    self._grow(min(self.capacity * 2, self.max_soldiers))
                i = heapq.heappop(self._free)
                if not self.alive[i]:  # (else taken by number since it was freed)
                    break
        else:
            i = int(index)
            if not 0 <= i < self.max_soldiers:
                raise ValueError(f"soldier index {i} outside 0..{self.max_soldiers - 1}")
            if i >= self.capacity:
                self._grow(min(max(self.capacity * 2, i + 1), self.max_soldiers))
            if self.alive[i]:
                raise ValueError(f"soldier index {i} is in use")
        self._reset_row(i)
        self.alive[i] = True
        self.count += 1
        self._live = None
        return i

    def free(self, index: int) -> None:
        """Release a live soldier's index (KeyError if it is not live)."""
        if not self.is_live(index):
            raise KeyError(f"no soldier {index}")
        self._reset_row(index)
        heapq.heappush(self._free, int(index))
        if len(self._free) > 2 * self.capacity:  # the entries of indices taken by number: start over
            self._free = np.flatnonzero(~self.alive).tolist()  # ascending: a heap
        self.count -= 1
        self._live = None

    def is_live(self, index: int) -> bool:
        return 0 <= int(index) < self.capacity and bool(self.alive[int(index)])

    @property
    def live(self) -> np.ndarray:
        """Indices of the live soldiers, ascending (cached until the next allocate/free)."""
        if self._live is None:
            self._live = np.flatnonzero(self.alive).astype(np.int64)
        return self._live

    def live_mask(self, indices: np.ndarray) -> np.ndarray:
        """Which of ``indices`` (any int values) name live soldiers."""
        idx = np.asarray(indices, np.int64)
        ok = (idx >= 0) & (idx < self.capacity)
        out = np.zeros(idx.shape, bool)
        out[ok] = self.alive[idx[ok]]
        return out
