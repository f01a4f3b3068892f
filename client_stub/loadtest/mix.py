"""The realistic soldier mix of ``ttes loadtest`` and ``ttes crowd``: what N soldiers do, as DIS would say it.

A DIS exercise does not send a soldier's state every frame: an entity state goes out when it changes beyond
the dead-reckoning thresholds (here: an activity change, a walker turning) and as a heartbeat every few
seconds (IEEE 1278.1 uses 5 s). :class:`MixDriver` keeps every soldier's *activity* (standing, walking,
running, kneeling, prone, crawling, firing in three postures, dying) as rows of arrays, dead-reckons the
positions, and each :meth:`MixDriver.step` returns the entity-request rows that a DIS gateway would send now,
vectorised over soldiers. Each activity lasts an exponentially distributed time, then the soldier picks
another by the mix's shares; a dead soldier is revived after a while with ``immediate`` (a respawn, since
no posture graph leaves DEAD gracefully).

``--mix moving`` keeps every soldier walking, running or crawling: the worst case for the update stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from protocol.entity import ENTITY_REQUEST_DTYPE, Appearance, WeaponState

HEARTBEAT_S = 5.0  # DIS heartbeat: a soldier's state is re-sent at least this often
TURN_EVERY_S = 4.0  # mean time between a walker's turns (each one a DR threshold crossing: a request)
MAX_TURN_DEG = 45.0


class Activity(IntEnum):
    STAND = 0
    WALK = 1
    RUN = 2
    KNEEL = 3
    PRONE = 4
    CRAWL = 5
    FIRE_STANDING = 6
    FIRE_KNEELING = 7
    FIRE_PRONE = 8
    DEAD = 9


@dataclass(frozen=True)
class ActivitySpec:
    appearance: int
    weapon: int
    speed: float  # m/s along the heading
    share: float  # probability of picking it at a change (realistic mix)
    dwell_s: float  # mean duration


SPECS: dict[Activity, ActivitySpec] = {
    Activity.STAND: ActivitySpec(Appearance.UPRIGHT, WeaponState.DEPLOYED, 0.0, 0.14, 8.0),
    Activity.WALK: ActivitySpec(Appearance.UPRIGHT, WeaponState.DEPLOYED, 1.4, 0.24, 10.0),
    Activity.RUN: ActivitySpec(Appearance.UPRIGHT, WeaponState.DEPLOYED, 4.0, 0.10, 6.0),
    Activity.KNEEL: ActivitySpec(Appearance.KNEEL, WeaponState.DEPLOYED, 0.0, 0.10, 8.0),
    Activity.PRONE: ActivitySpec(Appearance.PRONE, WeaponState.DEPLOYED, 0.0, 0.07, 8.0),
    Activity.CRAWL: ActivitySpec(Appearance.CRAWL, WeaponState.DEPLOYED, 0.4, 0.10, 10.0),
    Activity.FIRE_STANDING: ActivitySpec(Appearance.UPRIGHT, WeaponState.FIRING, 0.0, 0.06, 5.0),
    Activity.FIRE_KNEELING: ActivitySpec(Appearance.KNEEL, WeaponState.FIRING, 0.0, 0.06, 5.0),
    Activity.FIRE_PRONE: ActivitySpec(Appearance.PRONE, WeaponState.FIRING, 0.0, 0.05, 5.0),
    Activity.DEAD: ActivitySpec(Appearance.DEAD, WeaponState.STOWED, 0.0, 0.08, 6.0),
}
_ORDER = list(Activity)
APPEARANCE = np.array([SPECS[a].appearance for a in _ORDER], np.uint8)
WEAPON = np.array([SPECS[a].weapon for a in _ORDER], np.uint8)
SPEED = np.array([SPECS[a].speed for a in _ORDER], np.float64)
DWELL = np.array([SPECS[a].dwell_s for a in _ORDER], np.float64)
MOVING = SPEED > 0
MIXES: dict[str, np.ndarray] = {
    "realistic": np.array([SPECS[a].share for a in _ORDER], np.float64),
    "moving": np.where(MOVING, [SPECS[a].share for a in _ORDER], 0.0),
}


@dataclass
class MixStep:
    """What one :meth:`MixDriver.step` decided (slot numbers, not server indices)."""

    rows: np.ndarray  # ENTITY_REQUEST_DTYPE; ``index`` holds the slot
    changed: np.ndarray  # slots whose activity changed this step (a subset of ``rows['index']``)
    previous: np.ndarray  # their activity before the change


class MixDriver:
    """Every soldier's activity, position and heading; the requests a DIS gateway would send."""

    def __init__(
        self,
        n: int,
        *,
        mix: str = "realistic",
        seed: int = 1,
        centre: tuple[float, float] = (0.0, 0.0),
        spacing: float = 4.0,
        radius: float | None = None,
        heartbeat_s: float = HEARTBEAT_S,
        now: float = 0.0,
    ) -> None:
        if mix not in MIXES:
            raise ValueError(f"unknown mix {mix!r} (have {sorted(MIXES)})")
        self.rng = np.random.default_rng(seed)
        self.shares = MIXES[mix] / MIXES[mix].sum()
        self.heartbeat_s = float(heartbeat_s)
        self.centre = np.asarray(centre, np.float64)
        self.spacing = float(spacing)
        self.n = 0
        self.activity = np.zeros(0, np.int8)
        self.since = np.zeros(0)  # when the current activity started
        self.until = np.zeros(0)  # when it ends
        self.turn_at = np.zeros(0)
        self.last_sent = np.zeros(0)
        self.position = np.zeros((0, 3))
        self.heading = np.zeros(0)  # compass degrees
        self.home = np.zeros((0, 2))
        self.radius = 0.0
        self._fixed_radius = radius
        self.time = float(now)
        self.grow(n)

    # -- population ----------------------------------------------------------------------------------------
    def grow(self, n: int) -> np.ndarray:
        """Add soldiers up to ``n`` (slots keep their numbers); returns the new slots."""
        old = self.n
        if n <= old:
            return np.zeros(0, np.int64)
        k = n - old
        rng = self.rng
        side = int(np.ceil(np.sqrt(n)))
        self.radius = self._fixed_radius or max(20.0, 0.6 * side * self.spacing)
        slots = np.arange(old, n)
        grid = np.stack([slots % side, slots // side], axis=1).astype(np.float64)
        home = self.centre + (grid - (side - 1) / 2) * self.spacing + rng.uniform(-1, 1, (k, 2)) * 0.3
        act = rng.choice(len(_ORDER), k, p=self.shares).astype(np.int8)
        t = self.time
        self.activity = np.concatenate([self.activity, act])
        self.since = np.concatenate([self.since, np.full(k, t)])
        # the first activity ends at a random point of its dwell, so changes do not come in waves
        self.until = np.concatenate([self.until, t + rng.exponential(DWELL[act])])
        self.turn_at = np.concatenate([self.turn_at, t + rng.exponential(TURN_EVERY_S, k)])
        self.last_sent = np.concatenate([self.last_sent, np.full(k, -np.inf)])
        self.position = np.concatenate([self.position, np.column_stack([home, np.zeros(k)])])
        self.heading = np.concatenate([self.heading, rng.uniform(0.0, 360.0, k)])
        self.home = np.concatenate([self.home, home])
        self.n = n
        return slots

    # -- state ---------------------------------------------------------------------------------------------
    @property
    def moving(self) -> np.ndarray:
        """(n,) bool: the soldiers whose activity walks, runs or crawls."""
        return MOVING[self.activity]

    def velocity(self, slots: np.ndarray | None = None) -> np.ndarray:
        idx = slice(None) if slots is None else slots
        h = np.radians(self.heading[idx])
        s = SPEED[self.activity[idx]]
        return np.column_stack([s * np.sin(h), s * np.cos(h), np.zeros_like(s)])

    def requests(self, slots: np.ndarray, immediate: bool | np.ndarray = False) -> np.ndarray:
        """The entity-request rows of ``slots`` as they are now (``index`` = slot)."""
        slots = np.asarray(slots, np.int64)
        rows = np.zeros(len(slots), ENTITY_REQUEST_DTYPE)
        act = self.activity[slots]
        rows["index"] = slots
        rows["appearance"] = APPEARANCE[act]
        rows["weapon"] = WEAPON[act]
        rows["velocity"] = self.velocity(slots)
        rows["heading"] = self.heading[slots]
        rows["position"] = self.position[slots]
        rows["immediate"] = np.asarray(immediate, np.uint8)
        return rows

    def initial(self, slots: np.ndarray | None = None) -> np.ndarray:
        """First requests (default: every soldier), ``immediate``: snap into the starting posture."""
        slots = np.arange(self.n) if slots is None else np.asarray(slots, np.int64)
        # heartbeats of a real exercise are not in step: spread the first ones over a heartbeat period
        self.last_sent[slots] = self.time - self.rng.uniform(0.0, self.heartbeat_s, len(slots))
        return self.requests(slots, True)

    # -- time ----------------------------------------------------------------------------------------------
    def advance(self, now: float) -> None:
        """Dead-reckon every soldier to ``now`` (positions only; no requests)."""
        dt = max(0.0, now - self.time)
        self.time = max(self.time, now)
        if dt and self.n:  # the movers alone (the others' velocity is 0): half the sines of a realistic mix
            mov = np.flatnonzero(MOVING[self.activity])
            self.position[mov, :2] += self.velocity(mov)[:, :2] * dt

    def step(self, now: float) -> MixStep:
        """Advance to ``now`` and decide the requests due: activity changes, turns, heartbeats."""
        self.advance(now)
        rng = self.rng
        t = self.time
        due = np.flatnonzero(self.until <= t)
        previous = self.activity[due].copy()
        revive = due[previous == Activity.DEAD]
        if len(due):
            # a new activity, never the same one: draw, then redraw the repeats once and shift the rest
            new = rng.choice(len(_ORDER), len(due), p=self.shares).astype(np.int8)
            same = new == previous
            new[same] = rng.choice(len(_ORDER), int(same.sum()), p=self.shares)
            same = new == previous
            allowed = np.flatnonzero(self.shares > 0)
            if same.any():
                pos = np.searchsorted(allowed, new[same])
                new[same] = allowed[(pos + 1) % len(allowed)]
            new[previous == Activity.DEAD] = Activity.STAND  # respawn standing
            self.activity[due] = new
            self.since[due] = t
            self.until[due] = t + rng.exponential(DWELL[new])
        # walkers turn now and then, and back towards home when they stray
        turners = np.flatnonzero((self.turn_at <= t) & self.moving)
        self.turn_at[self.turn_at <= t] = t + rng.exponential(TURN_EVERY_S, int((self.turn_at <= t).sum()))
        if len(turners):
            off = self.position[turners, :2] - self.home[turners]
            far = np.hypot(off[:, 0], off[:, 1]) > self.radius
            home_heading = np.degrees(np.arctan2(-off[:, 0], -off[:, 1])) % 360.0
            turn = rng.uniform(-MAX_TURN_DEG, MAX_TURN_DEG, len(turners))
            self.heading[turners] = np.where(far, home_heading, (self.heading[turners] + turn) % 360.0)
        beat = np.flatnonzero(t - self.last_sent >= self.heartbeat_s)
        send = np.union1d(np.union1d(due, turners), beat)
        immediate = np.isin(send, revive)
        rows = self.requests(send, immediate)
        self.last_sent[send] = t
        return MixStep(rows, due, previous)

    def counts(self) -> dict[str, int]:
        """How many soldiers do what now (for reports)."""
        n = np.bincount(self.activity.astype(np.int64), minlength=len(_ORDER))
        return {a.name.lower(): int(n[a]) for a in _ORDER}
