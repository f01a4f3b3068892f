"""Synthetic DIS exercises: a squad patrol written as a real pcap (Ethernet / IPv4 / UDP broadcast).

Soldiers of two forces (friendly = force 1 with M16s, opposing = force 2 with AKs) follow a scripted
sequence of phases - patrol, rush, halt, kneel, fire kneeling, go prone, crawl, fire prone, stand up,
walk out - with seeded durations and a wandering heading. Entity State PDUs go out the way a DIS
simulator sends them: at once when the appearance changes, when the dead-reckoned (FPW) position drifts
more than :data:`DR_POSITION_THRESHOLD` m or the heading more than :data:`DR_HEADING_THRESHOLD` deg from
the truth, and at least every :data:`HEARTBEAT` s otherwise. Firing soldiers send Fire PDUs; one
opposing soldier is killed (Fire + Detonation with *entity impact*, then health fatal). A parked vehicle
(a non-lifeform) heartbeats too. Everything is deterministic for a seed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from protocol.dis.appearance import Health, LifeformState, WeaponState, encode_appearance
from protocol.dis.entity_state import (
    EntityId,
    EntityStatePdu,
    EntityType,
    encode_entity_state,
    make_marking,
)
from protocol.dis.geo import LocalFrame, orientation_from_heading
from protocol.dis.pdu import DEFAULT_PORT, encode_timestamp
from protocol.dis.warfare import (
    DetonationPdu,
    DetonationResult,
    FirePdu,
    MunitionDescriptor,
    encode_detonation,
    encode_fire,
)

QUANTICO_MOUT = (38.52, -77.44, 60.0)  # lat, lon, height: the Quantico MOUT training site, roughly
DT = 0.05  # simulation step (s)
HEARTBEAT = 5.0  # s between Entity State PDUs of an unchanging entity
DR_POSITION_THRESHOLD = 1.0  # m
DR_HEADING_THRESHOLD = 3.0  # degrees
# receipt time of t = 0: 1994-08-05 12:00:00 UTC, the date of the seed report (MS-CIS-94-42). Written as a
# date, not a count of seconds: 776_001_600, the count this was before, is 1994-08-04.
EPOCH = datetime(1994, 8, 5, 12, 0, 0, tzinfo=UTC).timestamp()

FRIENDLY, OPPOSING = 1, 2
# friendly: USA, new scheme, naval infantry (12), assault rifles (5), M16A2/A3/A4 (41)
FRIENDLY_TYPE = EntityType(3, 1, 225, 12, 5, 41, 0)
# opposing: CIS, old scheme, dismounted infantry (1), subcategory 205 = AK / AKM
OPPOSING_TYPE = EntityType(3, 1, 222, 1, 205, 1, 0)
VEHICLE_TYPE = EntityType(1, 1, 225, 6, 1, 1, 0)  # a land platform: skipped by the lifeform filter
# synthetic munition types (kind 2 munition, domain 8 anti-personnel, category 2 ballistic)
MUNITION = {FRIENDLY: EntityType(2, 8, 225, 2, 1, 0, 0), OPPOSING: EntityType(2, 8, 222, 2, 1, 0, 0)}


@dataclass(frozen=True, slots=True)
class Phase:
    name: str
    state: LifeformState
    weapon: WeaponState
    speed: float  # m/s
    duration: tuple[float, float]  # seconds, drawn uniformly


SCRIPT: tuple[Phase, ...] = (
    Phase("patrol", LifeformState.UPRIGHT_WALKING, WeaponState.DEPLOYED, 1.4, (8.0, 12.0)),
    Phase("rush", LifeformState.UPRIGHT_RUNNING, WeaponState.DEPLOYED, 3.6, (3.0, 5.0)),
    Phase("halt", LifeformState.UPRIGHT_STANDING, WeaponState.DEPLOYED, 0.0, (2.0, 3.0)),
    Phase("kneel", LifeformState.KNEELING, WeaponState.DEPLOYED, 0.0, (2.0, 3.0)),
    Phase("kneel_fire", LifeformState.KNEELING, WeaponState.FIRING, 0.0, (2.0, 4.0)),
    Phase("go_prone", LifeformState.PRONE, WeaponState.DEPLOYED, 0.0, (2.0, 3.0)),
    Phase("crawl", LifeformState.CRAWLING, WeaponState.DEPLOYED, 0.4, (4.0, 6.0)),
    Phase("prone_fire", LifeformState.PRONE, WeaponState.FIRING, 0.0, (2.0, 3.0)),
    Phase("stand_up", LifeformState.UPRIGHT_STANDING, WeaponState.STOWED, 0.0, (2.0, 3.0)),
    Phase("walk_out", LifeformState.UPRIGHT_WALKING, WeaponState.STOWED, 1.4, (6.0, 10.0)),
)
_STATE = np.array([p.state for p in SCRIPT], np.int64)
_WEAPON = np.array([p.weapon for p in SCRIPT], np.int64)
_SPEED = np.array([p.speed for p in SCRIPT])


@dataclass(slots=True)
class Packet:
    t: float  # receipt time, s since the epoch
    payload: bytes  # one PDU
    src: int  # index of the sending host (soldier / vehicle)


@dataclass(slots=True)
class Exercise:
    """The generated traffic plus the ground truth tests compare against."""

    packets: list[Packet]
    frame: LocalFrame
    entities: list[EntityId]  # soldiers, index = soldier number
    forces: list[int]
    victim: int | None  # soldier number of the one killed (None if nobody)
    killer: int | None
    t_kill: float | None  # seconds into the exercise
    schedule: list[list[tuple[float, str]]] = field(default_factory=list)  # per soldier (start, phase)
    counts: dict[str, int] = field(default_factory=dict)


def synthesize(
    soldiers: int = 8,
    seconds: float = 60.0,
    seed: int = 0,
    origin: tuple[float, float, float] = QUANTICO_MOUT,
    vehicles: int = 1,
    version: int = 7,
    progress: Callable[[int, int], None] | None = None,
) -> Exercise:
    """Generate the exercise (no I/O). ``soldiers`` alternate friendly / opposing, starting friendly.

    ``progress(step, steps)`` is called every 200 simulation steps (10 s of exercise) when given.
    """
    if soldiers < 1 or seconds <= 0:
        raise ValueError("need at least one soldier and a positive duration")
    rng = np.random.default_rng(seed)
    frame = LocalFrame(*origin)
    n = soldiers
    steps = round(seconds / DT)
    force = np.where(np.arange(n) % 2 == 0, FRIENDLY, OPPOSING)
    ids = [EntityId(1, int(f), i + 1) for i, f in enumerate(force)]

    # per-soldier phase table (steps, n): the script cycles if the exercise outlasts it
    phase_of = np.zeros((steps, n), np.int64)
    schedule: list[list[tuple[float, str]]] = []
    t_axis = np.arange(steps) * DT
    for i in range(n):
        starts, names, t, k = [], [], 0.0, 0
        while t < seconds:
            lo, hi = SCRIPT[k % len(SCRIPT)].duration
            starts.append(t)
            names.append(k % len(SCRIPT))
            t += float(rng.uniform(lo, hi))
            k += 1
        phase_of[:, i] = np.asarray(names)[np.searchsorted(starts, t_axis, side="right") - 1]
        schedule.append([(s, SCRIPT[p].name) for s, p in zip(starts, names, strict=True)])

    # the kill: the first opposing soldier (or the lone soldier) at 60% of the exercise
    victim = int(np.flatnonzero(force == OPPOSING)[0]) if (force == OPPOSING).any() else 0
    friendly = np.flatnonzero(force == FRIENDLY)
    killer = int(friendly[0]) if friendly.size and int(friendly[0]) != victim else None
    t_kill = round(0.6 * seconds / DT) * DT
    kill_step = round(t_kill / DT)
    hit_step = kill_step + round(0.2 / DT)

    # start positions: friendly west of the origin heading east, opposing east heading west
    base_heading = np.where(force == FRIENDLY, 90.0, 270.0)
    pos = np.zeros((n, 3))
    pos[:, 0] = np.where(force == FRIENDLY, -60.0, 60.0) + rng.uniform(-5, 5, n)
    pos[:, 1] = (np.arange(n) // 2 - (n - 1) / 4) * 8.0 + rng.uniform(-2, 2, n)
    heading = base_heading + rng.uniform(-20, 20, n)
    alive = np.ones(n, bool)
    last_t = np.full(n, -np.inf)
    last_pos = pos.copy()
    last_vel = np.zeros((n, 3))
    last_heading = heading.copy()
    last_app = np.full(n, -1, np.int64)
    next_shot = np.full(n, np.inf)
    event_no = np.zeros(n, np.int64)
    packets: list[Packet] = []
    counts = {"entity_state": 0, "fire": 0, "detonation": 0, "vehicle_entity_state": 0}
    veh_pos = (
        frame.to_ecef(np.array([[0.0, -25.0 - 10.0 * k, 0.0] for k in range(vehicles)])) if vehicles else None
    )

    def stamp(t: float) -> tuple[float, int]:
        rx = EPOCH + t + float(rng.uniform(0.0, 0.002))
        return rx, int(encode_timestamp(rx % 3600.0))

    for step in range(steps):
        if progress is not None and step % 200 == 0:
            progress(step, steps)
        t = step * DT
        ph = phase_of[step]
        speed = np.where(alive, _SPEED[ph], 0.0)
        moving = speed > 0
        # heading wanders while moving, pulled back towards the patrol direction
        drift = ((base_heading - heading + 180.0) % 360.0) - 180.0
        heading = np.where(moving, heading + rng.normal(0.0, 0.5, n) + 0.02 * drift, heading)
        h = np.radians(heading)
        vel = np.stack([speed * np.sin(h), speed * np.cos(h), np.zeros(n)], axis=1)
        if step:
            pos = pos + vel * DT
        app = encode_appearance(
            health=np.where(alive, Health.NO_INJURY, Health.FATAL),
            state=np.where(alive, _STATE[ph], LifeformState.PRONE),
            weapon1=np.where(alive, _WEAPON[ph], WeaponState.NONE),
            camouflage=2,
            paint_scheme=1,
        ).astype(np.int64)
        age = np.where(np.isfinite(last_t), t - last_t, 0.0)
        predicted = last_pos + last_vel * age[:, None]
        drift_m = np.linalg.norm(predicted - pos, axis=1)
        dh = np.abs(((heading - last_heading + 180.0) % 360.0) - 180.0)
        send = (
            (app != last_app)
            | (t - last_t >= HEARTBEAT - 1e-9)
            | (alive & ((drift_m > DR_POSITION_THRESHOLD) | (dh > DR_HEADING_THRESHOLD)))
        )
        senders = np.flatnonzero(send)
        if senders.size:
            ecef = frame.to_ecef(pos[senders])
            ori = orientation_from_heading(ecef, heading[senders])
            vel_ecef = frame.vector_to_ecef(vel[senders])
            for k, i in enumerate(senders.tolist()):
                rx, ts = stamp(t)
                pdu = EntityStatePdu(
                    entity_id=ids[i],
                    force_id=int(force[i]),
                    entity_type=FRIENDLY_TYPE if force[i] == FRIENDLY else OPPOSING_TYPE,
                    alt_entity_type=FRIENDLY_TYPE if force[i] == FRIENDLY else OPPOSING_TYPE,
                    velocity=tuple(vel_ecef[k].tolist()),
                    location=tuple(ecef[k].tolist()),
                    orientation=tuple(ori[k].tolist()),
                    appearance=int(app[i]),
                    dr_algorithm=2,
                    marking=make_marking(f"{'BLUE' if force[i] == FRIENDLY else 'RED'}-{i + 1}"),
                    version=version,
                    timestamp=ts,
                )
                packets.append(Packet(rx, encode_entity_state(pdu), i))
                counts["entity_state"] += 1
            last_t[senders] = t
            last_pos[senders] = pos[senders]
            last_vel[senders] = vel[senders]
            last_heading[senders] = heading[senders]
            last_app[senders] = app[senders]

        # small-arms fire: bursts every 0.6..1.2 s while in a firing phase
        firing = alive & (_WEAPON[ph] == WeaponState.FIRING)
        next_shot = np.where(firing & ~np.isfinite(next_shot), t, np.where(firing, next_shot, np.inf))
        for i in np.flatnonzero(firing & (next_shot <= t + 1e-9)).tolist():
            enemies = np.flatnonzero((force != force[i]) & alive)
            target = (
                int(enemies[np.argmin(np.linalg.norm(pos[enemies] - pos[i], axis=1))])
                if enemies.size
                else None
            )
            packets.append(_fire(frame, pos, force, ids, i, target, event_no, stamp(t), version))
            counts["fire"] += 1
            next_shot[i] = t + float(rng.uniform(0.6, 1.2))

        if step == kill_step and killer is not None and alive[victim]:
            packets.append(_fire(frame, pos, force, ids, killer, victim, event_no, stamp(t), version))
            counts["fire"] += 1
        if step == hit_step and alive[victim]:  # the round lands 0.2 s later
            packets.append(_detonation(frame, pos, force, ids, killer, victim, event_no, stamp(t), version))
            counts["detonation"] += 1
            alive[victim] = False  # the next step sends health fatal

        if vehicles and step % round(HEARTBEAT / DT) == 0:
            assert veh_pos is not None  # made when there are vehicles
            for k in range(vehicles):
                rx, ts = stamp(t)
                pdu = EntityStatePdu(
                    entity_id=EntityId(1, 3, 100 + k),
                    force_id=FRIENDLY,
                    entity_type=VEHICLE_TYPE,
                    alt_entity_type=VEHICLE_TYPE,
                    location=tuple(veh_pos[k].tolist()),
                    dr_algorithm=1,
                    marking=make_marking(f"HMMWV-{k + 1}"),
                    version=version,
                    timestamp=ts,
                )
                packets.append(Packet(rx, encode_entity_state(pdu), n + k))
                counts["vehicle_entity_state"] += 1

    packets.sort(key=lambda p: p.t)
    return Exercise(
        packets=packets,
        frame=frame,
        entities=ids,
        forces=force.tolist(),
        victim=victim,
        killer=killer,
        t_kill=t_kill,
        schedule=schedule,
        counts=counts,
    )


def _fire(
    frame: LocalFrame,
    pos: np.ndarray,
    force: np.ndarray,
    ids: list[EntityId],
    shooter: int,
    target: int | None,
    event_no: np.ndarray,
    stamp: tuple[float, int],
    version: int,
) -> Packet:
    event_no[shooter] += 1
    muzzle = pos[shooter] + np.array([0.0, 0.0, 1.4])
    aim = (
        (pos[target] + np.array([0.0, 0.0, 1.0]))
        if target is not None
        else muzzle + np.array([0.0, 300.0, 0.0])
    )
    d = aim - muzzle
    rng_m = float(np.linalg.norm(d))
    rx, ts = stamp
    pdu = FirePdu(
        shooter=ids[shooter],
        target=ids[target] if target is not None else EntityId(),
        event_id=EntityId(ids[shooter].site, ids[shooter].application, int(event_no[shooter])),
        location=tuple(frame.to_ecef(muzzle).tolist()),
        descriptor=MunitionDescriptor(MUNITION[int(force[shooter])], quantity=3, rate=600),
        velocity=tuple(frame.vector_to_ecef(d / max(rng_m, 1e-9) * 900.0).tolist()),
        range=rng_m,
        version=version,
        timestamp=ts,
    )
    return Packet(rx, encode_fire(pdu), shooter)


def _detonation(
    frame: LocalFrame,
    pos: np.ndarray,
    force: np.ndarray,
    ids: list[EntityId],
    shooter: int | None,
    target: int,
    event_no: np.ndarray,
    stamp: tuple[float, int],
    version: int,
) -> Packet:
    rx, ts = stamp
    side = int(force[shooter]) if shooter is not None else FRIENDLY
    pdu = DetonationPdu(
        shooter=ids[shooter] if shooter is not None else EntityId(),
        target=ids[target],
        event_id=EntityId(ids[shooter].site, ids[shooter].application, int(event_no[shooter]))
        if shooter is not None
        else EntityId(),
        velocity=(0.0, 0.0, 0.0),
        location=tuple(frame.to_ecef(pos[target] + np.array([0.0, 0.0, 1.2])).tolist()),
        descriptor=MunitionDescriptor(MUNITION[side], quantity=1, rate=0),
        entity_location=(0.1, 0.0, -1.2),
        result=DetonationResult.ENTITY_IMPACT,
        version=version,
        timestamp=ts,
    )
    return Packet(rx, encode_detonation(pdu), target if shooter is None else shooter)


def write_pcap(path: str | Path, exercise: Exercise, port: int = DEFAULT_PORT) -> int:
    """Write the packets as an Ethernet pcap of UDP broadcasts to ``port``; returns the packet count."""
    import dpkt

    with open(path, "wb") as f:
        writer = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
        for p in exercise.packets:
            writer.writepkt(udp_frame(p.payload, p.src, port), ts=p.t)
    return len(exercise.packets)


def udp_frame(payload: bytes, host: int, port: int = DEFAULT_PORT) -> bytes:
    """An Ethernet / IPv4 / UDP broadcast frame from host number ``host`` (10.1.x.y, 02:00:0a:01:x:y)."""
    import dpkt

    hi, lo = divmod(host + 1, 250)
    udp = dpkt.udp.UDP(sport=port, dport=port, data=payload)
    udp.ulen = len(udp)
    ip = dpkt.ip.IP(
        src=bytes([10, 1, hi, lo]),
        dst=b"\xff\xff\xff\xff",
        p=dpkt.ip.IP_PROTO_UDP,
        ttl=64,
        data=udp,
        id=(host * 7919) & 0xFFFF,
    )
    ip.len = len(ip)
    eth = dpkt.ethernet.Ethernet(
        src=bytes([2, 0, 10, 1, hi, lo]), dst=b"\xff" * 6, type=dpkt.ethernet.ETH_TYPE_IP, data=ip
    )
    return bytes(eth)
