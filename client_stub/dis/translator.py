"""DisTranslator: decoded Entity State PDUs in, soldier creations / removals and entity requests out.

The 1994 TTES "filters and translates the DIS stream into a set of posture and command tokens that are passed
to Jack" and "controls the global position of each human figure ... using DIS dead-reckoning algorithms"
(seed 002, section 2). This is that trainer's bookkeeping, pure (no sockets, no clock): one soldier per
lifeform entity, created on first sight, removed when its PDUs stop for ``timeout`` seconds (DIS's 12 s by
default) or when it reports itself deactivated; each soldier's last PDU kept for dead reckoning with the
entity's own algorithm; an entity request whenever the posture, weapon, velocity or heading the server
should show changes. Everything is struct-of-arrays indexed by *slot*; a slot belongs to one entity for
good, so a soldier that re-appears gets its old slot (and server index) back.

Weapon events: a Fire PDU makes its shooter's soldier recoil (``Translation.recoils``, sent as REACT) and,
if he is a live, standing-still soldier, holds his weapon at FIRING for ``fire_hold`` seconds (the firing
posture, "if not already": the server plays the recoil once the rifle is up); a moving soldier keeps moving
(a posture change would cut his step, and the server does not make a stepping soldier react). A Detonation
makes every live soldier within ``flinch_radius`` (FLINCH_RADIUS, 5 m, horizontally) of its location
flinch (``Translation.flinches``; one vectorised distance over the soldier slots), counted in
``near_detonations``. An event older than REACTION_MAX_AGE when its step runs (a replay's skipped start, a
late chunk) is counted but not played.

A Remove Entity PDU removes its entity's soldier at once (``RemoveReason.REMOVED``; 65535 in a field of the
id matches every site, application or entity), without waiting out the timeout; counted in
``removed_by_pdu``. Entity State Update PDUs arrive here as Entity State records (the log readers put each on
its entity's last Entity State PDU), so they need nothing of their own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from protocol.dis import (
    DisEvent,
    EntityStateBatch,
    LocalFrame,
    TtesPosture,
    TtesWeapon,
    WeaponEvent,
    dead_reckon,
    decode_appearance,
    entity_keys,
    heading_deg,
    rifle_code,
    ttes_posture,
    ttes_weapon,
)
from protocol.dis.remove_entity import ALL as ALL_IDS
from protocol.dis.remove_entity import RemoveEntity
from protocol.entity import ENTITY_REQUEST_DTYPE
from protocol.events import DEFAULT_MAX_SOLDIERS

DIS_TIMEOUT = 12.0  # s without a PDU before an entity is dropped (IEEE 1278.1 default)
FIRE_HOLD = 1.0  # s a Fire PDU holds a standing-still shooter at FIRING
FLINCH_RADIUS = 5.0  # m: a detonation this close to a soldier counts as "near" (he flinches)
REACTION_MAX_AGE = 0.5  # s: a Fire or Detonation older than this when translated makes nobody react
MAX_REQUEST_SPEED = 50.0  # m/s: the server refuses > 100 m/s; no lifeform is faster than this
MAX_ECEF_RADIUS = 1e8  # m: PDUs placed further from the Earth's centre are bad values
STILL_SPEED = 0.1  # m/s: slower counts as standing still
HEADING_EPS = 0.5  # degrees of heading change worth a request
VELOCITY_EPS = 1e-3  # m/s of velocity change worth a request
I64 = NDArray[np.int64]
F64 = NDArray[np.float64]


class RemoveReason(IntEnum):
    TIMEOUT = 1  # no PDU for ``timeout`` seconds
    DEACTIVATED = 2  # appearance bit 23
    RESET = 3  # replay looped / stopped
    REMOVED = 4  # a Remove Entity PDU named it


# One row per soldier created (or re-created): what the image generator and the server need to make him.
SOLDIER_DTYPE = np.dtype(
    [
        ("slot", "i8"),
        ("entity", "u2", (3,)),  # site, application, entity
        ("force", "u1"),  # DIS force id: 1 friendly, 2 opposing, 3 neutral
        ("rifle", "u1"),  # index into protocol.dis.RIFLE_FIGURES
        ("paint", "u1"),  # 0 uniform, 1 camouflage
        ("camouflage", "u1"),  # 0 desert, 1 winter, 2 forest, 3 other
        ("marking", "S11"),
    ]
)


@dataclass
class Translation:
    """What one step produced: soldiers to create, soldiers to remove, entity requests (index = slot)."""

    created: NDArray[np.void] = field(default_factory=lambda: np.zeros(0, SOLDIER_DTYPE))
    removed: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    reasons: NDArray[np.uint8] = field(default_factory=lambda: np.zeros(0, np.uint8))
    requests: NDArray[np.void] = field(default_factory=lambda: np.zeros(0, ENTITY_REQUEST_DTYPE))
    fire_reactions: I64 = field(default_factory=lambda: np.zeros(0, np.int64))  # slots set FIRING by Fire
    recoils: I64 = field(default_factory=lambda: np.zeros(0, np.int64))  # slots that fired (REACT RECOIL)
    flinches: I64 = field(default_factory=lambda: np.zeros(0, np.int64))  # slots near a blast (REACT FLINCH)

    def __bool__(self) -> bool:
        return bool(
            len(self.created)
            or len(self.removed)
            or len(self.requests)
            or len(self.recoils)
            or len(self.flinches)
        )

    @staticmethod
    def merge(parts: list[Translation]) -> Translation:
        """One translation of several in order (later requests for a soldier supersede earlier ones)."""
        parts = [p for p in parts if p or len(p.fire_reactions)]
        if not parts:
            return Translation()
        if len(parts) == 1:
            return parts[0]
        # applied as removals, creations, requests: a soldier created and then removed within the merged
        # steps is never created, and requests made before a removal are dropped
        created, removed, reasons, requests = (
            parts[0].created,
            parts[0].removed,
            parts[0].reasons,
            parts[0].requests,
        )
        recoils, flinches = parts[0].recoils, parts[0].flinches
        for p in parts[1:]:
            if len(p.removed):
                fresh = np.isin(created["slot"], p.removed)
                cancelled = created["slot"][fresh]
                created = created[~fresh]
                keep = ~np.isin(p.removed, cancelled)
                removed = np.concatenate([removed, p.removed[keep]])
                reasons = np.concatenate([reasons, p.reasons[keep]])
                requests = requests[~np.isin(requests["index"], p.removed)]
                recoils = recoils[~np.isin(recoils, p.removed)]
                flinches = flinches[~np.isin(flinches, p.removed)]
            created = np.concatenate([created, p.created])
            requests = np.concatenate([requests, p.requests])
            recoils = np.concatenate([recoils, p.recoils])
            flinches = np.concatenate([flinches, p.flinches])
        return Translation(
            created,
            removed,
            reasons,
            _last_per_index(requests),
            np.concatenate([p.fire_reactions for p in parts]),
            recoils,
            flinches,
        )


def sane_records(rec: NDArray[np.void]) -> NDArray[np.bool_]:
    """Records whose numbers a soldier can use: finite, and located within reach of the Earth."""
    with np.errstate(over="ignore", invalid="ignore"):
        ok = np.linalg.norm(rec["location"], axis=1) < MAX_ECEF_RADIUS  # False for NaN and inf too
    for name in ("velocity", "orientation", "acceleration", "angular_velocity"):
        ok &= np.isfinite(rec[name]).all(axis=1)
    return ok


def _last_per_index(rows: NDArray[np.void]) -> NDArray[np.void]:
    """Keep the last request of each soldier, ordered by soldier (the server applies only the last anyway)."""
    if len(rows) < 2:
        return rows
    idx = rows["index"][::-1]
    _, first = np.unique(idx, return_index=True)
    return rows[::-1][first]


_COLUMNS: dict[str, tuple[str, tuple[int, ...]]] = {
    "key": ("u8", ()),
    "live": ("?", ()),
    "last_seen": ("f8", ()),  # receipt time of the last PDU
    "pdu_t": ("f8", ()),  # dead-reckoning base time (= last_seen)
    "alg": ("u1", ()),
    "location": ("f8", (3,)),  # ECEF m
    "velocity": ("f8", (3,)),  # ECEF m/s
    "acceleration": ("f8", (3,)),
    "angular_velocity": ("f8", (3,)),
    "orientation": ("f8", (3,)),
    "frozen": ("?", ()),
    "force": ("u1", ()),
    "rifle": ("u1", ()),
    "paint": ("u1", ()),
    "camouflage": ("u1", ()),
    "posture": ("u1", ()),  # TtesPosture of the last PDU
    "weapon": ("u1", ()),  # TtesWeapon of the last PDU
    "local_velocity": ("f8", (3,)),  # east, north, up m/s (clamped)
    "heading": ("f8", ()),  # compass degrees of the last PDU
    "fire_until": ("f8", ()),  # Fire reaction holds FIRING until then (0: none)
    "sent_appearance": ("u1", ()),  # the last request sent (0: none yet)
    "sent_weapon": ("u1", ()),
    "sent_velocity": ("f8", (3,)),
    "sent_heading": ("f8", ()),
    "near_detonations": ("i8", ()),
}


class DisTranslator:
    """The entity table and the DIS -> TTES translation (see the module docstring).

    ``capacity`` caps the slots (the server's soldier indices); beyond it the slot of the entity gone longest
    is given to the newcomer, and with none gone newcomers are dropped (``stats["dropped"]``).
    """

    def __init__(
        self,
        frame: LocalFrame | None = None,
        *,
        timeout: float = DIS_TIMEOUT,
        capacity: int = DEFAULT_MAX_SOLDIERS,
        fire_hold: float = FIRE_HOLD,
        flinch_radius: float = FLINCH_RADIUS,
    ) -> None:
        if not (timeout > 0 and capacity > 0 and fire_hold >= 0):
            raise ValueError("timeout and capacity must be positive, fire_hold >= 0")
        self.frame = frame
        self.timeout = float(timeout)
        self.capacity = int(capacity)
        self.fire_hold = float(fire_hold)
        self.flinch_radius = float(flinch_radius)
        self.count = 0  # slots in use (0 .. count-1)
        self._size = 0
        for name, (dtype, shape) in _COLUMNS.items():
            setattr(self, name, np.zeros((0, *shape), dtype))
        self._sorted_keys = np.zeros(0, np.uint64)
        self._sorted_slots = np.zeros(0, np.int64)
        self._frame_key: LocalFrame | None = None
        self._frame_basis = np.eye(3)
        self._frame_origin = np.zeros(3)
        self.now = -np.inf
        self.stats = {
            "entity_states": 0,
            "created": 0,
            "recreated": 0,
            "removed_timeout": 0,
            "removed_deactivated": 0,
            "removed_by_pdu": 0,
            "requests": 0,
            "fire_events": 0,
            "fire_reactions": 0,
            "recoils": 0,
            "flinches": 0,
            "detonations": 0,
            "near_detonations": 0,
            "dropped": 0,
            "slots_reused": 0,
            "bad_values": 0,
        }

    key: NDArray[np.uint64]
    live: NDArray[np.bool_]
    last_seen: F64
    pdu_t: F64
    alg: NDArray[np.uint8]
    location: F64
    velocity: F64
    acceleration: F64
    angular_velocity: F64
    orientation: F64
    frozen: NDArray[np.bool_]
    force: NDArray[np.uint8]
    rifle: NDArray[np.uint8]
    paint: NDArray[np.uint8]
    camouflage: NDArray[np.uint8]
    posture: NDArray[np.uint8]
    weapon: NDArray[np.uint8]
    local_velocity: F64
    heading: F64
    fire_until: F64
    sent_appearance: NDArray[np.uint8]
    sent_weapon: NDArray[np.uint8]
    sent_velocity: F64
    sent_heading: F64
    near_detonations: I64

    # -- the entity <-> slot map ------------------------------------------------------------------
    @property
    def alive(self) -> int:
        return int(self.live[: self.count].sum())

    def live_slots(self) -> I64:
        return np.flatnonzero(self.live[: self.count])

    def slots_of(self, keys: NDArray[np.uint64]) -> I64:
        """Slot of each entity key, -1 for entities never seen."""
        keys = np.asarray(keys, np.uint64)
        if not len(self._sorted_keys):
            return np.full(keys.shape, -1, np.int64)
        pos = np.minimum(np.searchsorted(self._sorted_keys, keys), len(self._sorted_keys) - 1)
        return np.where(self._sorted_keys[pos] == keys, self._sorted_slots[pos], -1)

    def entity_of(self, slot: int) -> tuple[int, int, int]:
        k = int(self.key[slot])
        return (k >> 32) & 0xFFFF, (k >> 16) & 0xFFFF, k & 0xFFFF

    def _basis(self) -> F64:
        """The local frame's east, north, up rows (cached: LocalFrame recomputes them on every call)."""
        if self._frame_key is not self.frame:
            assert self.frame is not None
            self._frame_key = self.frame
            self._frame_basis = self.frame.basis
            self._frame_origin = self.frame.origin_ecef
        return self._frame_basis

    def to_local(self, ecef: F64) -> F64:
        """ECEF points -> local east, north, up metres."""
        basis = self._basis()
        return (np.asarray(ecef, np.float64) - self._frame_origin) @ basis.T

    def _grow(self, needed: int) -> None:
        if needed <= self._size:
            return
        size = max(needed, 2 * self._size, 64)
        for name, (dtype, shape) in _COLUMNS.items():
            old = getattr(self, name)
            new = np.zeros((size, *shape), dtype)
            new[: len(old)] = old
            setattr(self, name, new)
        self._size = size

    def _assign(self, new_keys: NDArray[np.uint64]) -> I64:
        """Slots for keys never seen (in order); -1 where the table is full."""
        n = len(new_keys)
        free = min(n, self.capacity - self.count)
        slots = np.full(n, -1, np.int64)
        slots[:free] = np.arange(self.count, self.count + free)
        self._grow(self.count + free)
        self.count += free
        if free < n:  # full: take the slots of the entities gone longest
            dead = np.flatnonzero(~self.live[: self.count])
            dead = dead[np.argsort(self.last_seen[dead], kind="stable")][: n - free]
            slots[free : free + len(dead)] = dead
            self.stats["slots_reused"] += len(dead)
            self.stats["dropped"] += n - free - len(dead)
            if len(dead):  # the old entities lose their slot
                keep = ~np.isin(self._sorted_slots, dead)
                self._sorted_keys, self._sorted_slots = self._sorted_keys[keep], self._sorted_slots[keep]
        ok = slots >= 0
        self.key[slots[ok]] = new_keys[ok]
        keys = np.concatenate([self._sorted_keys, new_keys[ok]])
        order = np.argsort(keys, kind="stable")
        self._sorted_keys = keys[order]
        self._sorted_slots = np.concatenate([self._sorted_slots, slots[ok]])[order]
        return slots

    # -- one step ---------------------------------------------------------------------------------
    def step(
        self,
        now: float,
        batch: EntityStateBatch | None = None,
        times: F64 | None = None,
        events: Sequence[DisEvent] = (),
    ) -> Translation:
        """Take the PDUs received up to ``now`` (``times`` per record, non-decreasing) and the events (Fire,
        Detonation, Remove Entity), then expire what ``now`` makes stale. Returns everything the server and
        the stub must hear."""
        parts = []
        if batch is not None and len(batch):
            parts.append(self.ingest(batch, np.asarray(times, np.float64)))
        weapons = [e for e in events if isinstance(e, WeaponEvent)]
        if weapons:
            parts.append(self.weapon_events(weapons, now))
        removals = [e for e in events if isinstance(e, RemoveEntity)]
        if removals:
            parts.append(self.remove_entities(removals))
        parts.append(self.advance(now))
        return Translation.merge(parts)

    def ingest(self, batch: EntityStateBatch, times: F64) -> Translation:
        """Entity State PDUs (lifeforms; records in receipt order). The last PDU of each entity wins."""
        n = len(batch)
        if n == 0:
            return Translation()
        self.stats["entity_states"] += n
        rec = batch.records
        sane = sane_records(rec)
        if not sane.all():  # NaN / inf / off-planet values would make the server refuse the whole batch
            self.stats["bad_values"] += int((~sane).sum())
            rec, times = rec[sane], np.asarray(times)[sane]
            n = len(rec)
            if n == 0:
                return Translation()
        keys = entity_keys(rec["entity_id"])
        # the last record of each entity in this batch, entities in order of first appearance
        _, first = np.unique(keys, return_index=True)
        last = (n - 1 - np.unique(keys[::-1], return_index=True)[1])[np.argsort(first)]
        keys_l = keys[last]
        slots = self.slots_of(keys_l)
        unseen = slots < 0
        known = ~unseen
        if unseen.any():
            slots[unseen] = self._assign(keys_l[unseen])
        ok = slots >= 0
        last, slots, known = last[ok], slots[ok], known[ok]
        if not len(last):
            return Translation()
        sub = rec[last]
        t = times[last]
        if self.frame is None:  # the local frame's origin: where the first PDU heard puts its entity
            self.frame = LocalFrame.at_ecef(rec["location"][0])
        et = sub["entity_type"]
        tokens = {  # Figure 2's tokens (as protocol.dis.translate, with the frame's basis computed once)
            "force": sub["force_id"],
            "posture": ttes_posture(sub["appearance"]),
            "weapon": ttes_weapon(sub["appearance"]),
            "rifle": rifle_code(et["category"], et["subcategory"], et["specific"]),
            "velocity": sub["velocity"].astype(np.float64) @ self._basis().T,
            "heading": heading_deg(sub["location"], sub["orientation"]),
        }
        app = decode_appearance(sub["appearance"])
        deactivated = np.asarray(app["deactivated"], bool)
        was_live = self.live[slots]
        born = ~deactivated & ~was_live
        gone = deactivated & was_live
        # the entity's state
        vel_local = tokens["velocity"]
        speed = np.linalg.norm(vel_local, axis=1)
        vel_local = vel_local * np.minimum(1.0, MAX_REQUEST_SPEED / np.maximum(speed, 1e-12))[:, None]
        self.live[slots] = ~deactivated
        self.last_seen[slots] = t
        self.pdu_t[slots] = t
        self.alg[slots] = sub["dr_algorithm"]
        self.location[slots] = sub["location"]
        self.velocity[slots] = sub["velocity"]
        self.acceleration[slots] = sub["acceleration"]
        self.angular_velocity[slots] = sub["angular_velocity"]
        self.orientation[slots] = sub["orientation"]
        self.frozen[slots] = app["frozen"]
        self.force[slots] = tokens["force"]
        self.rifle[slots] = tokens["rifle"]
        self.paint[slots] = app["paint_scheme"]
        self.camouflage[slots] = app["camouflage"]
        # the PDUs are the authority: a new posture or weapon from the entity ends a Fire reaction
        changed = (self.posture[slots] != tokens["posture"]) | (self.weapon[slots] != tokens["weapon"])
        self.fire_until[slots[born | changed]] = 0.0
        self.posture[slots] = tokens["posture"]
        self.weapon[slots] = tokens["weapon"]
        self.local_velocity[slots] = vel_local
        self.heading[slots] = tokens["heading"]
        self.sent_appearance[slots[born | gone]] = 0  # a (re)born soldier gets a full request
        self.stats["created"] += int(born.sum())
        self.stats["recreated"] += int((born & known).sum())  # re-appeared: his old slot and soldier
        self.stats["removed_deactivated"] += int(gone.sum())
        created = np.zeros(int(born.sum()), SOLDIER_DTYPE)
        b = slots[born]
        created["slot"] = b
        created["entity"] = np.stack(
            [sub["entity_id"][f][born] for f in ("site", "application", "entity")], axis=1
        )
        created["force"] = self.force[b]
        created["rifle"] = self.rifle[b]
        created["paint"] = self.paint[b]
        created["camouflage"] = self.camouflage[b]
        created["marking"] = sub["marking"][born]
        live_slots = slots[~deactivated]
        return Translation(
            created,
            slots[gone],
            np.full(int(gone.sum()), RemoveReason.DEACTIVATED, np.uint8),
            self._requests(live_slots, float(t.max())),
        )

    def remove_entities(self, events: Sequence[RemoveEntity]) -> Translation:
        """Remove Entity PDUs: the live soldiers of the named entities go at once (65535 matches all)."""
        live = self.live_slots()
        keys = self.key[live]
        ids = np.stack([(keys >> np.uint64(s)) & np.uint64(0xFFFF) for s in (32, 16, 0)], axis=1)
        gone = np.zeros(len(live), bool)
        for e in events:
            gone |= ((ids == np.array(e.entity, np.uint64)) | (np.array(e.entity) == ALL_IDS)).all(axis=1)
        removed = live[gone]
        self.live[removed] = False
        self.sent_appearance[removed] = 0
        self.fire_until[removed] = 0.0
        self.stats["removed_by_pdu"] += len(removed)
        return Translation(removed=removed, reasons=np.full(len(removed), RemoveReason.REMOVED, np.uint8))

    def weapon_events(self, events: Sequence[WeaponEvent], now: float | None = None) -> Translation:
        """Fire: the shooter recoils; a standing-still live shooter holds FIRING for ``fire_hold`` s.
        Detonation: the live soldiers within ``flinch_radius`` flinch. Events older than REACTION_MAX_AGE at
        ``now`` make nobody react (the hold and the counts still apply)."""
        fires = [e for e in events if e.kind == "fire"]
        dets = [e for e in events if e.kind == "detonation"]
        self.stats["fire_events"] += len(fires)
        self.stats["detonations"] += len(dets)
        out = Translation()
        fresh = -np.inf if now is None else now - REACTION_MAX_AGE
        if fires:
            self._fires(fires, fresh, out)
        if dets and self.frame is not None:
            self._detonations(dets, fresh, out)
        return out

    def _fires(self, fires: list[WeaponEvent], fresh: float, out: Translation) -> None:
        ids = np.array([e.shooter for e in fires], np.uint64).reshape(-1, 3)
        shooters = self.slots_of((ids[:, 0] << np.uint64(32)) | (ids[:, 1] << np.uint64(16)) | ids[:, 2])
        t = np.array([e.t for e in fires])
        ok = shooters >= 0
        shooters, t = shooters[ok], t[ok]
        ok = self.live[shooters] & (self.posture[shooters] != TtesPosture.DEAD)
        shooters, t = shooters[ok], t[ok]
        out.recoils = shooters[t >= fresh]
        self.stats["recoils"] += len(out.recoils)
        ok = self.weapon[shooters] != TtesWeapon.FIRING  # the PDUs already show him firing
        ok &= np.hypot(self.local_velocity[shooters, 0], self.local_velocity[shooters, 1]) < STILL_SPEED
        shooters, t = shooters[ok], t[ok]
        if len(shooters):
            np.maximum.at(self.fire_until, shooters, t + self.fire_hold)
            react = np.unique(shooters)
            self.stats["fire_reactions"] += len(react)
            out.requests = self._requests(react, float(t.max()))
            out.fire_reactions = react

    def _detonations(self, dets: list[WeaponEvent], fresh: float, out: Translation) -> None:
        live = self.live_slots()
        if not len(live):
            return
        where = self.to_local(np.array([e.location for e in dets]))
        pos, _ = self.dead_reckoned(max(e.t for e in dets), live)
        near = np.linalg.norm(pos[None, :, :2] - where[:, None, :2], axis=2) <= self.flinch_radius
        self.near_detonations[live] += near.sum(axis=0)
        self.stats["near_detonations"] += int(near.sum())
        near &= (np.array([e.t for e in dets]) >= fresh)[:, None]
        near &= (self.posture[live] != TtesPosture.DEAD)[None, :]
        out.flinches = live[np.flatnonzero(near.any(axis=0))]
        self.stats["flinches"] += len(out.flinches)

    def advance(self, now: float) -> Translation:
        """Expire entities silent for ``timeout`` s, end Fire reactions whose hold is over."""
        self.now = max(self.now, float(now))
        n = self.count
        live = self.live[:n]
        stale = np.flatnonzero(live & (now - self.last_seen[:n] > self.timeout))
        if len(stale):
            self.live[stale] = False
            self.sent_appearance[stale] = 0
            self.stats["removed_timeout"] += len(stale)
        ended = np.flatnonzero(self.live[:n] & (self.fire_until[:n] > 0) & (self.fire_until[:n] <= now))
        requests = np.zeros(0, ENTITY_REQUEST_DTYPE)
        if len(ended):
            self.fire_until[ended] = 0.0
            requests = self._requests(ended, now)
        return Translation(
            removed=stale, reasons=np.full(len(stale), RemoveReason.TIMEOUT, np.uint8), requests=requests
        )

    def reset(self) -> Translation:
        """Remove every live soldier (a replay that loops or stops); slots stay with their entities."""
        live = self.live_slots()
        self.live[live] = False
        self.sent_appearance[live] = 0
        self.fire_until[live] = 0.0
        self.now = -np.inf
        return Translation(removed=live, reasons=np.full(len(live), RemoveReason.RESET, np.uint8))

    # -- what the server and the stub see ---------------------------------------------------------
    def effective_weapon(self, slots: I64, now: float) -> NDArray[np.uint8]:
        """The PDU's weapon state, or FIRING while a Fire reaction holds."""
        hold = (self.fire_until[slots] > now) & (self.posture[slots] != TtesPosture.DEAD)
        return np.where(hold, np.uint8(TtesWeapon.FIRING), self.weapon[slots])

    def _requests(self, slots: I64, now: float) -> NDArray[np.void]:
        """Requests for ``slots`` whose posture, weapon, velocity or heading changed since the last one."""
        slots = np.asarray(slots, np.int64)
        if not len(slots):
            return np.zeros(0, ENTITY_REQUEST_DTYPE)
        weapon = self.effective_weapon(slots, now)
        vel = self.local_velocity[slots]
        dh = np.abs((self.heading[slots] - self.sent_heading[slots] + 180.0) % 360.0 - 180.0)
        changed = (
            (self.sent_appearance[slots] != self.posture[slots])
            | (self.sent_weapon[slots] != weapon)
            | (np.abs(vel - self.sent_velocity[slots]).max(axis=1) > VELOCITY_EPS)
            | (dh > HEADING_EPS)
        )
        s = slots[changed]
        rows = np.zeros(len(s), ENTITY_REQUEST_DTYPE)
        rows["index"] = s
        rows["appearance"] = self.posture[s]
        rows["weapon"] = weapon[changed]
        rows["velocity"] = vel[changed]
        rows["heading"] = self.heading[s]
        if self.frame is not None:
            rows["position"] = self.to_local(self.location[s])
        self.sent_appearance[s] = self.posture[s]
        self.sent_weapon[s] = weapon[changed]
        self.sent_velocity[s] = vel[changed]
        self.sent_heading[s] = self.heading[s]
        self.stats["requests"] += len(s)
        return rows

    def dead_reckoned(self, now: float, slots: I64 | None = None) -> tuple[F64, F64]:
        """Local east-north-up positions (n, 3) and compass headings (n,) of ``slots`` (default: the live
        ones) at ``now``, each extrapolated from its last PDU with its own dead-reckoning algorithm."""
        slots = self.live_slots() if slots is None else np.asarray(slots, np.int64)
        if not len(slots) or self.frame is None:
            return np.zeros((len(slots), 3)), np.zeros(len(slots))
        dt = np.maximum(now - self.pdu_t[slots], 0.0)
        loc, orient = dead_reckon(
            self.alg[slots],
            self.location[slots],
            self.velocity[slots],
            self.acceleration[slots],
            self.angular_velocity[slots],
            self.orientation[slots],
            dt,
            self.frozen[slots],
        )
        rotating = np.isin(self.alg[slots], (3, 4, 7, 8))
        heading = self.heading[slots].copy()
        if rotating.any():
            heading[rotating] = heading_deg(loc[rotating], orient[rotating])
        return self.to_local(loc), heading
