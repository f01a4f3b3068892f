"""SimSoldier (seed 002, 3.5): the stub's own soldiers: dead reckoning, terrain following, requests.

"An example implementation of the use of JackSoldier is in the file simsoldier.cpp, which has a sample class
called SimSoldier, which implements a kind of control for a soldier in the Performer environment, along with
simple simulations (soldiers that walk in squares and circles)." TTES owns each soldier's global position and
heading ("TTES controls the global position of each human figure ... using DIS dead-reckoning algorithms and
information about the terrain"); Jack only animates the body in place.

All soldiers are rows of arrays (struct of arrays); one :meth:`SimSoldiers.step` moves every one of them:
user-driven soldiers by dead reckoning along their heading at their signed speed (negative: walking
backwards), path walkers along a square or a circle, and every soldier's feet onto the ground by a vertical
ray cast from above its head. Only standing and prone (crawling) soldiers move, as in Figure 12.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np
from numpy.typing import DTypeLike

from client_stub.stub.terrain import Terrain
from protocol import coords
from protocol.entity import ENTITY_REQUEST_DTYPE, Appearance, WeaponState

RAY_START = 2.0  # metres above the feet the ground ray starts (a soldier walks under roofs, onto low steps)
MAX_SPEED = 8.0


class Behaviour(IntEnum):
    USER = 0  # keyboard / script: dead reckoning at its own heading and speed
    SQUARE = 1
    CIRCLE = 2


class Force(IntEnum):
    FRIENDLY = 0
    OPPOSING = 1


_COLUMNS: dict[str, tuple[DTypeLike, tuple[int, ...]]] = {
    "alive": (bool, ()),
    "position": (np.float64, (3,)),
    "heading": (np.float64, ()),  # compass degrees
    "speed": (np.float64, ()),  # signed m/s along the heading
    "appearance": (np.uint8, ()),
    "weapon": (np.uint8, ()),
    "behaviour": (np.int8, ()),
    "force": (np.int8, ()),
    "centre": (np.float64, (2,)),  # path centre
    "size": (np.float64, ()),  # square side / circle radius
    "travel": (np.float64, ()),  # metres travelled along the path
    "distance": (np.float64, ()),  # metres travelled in total (offline gait phase)
    "immediate": (bool, ()),
    "dirty": (bool, ()),  # a request is due
}


class SimSoldiers:
    """The stub's soldiers (slots ``0 .. count-1``)."""

    def __init__(self, terrain: Terrain, capacity: int = 16) -> None:
        self.terrain = terrain
        self.count = 0
        self.capacity = 0
        self.time = 0.0
        for name, (dtype, shape) in _COLUMNS.items():
            setattr(self, name, np.zeros((0, *shape), dtype))
        self._sent = np.zeros(0, ENTITY_REQUEST_DTYPE)
        self._grow(capacity)

    alive: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    appearance: np.ndarray
    weapon: np.ndarray
    behaviour: np.ndarray
    force: np.ndarray
    centre: np.ndarray
    size: np.ndarray
    travel: np.ndarray
    distance: np.ndarray
    immediate: np.ndarray
    dirty: np.ndarray

    def _grow(self, capacity: int) -> None:
        if capacity <= self.capacity:
            return
        extra = capacity - self.capacity
        for name, (dtype, shape) in _COLUMNS.items():
            old = getattr(self, name)
            setattr(self, name, np.concatenate([old, np.zeros((extra, *shape), dtype)]))
        self._sent = np.concatenate([self._sent, np.zeros(extra, ENTITY_REQUEST_DTYPE)])
        self.capacity = capacity

    def add(
        self,
        xy: np.ndarray | tuple[float, float],
        heading: float = 0.0,
        *,
        appearance: int = Appearance.UPRIGHT,
        weapon: int = WeaponState.DEPLOYED,
        speed: float = 0.0,
        behaviour: Behaviour = Behaviour.USER,
        force: Force = Force.FRIENDLY,
        size: float = 10.0,
    ) -> int:
        """A new soldier; path walkers walk around ``xy`` (the path's centre). Returns its slot."""
        slot = self.count
        if slot >= self.capacity:
            self._grow(max(2 * self.capacity, 16))
        self.count += 1
        xy = np.asarray(xy, np.float64)
        self.alive[slot] = True
        self.heading[slot] = heading % 360.0
        self.speed[slot] = speed
        self.appearance[slot] = appearance
        self.weapon[slot] = weapon
        self.behaviour[slot] = behaviour
        self.force[slot] = force
        self.centre[slot] = xy
        self.size[slot] = size
        self.travel[slot] = 0.0
        self.distance[slot] = 0.0
        self.position[slot, :2] = xy
        if behaviour != Behaviour.USER:
            self._follow_paths(np.array([slot]))
        self.position[slot, 2] = self.terrain.height(self.position[slot, :2])
        self.dirty[slot] = True
        return slot

    # -- per frame ---------------------------------------------------------------------------------------

    def moving(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Soldiers whose posture lets them travel: standing (walk, run) and prone (crawl)."""
        rows = np.arange(self.count) if rows is None else rows
        app = self.appearance[rows]
        return (app == Appearance.UPRIGHT) | (app == Appearance.PRONE) | (app == Appearance.CRAWL)

    def step(self, dt: float) -> None:
        """Advance every soldier by ``dt`` seconds and put its feet on the ground."""
        n = self.count
        if n == 0 or dt <= 0:
            self.time += max(dt, 0.0)
            return
        self.time += dt
        rows = np.arange(n)
        go = self.moving(rows) & self.alive[:n]
        step = np.where(go, self.speed[:n] * dt, 0.0)
        self.distance[:n] += np.abs(step)
        user = rows[(self.behaviour[:n] == Behaviour.USER) & go]
        if len(user):
            d = coords.compass_to_direction(self.heading[user])[:, :2]
            self.position[user, :2] += d * step[user, None]
        paths = rows[(self.behaviour[:n] != Behaviour.USER) & go]
        if len(paths):
            self.travel[paths] += step[paths]
            self._follow_paths(paths)
        self.position[:n, 2] = self.terrain.height(
            self.position[:n, :2], self.position[:n, 2] + RAY_START, default=0.0
        )

    def _follow_paths(self, rows: np.ndarray) -> None:
        """Place path walkers from the distance travelled: a square (heading turns 90° at each corner,
        clockwise seen from above) or a circle (heading along the tangent)."""
        beh = self.behaviour[rows]
        sq = rows[beh == Behaviour.SQUARE]
        if len(sq):
            side = np.maximum(self.size[sq], 1e-3)
            s = np.mod(self.travel[sq], 4 * side)
            leg = np.minimum((s // side).astype(np.int64), 3)
            along = s - leg * side
            corners = np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, 0.5], [0.5, -0.5]])
            dirs = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [-1.0, 0.0]])
            self.position[sq, :2] = (
                self.centre[sq] + corners[leg] * side[:, None] + dirs[leg] * along[:, None]
            )
            self.heading[sq] = np.array([0.0, 90.0, 180.0, 270.0])[leg]
        ci = rows[beh == Behaviour.CIRCLE]
        if len(ci):
            r = np.maximum(self.size[ci], 1e-3)
            angle = self.travel[ci] / r  # clockwise from north, as compass headings
            self.position[ci, :2] = self.centre[ci] + r[:, None] * np.stack([np.sin(angle), np.cos(angle)], 1)
            self.heading[ci] = np.mod(np.degrees(angle) + 90.0, 360.0)

    # -- what TTES sends Jack --------------------------------------------------------------------------------

    def velocity(self, rows: np.ndarray) -> np.ndarray:
        return coords.compass_to_direction(self.heading[rows]) * self.speed[rows, None]

    def requests(self, rows: np.ndarray | None = None, *, changed_only: bool = True) -> np.ndarray:
        """Entity-request rows (``ENTITY_REQUEST_DTYPE``, index = slot) of the soldiers whose request differs
        from the last one returned (posture, weapon, velocity, heading), or all of ``rows``."""
        rows = np.arange(self.count) if rows is None else np.asarray(rows, np.int64)
        rows = rows[self.alive[rows]]
        req = np.zeros(len(rows), ENTITY_REQUEST_DTYPE)
        req["index"] = rows
        req["appearance"] = self.appearance[rows]
        req["weapon"] = self.weapon[rows]
        req["velocity"] = self.velocity(rows)
        req["heading"] = self.heading[rows]
        req["position"] = self.position[rows]
        req["immediate"] = self.immediate[rows]
        if changed_only:
            old = self._sent[rows]
            changed = (
                self.dirty[rows]
                | (old["appearance"] != req["appearance"])
                | (old["weapon"] != req["weapon"])
                | (np.abs(old["velocity"] - req["velocity"]).max(axis=1) > 1e-4)
                | (np.abs((old["heading"] - req["heading"] + 180.0) % 360.0 - 180.0) > 0.05)
            )
            req = req[changed]
            rows = rows[changed]
        self._sent[rows] = req
        self.dirty[rows] = False
        self.immediate[rows] = False
        return req

    def entity_matrices(self, rows: np.ndarray) -> np.ndarray:
        """Entity Position DCS of each soldier: heading and position (feet on the ground)."""
        return coords.heading_transform(self.heading[rows], self.position[rows])

    # -- changes (keyboard, script) ------------------------------------------------------------------------

    def set_appearance(self, slot: int, appearance: int) -> None:
        self.appearance[slot] = appearance
        self.dirty[slot] = True

    def set_weapon(self, slot: int, weapon: int) -> None:
        self.weapon[slot] = weapon
        self.dirty[slot] = True

    def turn(self, slot: int, degrees: float) -> None:
        """Change heading; a path walker is taken over by the user (the seed: arrows drive any soldier)."""
        self._take_over(slot)
        self.heading[slot] = (self.heading[slot] + degrees) % 360.0
        self.dirty[slot] = True

    def accelerate(self, slot: int, delta: float) -> None:
        self._take_over(slot)
        self.speed[slot] = float(np.clip(round(self.speed[slot] + delta, 6), -MAX_SPEED, MAX_SPEED))
        self.dirty[slot] = True

    def _take_over(self, slot: int) -> None:
        self.behaviour[slot] = Behaviour.USER
