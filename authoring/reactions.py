"""Reactions a soldier shows without changing posture: a firing recoil and a flinch (hit or near blast).

Each is a self-loop of its posture in the reaction graph (``POSTURE -> POSTURE``, the clip forwards): the
soldier leaves the posture, reaches a reaction key and comes back, so the clip begins and ends exactly in
the posture. A reaction key is the posture with some joints turned further (:class:`Reaction`: the
spine, the neck, the clavicles), the pelvis sunk a little, and the rifle kicked in its carry (back into the
shoulder, muzzle up) or left where it lies; it is solved so that the palms stay on the rifle and every part
of the body that touches the ground in the posture (heels, balls, toe tips, kneecaps, elbows, forearms)
stays where it is. The clip is recorded like a transition (:func:`authoring.transitions.
record_transition`: the body parts move to the key and back, feet and knees planted, then eased in and out
of the posture).

* **recoil** (standing, kneeling and prone fire, 0.3 s): the rifle kicks back, the shoulders and head
  rocking back with it (the chest turning and leaning back, the firing shoulder 4 cm; the butt stays in the
  shoulder pocket: kicked further, it went into the arm), and its muzzle climbs a few degrees; then it all
  settles back. Prone, the elbows stay planted on every frame and the rifle turns where the forearms let
  it. How much shows is judged by :mod:`authoring.quality_reactions`.
* **flinch** (every posture but dead, 0.65 s): a duck in 0.2 s — head down, shoulders up, back hunched,
  knees giving a little — held a moment, then back.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from authoring import ik
from authoring.motion import KeyPosture
from authoring.postures import DEG, POSTURES, RIFLE, SOLDIER, SPINE, arm, leg, spine_angles
from authoring.transitions import (
    ClipFrames,
    Step,
    TransitionSpec,
    carrier_globals,
    carry_of,
    record_transition,
)
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.model import Figure

SIDES = ("left", "right")
CONTACT_CM = 6.0  # a site this close to the ground in the posture touches it (elbow centres sit ~4 cm up)
RIFLE_FIT_ROUNDS = 4  # elbows held: solve, put the rifle where the planted arms hold it, solve again
BUTT_RIDE = 0.5  # ... its butt going this share of the way with the firing shoulder (1: 1.8 cm into the arm)
YAW_DEG = np.linspace(-12.0, 12.0, 241)  # ... turned about the vertical through the butt, one of these
LEG_CONTACTS = ("foot.heel", "foot.ball", "toes.distal", "lower_leg.knee")
ARM_CONTACTS = ("upper_arm.distal", "lower_arm.distal")  # elbow and wrist: a forearm on the ground


@dataclass(frozen=True)
class Reaction:
    """One reaction clip ``name`` of ``posture``: the reaction key is the posture plus ``spine`` (degrees of
    lateral bend, flexion, twist spread over the vertebrae) and ``joints`` (degrees added), the pelvis sunk
    ``drop`` cm, the rifle kicked ``kick`` (cm back along the barrel, degrees muzzle up, about the butt)
    in its carry, or left where it lies (``rifle_stays``)."""

    name: str
    posture: str
    kind: str  # "recoil" or "flinch"
    spine: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joints: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    drop: float = 0.0
    kick: tuple[float, float] = (0.0, 0.0)
    rifle_stays: bool = False
    slave_follows: bool = False  # slaves: their posture plus the master's change (authoring.slave_reactions)
    elbows_planted: bool = False  # the elbows on the ground held above the palms (prone: the rifle gives)
    elbows_held: bool = False  # ... and held there on every frame of the clip, not in the key alone
    timing: tuple[float, float, float] | None = None  # (s) to the key, held, back: TIMING[kind] if None
    slave_shoulders_kept: bool = False  # slaves: each acromion kept where the trunk takes it

    @property
    def key(self) -> str:
        return f"{self.kind.upper()}@{self.posture}"


# timing (s): to the key, held, back; the kick is fast, the settling slower
TIMING: dict[str, tuple[float, float, float]] = {"recoil": (0.07, 0.0, 0.23), "flinch": (0.2, 0.1, 0.35)}

_SHRUG = {"left_clavicle": (6.0, 0.0), "right_clavicle": (6.0, 0.0)}
_HEAD_DOWN = {"neck": (0.0, 20.0, 0.0), "head": (0.0, 6.0, 0.0)}
_DUCK = {**_HEAD_DOWN, **_SHRUG}
_RECOIL = {"neck": (0.0, -3.0, 0.0), "head": (0.0, -2.0, 0.0)}
# the firing shoulder kicked back: the chest turns and leans back with the rifle, the right clavicle going
# back further (session 19's 3 degrees of lean alone moved the shoulders 1.7 cm, a nod: now 4.3)
_KICK = {**_RECOIL, "right_clavicle": (0.0, -3.0)}
# prone flinch: the head down as far as the neck goes (20 degrees moved the nose 5.6-7.0 cm)
_PRONE_DUCK = {"neck": (0.0, 30.0, 0.0), "head": (0.0, 12.0, 0.0)}

REACTIONS: tuple[Reaction, ...] = (
    Reaction("stfire_recoil", "STAND_FIRE", "recoil", (0.0, -4.0, -4.0), _KICK, kick=(0.0, 4.0)),
    Reaction("kfire_recoil", "KNEEL_FIRE", "recoil", (0.0, -4.0, -4.0), _KICK, kick=(0.0, 4.0)),
    # prone, on the elbows: lying angled to the line of fire, 5 degrees of lateral bend rock the shoulders
    # back 3 cm with the kick, the head rides the stock back (4 cm) and the muzzle climbs 2.5 degrees about
    # the butt, reaching its peak in 0.12 s (the M16's left palm went 0.59 m/s in the first frames in 0.07).
    # The elbows stay planted on every frame (held by the palms alone they rose 4.4 cm: pronereact-s20) and
    # the rifle goes where the planted forearms hold it (_on_planted_arms); before (0.7 degree of bend, 1.4
    # of climb) the shoulders moved 0.4 cm and the muzzle 2.9, unseen
    Reaction(
        "prfire_recoil",
        "PRONE_FIRE",
        "recoil",
        (-5.0, 0.0, 0.0),
        {"neck": (0.0, -4.0, 0.0), "head": (0.0, -3.0, 0.0)},
        kick=(0.0, 2.5),
        timing=(0.12, 0.0, 0.23),
        slave_follows=True,
        elbows_planted=True,
        elbows_held=True,
        slave_shoulders_kept=True,
    ),
    Reaction("ststow_flinch", "STAND_STOWED", "flinch", (0.0, 12.0, 0.0), _DUCK, drop=6.0),
    Reaction("stfire_flinch", "STAND_FIRE", "flinch", (0.0, 10.0, 0.0), _DUCK, drop=6.0),
    Reaction("kstow_flinch", "KNEEL_STOWED", "flinch", (0.0, 8.0, -10.0), _HEAD_DOWN, kick=(0.0, -5.0)),
    Reaction("kfire_flinch", "KNEEL_FIRE", "flinch", (0.0, 8.0, 0.0), _DUCK),
    # on the forearms: the head goes down behind the rifle, which stays where it lies, and the shoulders
    # rock over (a shrug is undone by the elbows and palms held; flexing the spine dragged a forearm 6 cm)
    Reaction(
        "prstow_flinch",
        "PRONE_STOWED",
        "flinch",
        (-5.0, 0.0, 0.0),
        _PRONE_DUCK,
        rifle_stays=True,
        slave_follows=True,
        elbows_planted=True,
    ),
    # the cheek on the stock, the neck near its limit: the face turns down and away from the blast
    Reaction(
        "prfire_flinch",
        "PRONE_FIRE",
        "flinch",
        (-5.0, 0.0, 0.0),
        {"neck": (0.0, 28.0, -20.0)},
        rifle_stays=True,
        slave_follows=True,
        elbows_planted=True,
        slave_shoulders_kept=True,
    ),
    # the rifle cradled under the face: the head turns away and the shoulders roll over (ducking 20 degrees
    # put the M16's stock 3.6 cm into the face; session 19 turned the head alone, 6.4 cm)
    Reaction(
        "crawl_flinch", "CRAWL", "flinch", (5.0, 0.0, 0.0), {"neck": (0.0, 5.0, 32.0)}, rifle_stays=True
    ),
)
FOLLOWING: frozenset[str] = frozenset(r.name for r in REACTIONS if r.slave_follows)
# slaves whose rifle turns to their palms about the grip (the butt in the shoulder), not slid to them
RIFLE_TURNS: frozenset[str] = frozenset(r.name for r in REACTIONS if r.elbows_held)
# slaves whose clavicles keep the shoulders where the trunk takes them while the arms hold the rifle
SHOULDERS_KEPT: frozenset[str] = frozenset(r.name for r in REACTIONS if r.slave_shoulders_kept)
REACT_NODES: tuple[str, ...] = tuple(p for p in POSTURES if any(r.posture == p for r in REACTIONS))


def react_arcs() -> list[tuple[str, str, str, bool]]:
    """(from, to, clip, forward) of the reaction graph: one self-loop per clip."""
    return [(r.posture, r.posture, r.name, True) for r in REACTIONS]


def ground_contacts(kin: FigureKinematics, key: KeyPosture) -> tuple[list[str], list[str]]:
    """The limbs' sites that touch the ground in ``key``: ``(leg sites, arm sites)``."""
    g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])

    def low(names: tuple[str, ...]) -> list[str]:
        sites = [f"{s}_{n}" for s in SIDES for n in names]
        return [s for s in sites if g[kin.site_names.index(s), 1, 3] <= CONTACT_CM]

    return low(LEG_CONTACTS), low(ARM_CONTACTS)


def _kick(back: float, up: float, butt: np.ndarray) -> np.ndarray:
    """The rifle's own frame moved ``back`` cm towards the butt (+Z, the barrel points along -Z) and turned
    ``up`` degrees muzzle up about its lateral axis through the butt."""
    a = up * DEG
    rot = np.eye(4)
    rot[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    about = np.eye(4)
    about[:3, 3] = butt
    shift = np.eye(4)
    shift[2, 3] = back
    return shift @ about @ rot @ np.linalg.inv(about)


def reaction_key(kin: FigureKinematics, rkin: FigureKinematics, base: KeyPosture, r: Reaction) -> KeyPosture:
    """The key of ``r`` (see the module docstring) solved on the posture ``base``."""
    q0 = np.array(base.poses[SOLDIER], dtype=np.float64)
    sp = spine_angles(kin, *r.spine)
    for k, j in enumerate(SPINE):
        q0[kin.dof_slices[j]] += sp[k]
    for j, deg in r.joints.items():
        q0[kin.dof_slices[j]] += np.asarray(deg, np.float64) * DEG
    q0 = kin.clamp(q0)
    root = np.array(base.locations[SOLDIER], dtype=np.float64)
    root[1, 3] -= r.drop
    if r.rifle_stays:
        rifle = np.array(base.locations[RIFLE], dtype=np.float64)
    else:
        rifle = carrier_globals(kin, q0, root) @ carry_of(kin, base)
    butt = rkin.site_globals(np.zeros(0))[rkin.site_names.index("rifle.butt"), :3, 3]
    rifle = rifle @ _kick(*r.kick, butt)
    g = kin.site_globals(base.poses[SOLDIER], base.locations[SOLDIER])
    legs, arms = ground_contacts(kin, base)
    palms = [kin.site_names.index(f"{side}_palm.palmcenter") for side in SIDES]

    def held(rifle: np.ndarray) -> list[np.ndarray]:  # each palm where it holds the rifle in the posture
        return [rifle @ rigid_inverse(base.locations[RIFLE]) @ g[i] for i in palms]

    def solve(rifle: np.ndarray) -> np.ndarray:
        goals = []
        for side, t in zip(SIDES, held(rifle), strict=True):  # (so no change solves it exactly)
            goals.append(ik.Goal(f"{side}_palm.palmcenter", t[:3, 3], None, 1.0, 3, arm(side)))
            goals.append(ik.Goal(f"{side}_palm.palmcenter", None, t[:3, :3], 1.0, 1, arm(side), 8.0))
        for site in legs:
            i = kin.site_names.index(site)
            rot = g[i, :3, :3] if site.endswith("heel") else None
            goals.append(ik.Goal(site, g[i, :3, 3], rot, 1.0, 2, leg(site.split("_")[0])))
        for site in arms:
            side = site.split("_")[0]
            i = kin.site_names.index(site)
            planted = 4 if r.elbows_planted else 2  # above the palms' 3: the elbow stays, the rifle gives
            chain = (f"{side}_clavicle", f"{side}_shoulder")
            goals.append(ik.Goal(site, g[i, :3, 3], None, 1.0, planted, chain))
        return ik.solve(kin, q0, goals, root, iterations=200, rest_pose=q0, rest_gain=0.5)[0]

    q = solve(rifle)
    for _ in range(RIFLE_FIT_ROUNDS if r.elbows_held else 0):
        rifle = _on_planted_arms(kin, rifle, butt, kin.site_globals(q, root), base)
        q = solve(rifle)
    return KeyPosture(r.key, {SOLDIER: q, RIFLE: np.zeros(0)}, {SOLDIER: root, RIFLE: rifle})


def _on_planted_arms(
    kin: FigureKinematics, rifle: np.ndarray, butt: np.ndarray, now: np.ndarray, base: KeyPosture
) -> np.ndarray:
    """``rifle`` (the kicked carry's placement, world) put where the prone arms can hold it with the elbows
    planted, ``now`` the key's site globals so far: the butt rides ``BUTT_RIDE`` of the firing shoulder's
    move from the posture (carried with the chest it went 1.5 cm into the raised right upper arm), and the
    rifle turns about the vertical through it until the handguard lies as far from the planted left elbow
    as the palm does in the posture; its muzzle keeps its climb (slid or turned to the palms, it lost it)."""
    g = kin.site_globals(base.poses[SOLDIER], base.locations[SOLDIER])
    shoulder, palm, elbow = (
        kin.site_names.index(s)
        for s in ("right_clavicle.acromion", "left_palm.palmcenter", "left_upper_arm.distal")
    )
    at = (rifle @ np.append(butt, 1.0))[:3]
    rode = (base.locations[RIFLE] @ np.append(butt, 1.0))[:3] + BUTT_RIDE * (now[shoulder] - g[shoulder])[
        :3, 3
    ]
    rifle = _moved(rode - at) @ rifle
    hold = (rifle @ rigid_inverse(base.locations[RIFLE]) @ g[palm])[:3, 3] - rode
    reach = np.linalg.norm(g[palm, :3, 3] - g[elbow, :3, 3])
    yaws = Rotation.from_euler("y", YAW_DEG[:, None], degrees=True)
    miss = np.abs(np.linalg.norm(yaws.apply(hold) + rode - g[elbow, :3, 3], axis=1) - reach)
    turn = np.eye(4)
    turn[:3, :3] = yaws[int(np.argmin(miss + 0.01 * np.radians(np.abs(YAW_DEG))))].as_matrix()
    return _moved(rode) @ turn @ _moved(-rode) @ rifle


def _moved(by: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = by
    return out


def reaction_spec(r: Reaction, legs: list[str], arms: Sequence[str] = ()) -> TransitionSpec:
    """The primitive motions: every body part and the rifle to the key and back; the feet and kneecaps on
    the ground planted. The forearms on the ground stay by interpolation between two poses that have them
    in the same place (IK holding them too over-constrained the arms: the wrists shook)."""
    go, hold, back = r.timing or TIMING[r.kind]
    t = go + hold + back
    steps: list[Step] = []
    for part in ("root", "legs", "spine", "arms", "rifle"):
        steps += [Step(part, r.key, 0.0, go), Step(part, r.posture, go + hold, back)]
    lag = 0.3 * go  # the head follows the shoulders
    steps += [Step("head", r.key, lag, go), Step("head", r.posture, go + hold + lag, back - lag)]
    for side in SIDES:
        if any(s.startswith(f"{side}_foot") or s.startswith(f"{side}_toes") for s in legs):
            steps.append(Step(f"{side}_foot", r.posture, 0.0, t))
        if f"{side}_lower_leg.knee" in legs:
            steps.append(Step(f"{side}_knee", r.posture, 0.0, t))
    planted = tuple(arms) if r.elbows_held else ()
    return TransitionSpec(r.name, r.posture, r.posture, round(t, 6), tuple(steps), planted=planted)


def record_reaction(
    r: Reaction, keys: Mapping[str, KeyPosture], figures: tuple[Figure, Figure]
) -> ClipFrames:
    """Solve the reaction key on its posture and record the clip."""
    kin, rkin = FigureKinematics(figures[0]), FigureKinematics(figures[1])
    base = keys[r.posture]
    legs, arms = ground_contacts(kin, base)
    key = reaction_key(kin, rkin, base, r)
    return record_transition(reaction_spec(r, legs, arms), {**keys, r.key: key}, figures)


def reaction_clips() -> dict[str, Callable[[Any], tuple[ClipFrames, None, None]]]:
    """Build jobs: clip name -> recorder taking the build context."""

    def make(r: Reaction) -> Callable[[Any], tuple[ClipFrames, None, None]]:
        return lambda ctx: (record_reaction(r, ctx.keys, (ctx.soldier, ctx.rifle)), None, None)

    return {r.name: make(r) for r in REACTIONS}
