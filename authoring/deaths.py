"""The seven deaths, simulated: a MuJoCo ragdoll (:mod:`authoring.ragdoll`) falls from its posture.

Each death starts exactly in its posture (frame 0 is the graph's key posture, at rest) with the muscles
holding that pose: joint springs toward it, and gravity fed forward on the joints of the limbs off the ground
and on the held rifle (:func:`_carried_dofs`), so nothing sags in the first frames. A posture that dips into
the ground (by a few millimetres) starts on a ground lowered that far, which rises to 0 as the body settles
(:data:`GROUND_RISE`). Then:

1. **the hit**: a force on the upper torso, ramped up over :attr:`DeathSpec.ramp` and down again (so every
   part starts moving slowly), pushing the body the way it falls (forward standing, straight to the side
   kneeling — at 100 N: harder or forward, he rolled over his back with his legs up — down lying);
2. **the slump**: PD control (the springs) toward a slumped shape — the ``SLUMP`` key standing (the knees
   buckle), the spine and head of ``SLUMP`` kneeling (the legs stay as they are: no kick), the ``DEAD`` key's
   head lying — at half strength by :attr:`DeathSpec.slump_time`, then toward a limp shape (the ``DEAD``
   key's, legs straight and feet pointed, :func:`limp_pose`) fading to a faint tone by
   :attr:`DeathSpec.fade`; the knees give way at once (:data:`KNEES_GIVE_WAY`: held, they swung the shins up
   as the body pitched forward) but stay damped harder until he is down (:attr:`DeathSpec.knee_damping`:
   limp, they flung the shins up as he hit the ground and dragged the feet) — standing at the trigger, his
   hips, waist and lower back too (:attr:`DeathSpec.hip_damping`: landing on his chest, the legs whipped up
   over it, shins straight up and the feet 81 cm over the pelvis, issue 14) and his knees straighten from
   :attr:`DeathSpec.knee_straighten` on — arms, neck and head keep no
   tone (:data:`LOOSE`; :attr:`DeathSpec.arm_tone`: a faint one, so a soldier on his side lays his arm
   down instead of leaving it up in the air); dead joints stay damped;
   once he is down (after :attr:`DeathSpec.fade`, over :data:`KNEE_STRAIGHTEN`) the legs roll outward at
   the hips and the feet turn (:data:`ROLLED_LEGS`, :data:`HIP_ROLL`, at :data:`LEG_TONE`: the feet lie on
   their inner sides, heels low) — a soldier who may come to rest on his side (:attr:`DeathSpec.sideways`,
   the kneeling deaths) only as far as he lies on his front (:func:`_face_down`; on his side, the toned
   hip held the upper leg up in the air) — and a standing death's knees straighten (:data:`KNEE_TONE`:
   bent, they left him bottom-up on his knees); a crawler keeps his arms propped and his legs drawn a
   while (:attr:`DeathSpec.kept`: limp, his chest dropped onto his forearms and they slid 5 cm);
3. **the rifle is let go** at :attr:`DeathSpec.release` (the welds to the palms are switched off; the frame
   is the channelset's ``release_frame``) and flung clear of the falling body (:data:`TOSS`; a crawler's,
   cradled across his forearms, forward ahead of his face: :attr:`DeathSpec.toss_to`); a death may let
   go gently (:attr:`DeathSpec.letgo_clear`, :attr:`DeathSpec.letgo_fingers`,
   :attr:`DeathSpec.letgo_blend`: the rifle pushed out of the forearm it lay in, into the fingers, and the
   arms' springs aimed at the slump flung the hand 12-17 cm in a frame); it collides
   with the arms and head it touched in the start pose too (:class:`~authoring.ragdoll.Ragdoll`), and a
   rifle the posture dipped into the ground rises out of it (:data:`GROUND_RISE`); ststow2dead's falls
   again on its own from where the hands let go, the body keeping its fall (:attr:`DeathSpec.drop_toss`,
   :mod:`authoring.rifle_drop`: flung away from the fall, it came to rest by his boots);
4. **the body settles and sleeps**: once the muscle program is over (:attr:`DeathSpec.fade`) and the pelvis
   is slower than :data:`SLEEP_SPEED`, the joints hold the shape they have (the springs' references frozen
   there) and are damped ever harder (:data:`SLEEP_DAMPING`): still-acting muscles (the legs rolling
   outward) dragged a lying soldier's feet along the ground, and soft contacts let resting parts creep;
   recording (60 fps) stops once every body has been still (:data:`REST_SPEED`) for
   :data:`REST_SECONDS` (or after :data:`MAX_SECONDS`); the clip keeps those still frames, so the last frame
   is at rest;
5. **the skid is taken out**: the ragdoll's parts slide over the ground as he falls, and the recorded frames
   are moved back by their drift (:func:`authoring.planted.plant`); kfire2dead's thigh, on which he lands,
   skids in the physics itself (its contact flickers), and the mean drift shared that out to the others:
   its frames are moved so that each part's worst slide is least instead (:attr:`DeathSpec.plant_worst`,
   :func:`authoring.planted.plant_least_worst`);
6. **a face-down body goes limp**: a short kinematic settle drops the head and turns the legs out (heels
   lower) where that slides nothing on the ground (:func:`authoring.dead_settle.settle`; stfire2dead's
   feet are first held where they leave the ground as his knees land, :attr:`DeathSpec.feet_held`,
   :mod:`authoring.feet_held`: his shins swung up 45 degrees, and his legs laid from then on,
   :attr:`DeathSpec.legs_land_from`: laid once he was down, lifted to turn out, they rose 6.9 cm) — a
   prone death left propped on its elbows (:attr:`DeathSpec.propped`) brings its chest down too, the arms
   laid anew and lifted clear of the ground while they move (:mod:`authoring.dead_prone`; the prone deaths
   from :attr:`DeathSpec.lowered_at` on, as the hit ends, the physics' tail left out but the rifle's: after
   it, they lay propped on their elbows, head up, until 3.4 and 1.7 s), a crawler's pelvis and
   belly first, turned down about his thighs (:attr:`DeathSpec.sunk`, :mod:`authoring.dead_crawl`), and its
   feet go slack, the ankles pointing into their passive range before the legs roll, the shins on the
   ground (:attr:`DeathSpec.slack_feet`: he lay on his toes, heels 16-21 cm up); a
   body on its back (:attr:`DeathSpec.arms_fall`) lets its arms fall to the ground the same way, as it
   lands, over the physics' last frames (a faint arm tone in the physics made the DI slaves' feet jump and
   slide, branch ``legsup14-kfire``; after the physics, the arm hung in the air 1.5 s after he lay still).
7. **the limbs stay where they land** (:attr:`DeathSpec.pinned`): hands, forearms, feet and the head on the
   ground are held where they touched down by re-solving the limb (:func:`authoring.contact_pin.pin_frames`;
   the first and last frames unchanged; the standing deaths, kstow2dead and the two prone deaths: pinned,
   kfire2dead's DI slave's kneeling knee slid 1.3 cm more; a prone death's forearms are held in their turn
   too, from the rifle's release on: the limp arms pivoted under the slumping body, 5-6 cm). kstow2dead is
   pinned before its arms fall (pinned after, the still frames appended moved the feet's pins: a foot slid
   1.8 cm more); each arm falls to its own side along a way that lifts no part of it
   (:mod:`authoring.dead_arms`; its left forearm lay raised over the chest at 23.5 cm). ststow2dead's knee
   on the ground is held before (:attr:`DeathSpec.knees_held`, :mod:`authoring.knee_hold`: the root follows
   it, the legs keep their feet; it slid 10.3 cm, the hip pitching further than the thigh reaches); the
   kneeling deaths' knees (tipping sideways, they roll) and the thighs and trunk still skid: held so, a
   kneeling soldier's tucked foot slid 9-10 cm. Making every part stick in the physics instead
   (MuJoCo connect constraints to mocap points following a part's lowest node, released 2.5 cm up) held
   every contact under 1.5 cm but changed the falls: from the start, the standing soldier sat down
   backwards; from touchdown, he ended bottom-up on his knees (pelvis 24 cm up) and the kneeling ones
   on their sides with an arm up (52-60 cm): the muscle program that lays a body out needs its knees to
   slide (issue 14, branch ``dfall14``).

8. **a kneeling soldier's legs roll off the ground** (:attr:`DeathSpec.legs_lift`, last): a foot or knee
   that would skid more than a centimetre lifts clearly off the ground until it comes to rest, carried by
   the leg's own joints (:mod:`authoring.leg_lift`; kstow2dead's and kfire2dead's feet slid 4.8-4.9 cm,
   their kneeling knees 5.9-6.1); kstow2dead's legs' change by the pin and the lift is smoothed where it
   flicks (:attr:`DeathSpec.legs_eased`, :func:`authoring.leg_lift.eased_legs`: the right foot's pin let its
   stretched knee go 19 degrees in one frame); then kfire2dead, whose trunk still spins on the ground as he
   lands (belly 3.3, chest 3.7 cm), and kstow2dead (its left thigh 4.5, chest 4.5 cm) are shifted and turned
   about the vertical as a whole so that each part's worst slide is least (:attr:`DeathSpec.turn_worst`,
   :func:`authoring.planted.least_worst_turned`: 5 degrees at most);

9. **prfire2dead leaves its posture from rest** (:attr:`DeathSpec.start_ease`, last): the finished clip
   is retimed so that it starts from standstill (:func:`authoring.easing.eased_in`, lengthened by half the
   ramp): its first frames moved at 0.46 m/s (a toe, the hip, as the hit ramped in) and its DI/M16 slaves'
   at 0.57-0.67 m/s, over the check's end_speed (:data:`PRONE_START_EASE`).
10. **the prone deaths' rifle falls again** (:attr:`DeathSpec.rifle_resettle`, last): steps 5-8 moved his
    arms from under the rifle that leaned on them and left it standing on its magazine or muzzle, butt
    19-36 cm up; from the frame the ragdoll laid it there it is simulated again among the finished body
    (:mod:`authoring.rifle_settle`), tips over and lies on the ground (overhang 20.8-26.8 -> 0 cm).

**No pop at DEAD — option (b) of issue 14.** Real physics does not land seven falls in one pose, so each
death ends in its own variant of the DEAD posture, a node ``DEAD@<start>`` of the static posture graph
(:func:`dead_node`), and getting up from it replays that very death backwards (:data:`GET_UP_SECONDS`).
The server treats ``NAME@variant`` as posture ``NAME``.

MuJoCo is deterministic for one build (no randomness anywhere, fixed step), so a rebuild gives the same
bytes on the same machine.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from authoring import dead_crawl, dead_settle, prone_roll, rifle_settle
from authoring.body_parts import DIRECTIONS
from authoring.contact_pin import pin_frames
from authoring.death_specs import DEAD as DEAD
from authoring.death_specs import DEATHS as DEATHS
from authoring.death_specs import MAX_SECONDS as MAX_SECONDS
from authoring.death_specs import PRONE_START_EASE as PRONE_START_EASE
from authoring.death_specs import PRSTOW_HEAD_HELD as PRSTOW_HEAD_HELD
from authoring.death_specs import REST_SECONDS, REST_SPEED, TOSS_SECONDS
from authoring.death_specs import STFIRE_TOSS as STFIRE_TOSS
from authoring.death_specs import TOSS as TOSS
from authoring.death_specs import DeathSpec as DeathSpec
from authoring.death_specs import dead_node as dead_node
from authoring.death_specs import death_specs as death_specs
from authoring.easing import eased_in
from authoring.feet_held import held_feet
from authoring.grounded import grounded_frames
from authoring.knee_hold import hold_knees
from authoring.leg_lift import eased_legs, lifted
from authoring.letgo_ease import eased_letgo
from authoring.motion import KeyPosture
from authoring.passive_range import passive_figure
from authoring.planted import WORST_DIRECTIONS, least_worst_turned, plant, plant_least_worst
from authoring.postures import RIFLE, SOLDIER
from authoring.quality_frames import FigureSet
from authoring.quality_rest import DOWN_CM
from authoring.rifle_drop import LetGo, dropped, let_go
from authoring.transitions import FPS, ClipFrames
from peabody.fk import FigureKinematics
from peabody.model import Figure

GROUND_RISE = 0.4  # s: a ground lowered under a posture dipping into it rises to 0
SLEEP_SPEED = 0.15  # m/s: once the muscles are done and the pelvis is this slow, the body goes to sleep
SLEEP_DAMPING = 20.0  # asleep: the joints hold the shape they have, damped this many times harder
SLEEP_RAMP = 0.2  # s, over which the damping rises
SLEEP_FEET = 0.15  # m: and both feet (centres of mass) this low (asleep, shins up stayed up)
KEPT_FADE = 0.4  # s: a kept joint lets go of the start shape this slowly
GET_UP_SECONDS = 10.0  # DEAD@x -> its start posture: the death played backwards (seed 002 Figure 7: 10 s)


SLUMP = "SLUMP"  # the in-between key of a body crumpling onto its knees (authoring.postures)
UPPER = ("waist", "neck", "head")  # with the vertebrae: what slumps of a kneeling soldier
HEAD = ("neck", "head")


@dataclass(frozen=True)
class DeathClip:
    frames: ClipFrames
    release_frame: int


@dataclass(frozen=True)
class Fall:
    """The ragdoll's recording (:func:`fall`): poses, roots and rifles per frame, the frame the hands let go
    (None: never), the rifle as they let go and the pelvis at the start (the frame the tosses are in)."""

    recording: tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]
    release: int | None
    letgo: LetGo | None
    pelvis: np.ndarray


# muscle strength (N m / rad) of holding the posture, by joint; the rest gets DEFAULT_GAIN
GAINS: dict[str, float] = {
    "hip": 900.0,
    "knee": 700.0,
    "ankle": 300.0,
    "toes": 40.0,
    "waist": 900.0,
    "neck": 120.0,
    "head": 60.0,
    "clavicle": 400.0,
    "shoulder": 400.0,
    "elbow": 250.0,
    "wrist": 100.0,
}
SPINE_GAIN = 1500.0  # vertebrae: stiff throughout (a dead back bends, mostly at the hips and waist)
SPINE_TONE = 0.25  # the fraction of the vertebrae's gain kept when dead
LOOSE = ("clavicle", "shoulder", "elbow", "wrist", "neck", "head")  # no tone left: gravity lays them down
TONE = 0.10  # the fraction of the muscles' gain kept when dead (toward the DEAD key's shape)
LEG_TONE = 0.3  # hips, ankles: enough to roll the legs outward and lay the feet on their inner sides
LEGS = ("hip", "ankle")
KNEE_TONE = 0.3  # a standing death's knees straighten with this once he is down (bent, they held him
KNEE_STRAIGHTEN = 1.0  # s: bottom-up on his knees), slowly after DeathSpec.fade (quickly, the shins kick up)
KNEE_DAMPING_FADE = 0.3  # s: after DeathSpec.fade the knees' extra damping fades this fast
KNEES_GIVE_WAY = 0.15  # s: after the slump the knees go limp this fast
FALL_STIFF = ("hip", "waist", "vl")  # the joints DeathSpec.hip_damping damps (vl: the lumbar vertebrae)
GRIP = ("clavicle", "shoulder", "elbow", "wrist")  # the joints DeathSpec.letgo_blend eases at the let-go
DAMPING = 0.1  # joint damping = DAMPING * gain (s), at least MIN_DAMPING
MIN_DAMPING = 4.0


def _gain(joint: str) -> float:
    if joint.startswith(("v", "vl", "vt")) and joint[1:2] in ("l", "t"):
        return SPINE_GAIN
    for key, g in GAINS.items():
        if joint.endswith(key):
            return g
    return 60.0


# degrees: the legs' tone pulls them straight and the feet pointed (heels low on the ground)
LIMP_LEGS = {"knee": (0.0,), "ankle": (-50.0, 0.0)}
# degrees: once he is down, the legs roll outward at the hips (external rotation) and the feet evert and
# point, so a body on its front lies with its feet on their inner sides and its heels low, as real bodies
# lie
ROLLED_LEGS = {"knee": (5.0,), "ankle": (-50.0, 30.0)}
HIP_ROLL = -45.0  # the hips' third DOF (about the thigh); negative turns the toes out
# degrees: a death that rolls its legs sooner (DeathSpec.legs_roll) rolls them into the passive range
PASSIVE_ROLL = {"ankle": -60.0, "hip": -60.0}
FACE_DOWN = (0.2, 0.6)  # the pelvis' front pointing down this much (cosine): from on his side to on his front


def limp_pose(kin, dead: np.ndarray, rolled: bool = False, passive: bool = False) -> np.ndarray:
    """The shape the faint tone of a dead body pulls toward: the DEAD key's, legs straight and feet pointed
    (so a body on its front lies with its heels low); ``rolled``: the legs rolled outward too (``passive``:
    into the passive range, :data:`PASSIVE_ROLL`)."""
    q = np.array(dead, dtype=np.float64)
    for side in ("left", "right"):
        for j, deg in (ROLLED_LEGS if rolled else LIMP_LEGS).items():
            q[kin.dof_slices[f"{side}_{j}"]] = np.radians(deg)
        if rolled:
            hip = PASSIVE_ROLL["hip"] if passive else HIP_ROLL
            q[kin.dof_slices[f"{side}_hip"].stop - 1] = np.radians(hip)
        if rolled and passive:
            q[kin.dof_slices[f"{side}_ankle"].start] = np.radians(PASSIVE_ROLL["ankle"])
    return q


def slump_pose(kin, spec: DeathSpec, keys: Mapping[str, KeyPosture]) -> np.ndarray:
    """The shape the slump's muscles pull toward: the SLUMP key (standing), or the start posture with the
    spine and head slumped (kneeling: the legs stay as they are, so nothing kicks) or the head dropped
    (lying)."""
    start = np.array(keys[spec.start].poses[SOLDIER], dtype=np.float64)
    if spec.slump == "all":
        return np.array(keys[SLUMP].poses[SOLDIER], dtype=np.float64)
    src = keys[SLUMP if spec.slump == "upper" else DEAD].poses[SOLDIER]
    parts = UPPER if spec.slump == "upper" else HEAD
    for name, sl in kin.dof_slices.items():
        if name in parts or (spec.slump == "upper" and _gain(name) == SPINE_GAIN):
            start[sl] = src[sl]
    return start


def _carried_dofs(doll, key: KeyPosture) -> np.ndarray:
    """``qvel`` addresses of the hinges whose limb (the child segment and everything beyond it) has no
    segment within 1 cm of the ground in the posture ``key``: the ones muscles hold up against gravity."""
    from authoring.postures import segment_heights

    m = doll.model
    heights = segment_heights(doll.kin, key.poses[SOLDIER], key.locations[SOLDIER])
    grounded = {m.body(name).id for name, h in heights.items() if float(h) < 1.0}
    beyond: dict[int, set[int]] = {b: {b} for b in range(m.nbody)}
    for b in range(m.nbody - 1, 0, -1):  # children come after their parents
        beyond[int(m.body_parentid[b])] |= beyond[b]
    return np.array(
        [int(d) for d in doll.map.qvel if not beyond[int(m.dof_bodyid[d])] & grounded], dtype=np.intp
    )


def _face_down(doll) -> float:
    """How much the ragdoll lies on its front: 1 when the pelvis' front (its -Z) points down more than
    :data:`FACE_DOWN` (cosine), 0 on his side or back, smooth in between."""
    down = float(doll.body_global("lower_torso")[1, 2])  # the front's downward component
    return _smoothstep((down - FACE_DOWN[0]) / (FACE_DOWN[1] - FACE_DOWN[0]))


def _straightened(spec: DeathSpec, t: float, rolled: float) -> float:
    """How far a standing death's knees have straightened at ``t``: as far as the legs have rolled outward
    (``rolled``), or from the spec's own :attr:`DeathSpec.knee_straighten` on."""
    if spec.knee_straighten is None:
        return rolled
    return _smoothstep((t - spec.knee_straighten) / KNEE_STRAIGHTEN)


def _toss_direction(spec: DeathSpec, pelvis: np.ndarray, right: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """Where the let-go rifle is flung (figure frame, unit): :attr:`DeathSpec.toss_to` in the pelvis' frame,
    or to the side (the heading frame's left), away from the fall ``hit``, horizontal."""
    if spec.toss_to is not None:
        away = pelvis[:3, :3] @ np.array(spec.toss_to)
        return away / np.linalg.norm(away)
    away = -right - 0.3 * hit
    away[1] = 0.0
    return away / (np.linalg.norm(away) or 1.0)


def _keeper(spec: DeathSpec, names: list[str], hold_ref: np.ndarray) -> Callable[..., tuple]:
    """``(t, ref, gain) -> (ref, gain)``: the :attr:`DeathSpec.kept` joints pulled toward the start posture
    at :attr:`DeathSpec.kept_tone` until their time, letting go over :data:`KEPT_FADE` (a crawler's arms
    stay propped, so his forearms do not skid as he slumps; the settle lays his chest down,
    :mod:`authoring.dead_prone`); the others as they are."""
    if not spec.kept:
        return lambda t, ref, g: (ref, g)
    until = np.array([u for _, u in spec.kept] + [-np.inf])  # the last group: not kept
    group = np.array([next((i for i, (j, _) in enumerate(spec.kept) if n.endswith(j)), len(spec.kept))
                      for n in names])  # fmt: skip

    def keep(t: float, ref: np.ndarray, g: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = (1.0 - np.array([_smoothstep(u) for u in (t - until) / KEPT_FADE]))[group]
        return ref + w * (hold_ref - ref), g + w * (spec.kept_tone - g)

    return keep


class _Grip:
    """The arms' spring references as the hands let go (:attr:`DeathSpec.letgo_blend`): aimed where the arms
    are held at the let-go, turning to the muscle program's over the blend. The welds to the rifle held the
    arms against springs already pulling toward the slump; dropped in one step, the hand jumped 12-17 cm in
    the next frame."""

    def __init__(self, spec: DeathSpec, names: list[str]) -> None:
        self.seconds = spec.letgo_blend
        self.arms = np.array([n.endswith(GRIP) for n in names])
        self.held: tuple[float, np.ndarray] | None = None  # when the hands let go, and the joints then

    def let_go(self, t: float, qpos: np.ndarray) -> None:
        """The hands let go at ``t`` with the joints at ``qpos``."""
        if self.seconds > 0.0:
            self.held = (t, qpos.copy())

    def __call__(self, t: float, ref: np.ndarray) -> np.ndarray:
        if self.held is None:
            return ref
        since, q = self.held
        w = _smoothstep((t - since) / self.seconds)
        return np.where(self.arms, q + w * (ref - q), ref)


def _smoothstep(u: float) -> float:
    u = min(1.0, max(0.0, u))
    return u * u * (3.0 - 2.0 * u)


def simulate(spec: DeathSpec, keys: Mapping[str, KeyPosture], figures: tuple[Figure, Figure]) -> DeathClip:
    """Record one death (see the module docstring)."""
    rifle = figures[1]
    fallen = fall(spec, keys, figures)
    release = int(fallen.release if fallen.release is not None else len(fallen.recording[0]) - 1)
    _dropped_alone(spec, rifle, fallen.pelvis, fallen.letgo, release, fallen.recording)
    poses, roots, rifles = (np.array(v) for v in fallen.recording)
    recorded = ClipFrames(poses, roots, rifles, FPS)
    clip = _eased(spec, DeathClip(_after_physics(spec, recorded, figures, release), release))
    return _rifle_resettled(spec, _grounded(spec, clip, figures[0]), figures)


def fall(
    spec: DeathSpec,
    keys: Mapping[str, KeyPosture],
    figures: tuple[Figure, Figure],
    seconds: float = MAX_SECONDS,
) -> Fall:
    """The ragdoll's fall of one death (steps 1-4 of the module docstring), at most ``seconds`` long."""
    from authoring.ragdoll import Ragdoll

    soldier, rifle = figures
    first, dead = keys[spec.start], keys[DEAD]
    doll = Ragdoll(soldier, rifle, first.poses[SOLDIER], first.locations[SOLDIER], first.locations[RIFLE])
    model, data, jm = doll.model, doll.data, doll.map
    joint_of = {i: name for name, sl in doll.kin.dof_slices.items() for i in range(sl.start, sl.stop)}
    names = [joint_of[int(i)] for i in jm.dof]
    gain = np.array([_gain(n) for n in names])
    spine = np.array([_gain(n) == SPINE_GAIN for n in names])
    hold_ref = first.poses[SOLDIER][jm.dof]
    lo, hi = doll.kin.lower[jm.dof], doll.kin.upper[jm.dof]
    dead_ref = np.clip(limp_pose(doll.kin, dead.poses[SOLDIER])[jm.dof], lo, hi)
    rolled = limp_pose(doll.kin, dead.poses[SOLDIER], rolled=True, passive=spec.legs_roll is not None)
    rolled_ref = np.clip(rolled[jm.dof], lo, hi)
    slump_ref = np.clip(slump_pose(doll.kin, spec, keys)[jm.dof], lo, hi)
    knees = np.array([n.endswith("knee") for n in names])
    trunk = np.array([n.endswith(FALL_STIFF) or n.startswith(FALL_STIFF) for n in names])
    loose = [n.endswith(LOOSE) for n in names]
    legs = np.array([n.endswith(LEGS) for n in names])
    arms = np.array([n.endswith(("clavicle", "shoulder", "elbow")) for n in names])
    keep = _keeper(spec, names, hold_ref)
    grip = _Grip(spec, names)
    tone = np.where(spine, SPINE_TONE, np.where(loose, np.where(arms, spec.arm_tone, 0.0), TONE))
    # once he is down the legs roll outward (hips, ankles) and, standing deaths only, the knees straighten
    # (straightened, a fallen kneeling soldier's knees drag his feet along the ground)
    settle = np.where(legs, LEG_TONE - TONE, 0.0)
    straighten = (KNEE_TONE - TONE) * knees * (spec.slump == "all")

    # the hit's direction in the world (MuJoCo frame): the pelvis' heading, horizontal
    pelvis = doll.body_global("lower_torso")
    fwd = -pelvis[:3, 2].copy()
    fwd[1] = 0.0
    fwd /= np.linalg.norm(fwd) or 1.0
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    dx, dy, dz = spec.direction
    d_fig = dx * right + dy * np.array([0.0, 1.0, 0.0]) - dz * fwd
    d_fig /= np.linalg.norm(d_fig)
    d_mj = np.array([d_fig[0], -d_fig[2], d_fig[1]])  # figure (x, y, z) -> MuJoCo (x, -z, y)
    torso = model.body("upper_torso").id
    hips = model.body("lower_torso").id
    feet = [model.body(f"{side}_foot").id for side in ("left", "right")]
    gun = model.body("rifle").id
    away = _toss_direction(spec, pelvis, right, d_fig)
    toss_mj = spec.toss * np.array([away[0], -away[2], away[1]])

    asleep: list[tuple[float, np.ndarray]] = []  # when he fell asleep, his damping then (:data:`SLEEP_SPEED`)

    def set_muscles(t: float) -> None:
        if asleep:  # the shape he lies in is held, the joints damped ever harder: nothing creeps
            since, damping = asleep[0]
            model.dof_damping[jm.qvel] = damping * (
                1.0 + (SLEEP_DAMPING - 1.0) * _smoothstep((t - since) / SLEEP_RAMP)
            )
            return
        g: float | np.ndarray  # one gain, or one per joint once the knees give way on their own
        if t < spec.slump_time:  # holding -> slumping
            u = _smoothstep(t / spec.slump_time)
            ref = hold_ref + u * (slump_ref - hold_ref)
            g = 1.0 + u * (spec.slump_gain - 1.0)
        else:  # slumped -> limp; the knees give way at once (held, they swing the shins up as he pitches)
            u = _smoothstep((t - spec.slump_time) / (spec.fade - spec.slump_time))
            uk = _smoothstep((t - spec.slump_time) / KNEES_GIVE_WAY)
            ref = slump_ref + u * (dead_ref - slump_ref)
            g = spec.slump_gain + np.where(knees, uk, u) * (tone - spec.slump_gain)
            us = _smoothstep((t - spec.fade) / KNEE_STRAIGHTEN)
            ur = us if spec.legs_roll is None else _smoothstep((t - spec.fade) / spec.legs_roll)
            if us > 0.0 and spec.sideways:  # only on his front (on his side, the upper leg would rise)
                front = _face_down(doll)
                us, ur = us * front, ur * front
            if us > 0.0:
                ref = ref + np.where(legs, ur, us) * (rolled_ref - dead_ref)
                g = g + settle * ur
            g = g + straighten * _straightened(spec, t, us)
        ref, g = keep(t, ref, g)
        ref = grip(t, ref)
        model.jnt_stiffness[jm.jnt] = gain * g
        model.qpos_spring[jm.qpos] = ref
        damping = np.maximum(MIN_DAMPING, DAMPING * gain * np.maximum(g, 0.3))
        # until he is down the knees are damped harder (limp, they flung the shins up as he hit the ground)
        fall = 1.0 - _smoothstep((t - spec.fade) / KNEE_DAMPING_FADE)
        extra = np.where(knees, spec.knee_damping - 1.0, np.where(trunk, spec.hip_damping - 1.0, 0.0))
        model.dof_damping[jm.qvel] = damping * (1.0 + extra * fall)

    # the living soldier's muscles carry his limbs and the rifle: gravity fed forward on every joint whose
    # limb does not rest on the ground (and an upward pull on the held rifle), fading as he slumps, so the
    # first frames start from rest instead of sagging into the joint springs
    carried = _carried_dofs(doll, first)
    rifle_weight = model.body_mass[gun] * -model.opt.gravity

    def carry(t: float) -> float:
        return 1.0 - _smoothstep(t / spec.slump_time)

    def hit(t: float) -> float:
        if t < spec.ramp:
            return _smoothstep(t / spec.ramp)
        t -= spec.ramp + spec.hold
        return 1.0 - _smoothstep(t / spec.ramp) if t > 0 else 1.0

    steps = round(1.0 / (FPS * model.opt.timestep))
    dt = steps * model.opt.timestep
    poses, roots, rifles = [doll.pose()], [doll.root_location()], [doll.rifle_location()]
    com = data.xipos.copy()
    still = 0
    release_frame = None
    letgo: LetGo | None = None  # the rifle as the hands let go of it
    rifle_ground0 = 0.0
    ground0 = min(0.0, doll.lowest())  # a posture dipping into the ground starts on a ground that low
    t = 0.0
    while t < seconds:
        for k in range(steps):
            ts = data.time
            set_muscles(ts)
            c = carry(ts)
            data.qfrc_applied[carried] = c * data.qfrc_bias[carried]
            held = release_frame is None
            data.xfrc_applied[torso, :3] = spec.force * hit(ts) * d_mj
            tossing = release_frame is not None and ts < spec.release + TOSS_SECONDS
            data.xfrc_applied[gun, :3] = toss_mj if tossing else (c * rifle_weight if held else 0.0)
            doll.set_ground(ground0 * (1.0 - _smoothstep(ts / GROUND_RISE)))
            if release_frame is None and ts >= spec.release:
                doll.release(push_out=not spec.letgo_clear, fingers=not spec.letgo_fingers)
                release_frame = len(poses)
                rifle_ground0 = min(0.0, doll.rifle_lowest())
                letgo = let_go(doll, steps - k)
                grip.let_go(ts, data.qpos[jm.qpos])
                set_muscles(ts)  # (the same as before the let-go unless the grip blends)
            if release_frame is not None:  # a rifle the posture dipped into the ground is raised out of it
                doll.set_rifle_ground(rifle_ground0 * (1.0 - _smoothstep((ts - spec.release) / GROUND_RISE)))
            doll.step()
        t += dt
        poses.append(doll.pose())
        roots.append(doll.root_location())
        rifles.append(doll.rifle_location())
        speed = np.linalg.norm(data.xipos[1:] - com[1:], axis=1).max() / dt
        com_before, com = com, data.xipos.copy()
        pelvis_speed = np.linalg.norm(data.xipos[hips] - com_before[hips]) / dt
        down = data.xipos[feet, 2].max() < SLEEP_FEET
        if not asleep and t > spec.fade and pelvis_speed < SLEEP_SPEED and down:
            asleep.append((data.time, model.dof_damping[jm.qvel].copy()))
            model.qpos_spring[jm.qpos] = data.qpos[jm.qpos]
        still = still + 1 if speed < REST_SPEED and t > spec.fade + spec.release else 0
        if still * dt >= REST_SECONDS:
            break
    return Fall((poses, roots, rifles), release_frame, letgo, pelvis)


def _grounded(spec: DeathSpec, clip: DeathClip, body: Figure) -> DeathClip:
    """(:attr:`DeathSpec.grounded`) ``clip`` lowered where it hovers (:mod:`authoring.grounded`), before
    the rifle falls again among it."""
    if not spec.grounded:
        return clip
    frames = grounded_frames(clip.frames, body, clip.release_frame, spec.grounded_until_down)
    return DeathClip(frames, clip.release_frame)


def _rifle_resettled(spec: DeathSpec, clip: DeathClip, figures: tuple[Figure, Figure]) -> DeathClip:
    """(:attr:`DeathSpec.rifle_resettle`) the rifle leaning on him falls again among the finished body, as
    the settle takes his arms from under it; (:attr:`DeathSpec.rifle_refall`) it falls again among his
    trunk and legs from about the release, flung by :attr:`DeathSpec.rifle_refall_toss` (the first
    frame's pelvis' frame) (:mod:`authoring.rifle_settle`)."""
    if spec.rifle_refall is not None:
        kin = FigureKinematics(figures[0])
        first = kin.segment_globals(clip.frames.poses[:1], clip.frames.roots[:1])[0]
        toss = first[kin.segment_names.index("lower_torso"), :3, :3] @ np.array(spec.rifle_refall_toss)
        start = clip.release_frame + spec.rifle_refall
        frames = rifle_settle.settled(clip.frames, *figures, start, rifle_settle.ARMS, toss)
        clip = DeathClip(frames, clip.release_frame)
    if not spec.rifle_resettle:
        return clip
    return DeathClip(rifle_settle.settled(clip.frames, *figures), clip.release_frame)


def _dropped_alone(
    spec: DeathSpec,
    rifle: Figure,
    pelvis: np.ndarray,
    letgo: LetGo | None,
    release: int,
    recording: tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]],
) -> None:
    """(:attr:`DeathSpec.drop_toss`) the recorded rifle from the ``release`` frame on replaced, in place, by
    the same rifle falling again on its own from where the hands let it go (``letgo``), flung by the toss
    (the start ``pelvis``' frame; :mod:`authoring.rifle_drop`); the body lies still (its last frame
    repeated) while the rifle comes to rest after it."""
    if spec.drop_toss is None or letgo is None:
        return
    poses, roots, rifles = recording
    toss = pelvis[:3, :3] @ np.array(spec.drop_toss)
    rifles[release:] = list(dropped(rifle, letgo, toss, len(rifles) - release, FPS))
    poses += poses[-1:] * (len(rifles) - len(poses))
    roots += roots[-1:] * (len(rifles) - len(roots))


def _eased(spec: DeathSpec, clip: DeathClip) -> DeathClip:
    """``clip`` leaving its start posture from rest (:attr:`DeathSpec.start_ease`), its release frame the
    first that plays the recorded one or later."""
    if spec.start_ease <= 0.0:
        return clip
    frames, times = eased_in(clip.frames, spec.start_ease)
    release = int(np.searchsorted(times * frames.fps, clip.release_frame - 1e-6))
    return DeathClip(frames, release)


def _after_physics(
    spec: DeathSpec, frames: ClipFrames, figures: tuple[Figure, Figure], release: int = 0
) -> ClipFrames:
    """The recorded fall with its skid taken out, settled limp, (:attr:`DeathSpec.knees_held`) its knees on
    the ground held and (:attr:`DeathSpec.pinned`) its limbs on the ground held where they touched down
    (steps 5-7 of the module docstring), then (:attr:`DeathSpec.legs_lift`) its feet and knees that would
    skid lifted (step 8)."""
    if spec.letgo_eased:  # the arms leave the grip over frames, not in one
        frames = eased_letgo(frames, FigureKinematics(figures[0]), release, spec.letgo_eased)
    planted = (plant_least_worst if spec.plant_worst else plant)(frames, figures[0])
    frames = _held(spec, planted, figures, release)
    frames = lifted(frames, figures[0], spec.legs_lift_step_deg) if spec.legs_lift else frames
    if spec.legs_eased:
        frames = eased_legs(planted, frames, figures[0], spec.legs_eased, spec.legs_eased_together)
    if not spec.turn_worst:
        return frames
    return least_worst_turned(frames, figures[0], DIRECTIONS if spec.turn_as_checked else WORST_DIRECTIONS)


def _held(spec: DeathSpec, frames: ClipFrames, figures: tuple[Figure, Figure], release: int) -> ClipFrames:
    """The planted fall settled and its contacts held (:func:`_after_physics` but the legs' lift)."""
    soldier, rifle = figures
    if spec.pinned and spec.arms_fall:  # held where they landed first, then the arms fall (kstow2dead: pinned
        # after the fall, the still frames appended moved the feet's pins and slid a foot 1.8 cm more)
        assert not (spec.knees_held or spec.propped), f"{spec.name}: knees held or propped, and arms falling"
        arms = dead_settle.ArmsFall(
            early_s=spec.arms_fall_early_s, seconds=spec.arms_fall_s, still_s=spec.arms_still_s
        )
        return dead_settle.settle(pin_frames(frames, soldier), soldier, rifle, spec.arms_fall, arms=arms)
    if spec.sunk:  # a crawler's trunk comes down about his thighs first
        frames = dead_crawl.sunk(FigureSet({"body": soldier, "rifle": rifle}), frames)
    if spec.feet_held:  # the shins do not kick up as the knees land
        frames = held_feet(frames, soldier)
    if spec.slack_feet:  # settled and pinned past a live soldier's ankles (authoring.passive_range)
        soldier = passive_figure(soldier)
    settled_from = len(frames.poses) - 1  # the frame the settle starts after
    lowered = None
    if spec.lowered_at is not None:  # the chest comes down as he is hit, not after the physics
        early = min(round(spec.lowered_at * frames.fps), settled_from)
        lowered = dead_settle.lowered_early(
            frames, soldier, rifle, early, spec.slack_feet, spec.arms_lifted_level
        )
        settled_from = settled_from if lowered is None else early  # (not face down there: as without it)
    if lowered is not None:
        frames = lowered
    else:  # face down: the head drops; on his back (arms_fall): the arms fall, kinematically
        frames = dead_settle.settle(
            frames,
            soldier,
            rifle,
            spec.arms_fall,
            spec.propped,
            legs=spec.legs_settle and spec.legs_land_from is None,
            slack_feet=spec.slack_feet,
            arms=dead_settle.ArmsFall(
                spec.arms_headward_cm,
                spec.arms_fall_early_s,
                spec.arms_fall_s,
                spec.arms_still_s,
                spec.arms_air_low,
                spec.legs_lift_off,
            ),
        )
        if spec.legs_settle and spec.legs_land_from is not None:  # laid as the knees land
            k0 = round(spec.legs_land_from * frames.fps)
            frames = dead_settle.legs_landed_from(frames, soldier, rifle, k0, settled_from)
    if spec.knees_held:  # the body pivots over a knee on the ground (knee_hold)
        frames = hold_knees(frames, soldier, release)
    if not spec.pinned:
        return frames
    held = pin_frames(frames, soldier, spec.propped, release if spec.propped else 0)
    if not spec.prone_legs_roll:
        return held
    figs = FigureSet({"body": soldier, "rifle": rifle})  # the legs roll out over the settle, on the pins
    rest = dead_settle._rest_frame(figs, held, DOWN_CM)
    return prone_roll.rolled(figs, held, settled_from, rest, round(dead_settle.STILL_SECONDS * held.fps))
