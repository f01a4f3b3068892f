"""The 17 static posture transitions of seed 002 (section 3.2, Figure 7) as motion scripts.

Each transition is what the 1994 animators typed into Jack: 10-15 primitive motions, each moving one body
part (legs, hips, spine, head, arms, fingers, the rifle, one foot) from where it is to its place in a target
key posture, with its own start, duration and velocity control ("step the left foot forward, lower the hips,
bring the rifle up"). Targets are the graph's postures (:mod:`authoring.postures`) or in-between keys
(both knees down). The seven deaths are simulated, not scripted (:mod:`authoring.deaths`). Recording
a transition:

1. :class:`~authoring.motion.MotionScript` interpolates the joint groups and the pelvis placement
   (``soldier``) and the rifle's placement *relative to the upper torso* (``AK_47``: the soldier carries it,
   so the gun moves with the body and only its carry changes);
2. the rifle is put in the world (``upper_torso`` global times the carry);
3. one batched IK solve over all frames (:func:`authoring.ik.solve`) keeps the palm centres on the
   rifle's grip and handguard (highest priority) and the feet on their trajectories (planted, or stepping
   along an arc with ``lift``; stepping back into a kneel the ball of the foot follows the arc and the foot
   turns ahead of it, so it peels off and lands on its toes), pulling towards the interpolated joints in the
   null space. Kneeling transitions also put the kneecaps on tracks (planted, or lifted and put down), and a
   ``free`` step leaves a foot or knee to the interpolated joints until it lands;
4. the clip is retimed (:func:`authoring.easing.ease_ends`) so that it leaves its start posture and
   reaches its end posture at rest, as a soldier does (played backwards too); deaths are not.

In-between keys may be derived from the postures (:data:`DERIVED_KEYS`: moved along the ground, some joints
turned, the pelvis hiked, the legs solved onto other keys' contacts). Getting down to crawl, the soldier
kneels with his right knee and toes where the crawl has them, folds the left leg back onto its knee beside
the right one (the foot never touches the ground on the way), then pivots forward about knees and toes onto
his forearms, so no contact on the ground slides.

Every target of step 3 interpolates the *actual* states of the start and end key postures, so the first
and last frames are exactly the graph's postures and consecutive clips join without a jump.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from authoring import easing, ik, rifle_pace
from authoring.motion import (
    JointTarget,
    KeyPosture,
    LocationTarget,
    Motion,
    MotionScript,
    VelocityControl,
)
from authoring.postures import RIFLE, SOLDIER, SPINE, arm, leg, palm_targets
from authoring.signal_shaping import smoothstep
from peabody import quaternion
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.model import Figure
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset

FPS = 60
EASE = VelocityControl.EASE_IN_OUT
CARRIER = "upper_torso"  # the rifle's carry is relative to this segment

FINGERS = (
    "thumb_cmc",
    "thumb_mcp",
    "thumb_ip",
    *tuple(f"{f}_{k}" for f in ("index", "middle", "ring", "pinky") for k in ("mcp", "pip", "dip")),
)
# body parts a primitive motion can move (joint groups of soldier.fig)
PARTS: dict[str, tuple[str, ...]] = {
    "legs": (*leg("left"), "left_toes", *leg("right"), "right_toes"),
    "left_leg": (*leg("left"), "left_toes"),
    "right_leg": (*leg("right"), "right_toes"),
    "spine": ("waist", *SPINE),
    "head": ("neck", "head", "left_eye", "right_eye"),
    "arms": tuple(j for s in ("left", "right") for j in (f"{s}_clavicle", *arm(s))),
    "hands": tuple(f"{s}_{f}" for s in ("left", "right") for f in FINGERS),
}
FEET = ("left_foot", "right_foot")
KNEES = ("left_knee", "right_knee")  # kneecaps (``lower_leg.knee``) put on tracks like the feet (kneeling)
SPECIAL = ("root", "rifle", *FEET, *KNEES)
CONTACTS = ("{s}_foot.heel", "{s}_foot.ball", "{s}_toes.distal")  # the points of a foot that touch the ground


@dataclass(frozen=True)
class Step:
    """One primitive motion: move ``part`` to its place in key posture ``to`` over
    ``[start, start + duration]``.

    ``part`` is a joint group of :data:`PARTS`, ``"root"`` (the pelvis placement), ``"rifle"`` (the carry of
    the gun), a foot (``"left_foot"``: the heel frame follows an arc ``lift`` cm high; outside its steps a
    foot with any step is planted where it last was, a foot without steps is free) or a kneecap
    (``"left_knee"``, likewise, position only). A ``free`` step leaves the foot or knee to the joints (no
    goal) until it arrives where ``to`` has it, planted there from then on. A foot step with ``follow``
    goes where the interpolated leg carries it, the knee folded just enough to clear the ground by the arc
    (:func:`_fold_knee`), instead of the straight path: where that path needs a pose far from the
    interpolation (the front leg of a kneeling man swinging back under him), IK tracking it wanders through
    a hip singularity and pops.
    """

    part: str
    to: str
    start: float
    duration: float
    velocity: VelocityControl = EASE
    lift: float = 0.0
    arc_site: str = "heel"  # foot steps: the foot site that follows the arc ("ball": peel off the toes)
    free: bool = False
    follow: bool = False


@dataclass(frozen=True)
class TransitionSpec:
    """A transition file ``name`` (e.g. ``ststow2kstow``): posture ``start`` to ``end`` in ``duration`` s."""

    name: str
    start: str
    end: str
    duration: float
    steps: tuple[Step, ...] = field(default_factory=tuple)
    in_hand: bool = False  # the right hand carries the rifle (its arm interpolated), not the upper torso
    # in_hand: when (s) the rifle turns in the right hand from its start to its end grip (default: the clip)
    hand_turn: tuple[float, float] | None = None
    # in_hand: the left elbow is guided (lowest priority) from its start key's place to its end key's,
    # relative to the chest, so the solved arm swings round the rifle on the end key's side of its swivel
    guide_elbow: bool = False
    # degrees per second: the clip is retimed so its rifle's line turns no faster (authoring.rifle_pace)
    rifle_pace: float | None = None
    # seconds over which a foot or knee goal fades out as its ``free`` step starts (0: let go at once;
    # ststow2crawl's left foot let go in one frame popped its knee 3.6 cm)
    free_fade: float = 0.0
    # sites (``segment.site``) held on every frame where they lie in the start key, above the palms (a prone
    # reaction's planted elbows: the rifle gives, not the elbow; tracking the palms alone lifted one 4.4 cm)
    planted: tuple[str, ...] = ()


# --- clip frames --------------------------------------------------------------------------------------------


@dataclass
class ClipFrames:
    """A recorded clip before it becomes a channelset: per frame the soldier's pose and root placement and the
    rifle's placement (clip frame)."""

    poses: np.ndarray  # (n, ndof)
    roots: np.ndarray  # (n, 4, 4)
    rifles: np.ndarray  # (n, 4, 4)
    fps: float = FPS

    @property
    def nframes(self) -> int:
        return len(self.poses)


def clip_to_channelset(name: str, clip: ClipFrames, soldier: Figure, rifle: Figure) -> Channelset:
    """``write_channelset`` of soldier and rifle: one figure channel each, one joint channel per joint."""
    rec = Recording([soldier, rifle])
    n = clip.nframes
    soldier_root = f"{soldier.root.segment.name}.{soldier.root.name}"  # type: ignore[union-attr]
    rifle_root = f"{rifle.root.segment.name}.{rifle.root.name}"  # type: ignore[union-attr]
    rec.poses[soldier.name].extend(np.asarray(clip.poses, np.float32))
    rec.roots[soldier.name].extend([soldier_root] * n)
    rec.locations[soldier.name].extend(np.asarray(clip.roots, np.float64))
    rec.poses[rifle.name].extend(np.zeros((n, 0), np.float32))
    rec.roots[rifle.name].extend([rifle_root] * n)
    rec.locations[rifle.name].extend(np.asarray(clip.rifles, np.float64))
    return recording_to_channelset(name, rec, 0, n - 1, clip.fps)


def carrier_globals(kin: FigureKinematics, poses: np.ndarray, roots: np.ndarray) -> np.ndarray:
    return kin.segment_globals(poses, roots)[..., kin.segment_names.index(CARRIER), :, :]


def carry_of(kin: FigureKinematics, key: KeyPosture) -> np.ndarray:
    """The rifle's placement relative to the carrier segment in a key posture."""
    g = carrier_globals(kin, key.poses[SOLDIER], key.locations[SOLDIER])
    return rigid_inverse(g) @ key.locations[RIFLE]


def heel_frame(kin: FigureKinematics, side: str, pose: np.ndarray, root: np.ndarray) -> np.ndarray:
    return kin.site_globals(pose, root)[..., kin.site_names.index(f"{side}_foot.heel"), :, :]


def palm_offsets(kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture) -> dict[str, np.ndarray]:
    """Each palm's actual frame relative to its target frame on the rifle (identity when solved exactly)."""
    g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])
    out = {}
    for side in ("right", "left"):
        t = palm_targets(rkin, key.locations[RIFLE], side)
        out[side] = rigid_inverse(t) @ g[kin.site_names.index(f"{side}_palm.palmcenter")]
    return out


def slerp_frames(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` rigid frames from ``a`` to ``b`` (lerp positions, slerp rotations) at progress ``u``."""
    qa = quaternion.from_matrix(a[None, :3, :3])[0]
    qb = quaternion.from_matrix(b[None, :3, :3])[0]
    if float(qa @ qb) < 0:
        qb = -qb
    q = quaternion.slerp(np.broadcast_to(qa, (len(u), 4)), np.broadcast_to(qb, (len(u), 4)), u)
    p = a[None, :3, 3] + u[:, None] * (b[:3, 3] - a[:3, 3])[None]
    return quaternion.to_transform(p, q)


def _track(
    kin: FigureKinematics,
    poses: np.ndarray,
    goals: Sequence[ik.Goal],
    roots: np.ndarray,
    order: np.ndarray,
    iterations: int,
    max_dof_step: float = 0.35,
) -> np.ndarray:
    """Solve frame after frame in ``order``, each frame starting from the previous solution moved by the
    interpolated motion and pulled towards that start (not towards the interpolated pose); ``max_dof_step``
    (rad per iteration) small, no joint can leap to another solution between frames."""
    out = np.array(poses, dtype=np.float64)
    prev_in = poses[order[0]]
    prev_out = poses[order[0]]
    for i in order:
        start = kin.clamp(prev_out + (poses[i] - prev_in))
        prev_in, prev_out = poses[i], ik.solve_frame(kin, start, goals, roots, i, iterations, max_dof_step)
        out[i] = prev_out
    return out


def track_solve(
    kin: FigureKinematics,
    poses: np.ndarray,
    goals: Sequence[ik.Goal],
    roots: np.ndarray,
    iterations: int = 40,
    max_dof_step: float = 0.35,
    backward_only: bool = False,
    forward_only: bool = False,
) -> np.ndarray:
    """IK over a clip without jumps between solutions.

    A batched solve from the interpolated poses can pick a different elbow branch in neighbouring frames,
    and a clip must also end exactly in its end key. So the goals are tracked forwards from the first frame
    and backwards from the last (each frame warm-started from its neighbour), the two tracks are blended
    with an ease-in/ease-out weight, and a short final solve from the blend puts the hands back on the
    rifle with small steps (``max_dof_step``), so it cannot leave the blend's branch. ``backward_only``:
    the track back from the end alone (where the forward one ends on another branch than the end key's,
    and the backward one comes back to the start key's); ``forward_only``: the track from the start alone
    (the other way round).
    """
    n = len(poses)
    w = (1.0 - np.cos(np.pi * np.linspace(0.0, 1.0, n))) / 2.0
    if forward_only:
        blend = _track(kin, poses, goals, roots, np.arange(n), iterations, max_dof_step)
    else:
        bwd = _track(kin, poses, goals, roots, np.arange(n)[::-1], iterations, max_dof_step)
        if backward_only:
            blend = bwd
        else:
            fwd = _track(kin, poses, goals, roots, np.arange(n), iterations, max_dof_step)
            blend = fwd + w[:, None] * (bwd - fwd)
    fix_step = 0.1  # rad
    fix = min(fix_step, max_dof_step)  # (small steps: the tracks are on the rifle already, a few steps)
    q, _ = ik.solve(
        kin,
        blend,
        goals,
        roots,
        iterations=4 if max_dof_step < fix_step else 40,
        rest_pose=blend,
        rest_gain=0.1,
        max_dof_step=fix,
    )
    return q


def lift_off_ground(
    kin: FigureKinematics, poses: np.ndarray, roots: np.ndarray, rifles: np.ndarray
) -> np.ndarray:
    """Raise the soldier (and his rifle) in frames where part of the body would sink into the ground;
    returns the lift per frame (cm). In place."""
    from authoring.postures import lowest_point

    lift = np.maximum(0.0, -lowest_point(kin, poses, roots))
    roots[:, 1, 3] += lift
    rifles[:, 1, 3] += lift
    return lift


# --- in-between keys derived from the postures -------------------------------------------------------------


@dataclass(frozen=True)
class DerivedKey:
    """An in-between key built from the posture ``base``: moved along the ground by ``fraction`` of the shift
    that puts the mean of ``sites`` on the key ``ref``'s (``ref=None``: not moved), with some joints turned
    by ``joints`` (degrees added to the base's angles), the pelvis hiked (the whole figure turned about the
    forward axis through one hip joint until the other, ``hike_side``, is ``hike`` cm higher); then the legs
    are solved so that each ``hold`` site (a foot's heel frame, a kneecap's position) is where the named key
    has it. The animator's way to a pose between two postures, with every contact where it belongs."""

    base: str
    ref: str | None = None
    sites: tuple[str, ...] = ()
    joints: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    fraction: float = 1.0
    hold: tuple[tuple[str, str], ...] = ()
    hike: float = 0.0
    hike_side: str = "left"


KNEES_AT_CRAWL = "KNEEL_BOTH@CRAWL"  # on both knees, knees and toes exactly where the crawl has them
KNEEL_AT_CRAWL = "KNEEL_STOWED@CRAWL"  # on the right knee, that knee and its toes where the crawl has them
SHUFFLED = "KNEEL_STOWED@SHUFFLED"  # right knee and toes as there, hips most of the way, left foot stays
SHUFFLING = "KNEEL_STOWED@SHUFFLING"  # on the way there, the right hip hiked so the right knee can lift
FOLD = "FOLD@CRAWL"  # shuffled, the left heel pulled up behind the left thigh (the foot off the ground)
TUCK = "TUCK@CRAWL"  # on both knees at the crawl's places, the left shin still folded up behind
RAISED = "KNEEL_STOWED@RAISED"  # the rifle raised in the right hand: the left forearm over the left knee
# Knees and toes already where the crawl has them, the soldier only pivots forward about them onto his
# forearms. Fold and tuck bring the front leg back onto its knee without the foot touching the ground; the
# thigh lifts only 10 degrees into the fold and the rifle is raised meanwhile (with the thigh lifted 40 and
# the rifle low, the left knee came up 5 cm through the left arm: limb_through_cm).
DERIVED_KEYS: dict[str, DerivedKey] = {
    KNEES_AT_CRAWL: DerivedKey(
        "KNEEL_BOTH",
        "CRAWL",
        ("left_toes.distal", "right_toes.distal"),
        hold=tuple(
            (f"{s}_{site}", "CRAWL") for s in ("left", "right") for site in ("lower_leg.knee", "toes.distal")
        ),
    ),
    KNEEL_AT_CRAWL: DerivedKey("KNEEL_STOWED", KNEES_AT_CRAWL, ("right_toes.distal",)),
    SHUFFLED: DerivedKey(
        "KNEEL_STOWED",
        KNEES_AT_CRAWL,
        ("right_toes.distal",),
        fraction=0.85,
        hold=(
            ("right_foot.heel", KNEES_AT_CRAWL),
            ("right_lower_leg.knee", KNEES_AT_CRAWL),
            ("left_foot.heel", "KNEEL_STOWED"),
        ),
    ),
    SHUFFLING: DerivedKey(
        "KNEEL_STOWED",
        KNEES_AT_CRAWL,
        ("right_toes.distal",),
        fraction=0.85,
        hold=(("left_foot.heel", "KNEEL_STOWED"),),
        hike=5.0,
        hike_side="right",
    ),
    FOLD: DerivedKey(SHUFFLED, joints={"left_hip": (0.0, 10.0, 0.0), "left_knee": (75.0,)}),
    TUCK: DerivedKey(KNEES_AT_CRAWL, joints={"left_knee": (59.0,)}, hike=4.0),
    RAISED: DerivedKey(SHUFFLED, joints={"right_shoulder": (0.0, 0.0, -15.0)}),
}


def _derive(kin: FigureKinematics, keys: dict[str, KeyPosture], name: str) -> KeyPosture:
    """Key ``name`` from ``keys``, or built from :data:`DERIVED_KEYS` (and its bases) and added to them."""
    if name in keys:
        return keys[name]
    d = DERIVED_KEYS[name]
    base = _derive(kin, keys, d.base)
    pose = np.array(base.poses[SOLDIER], dtype=np.float64)
    for j, deg in d.joints.items():
        pose[kin.dof_slices[j]] += np.radians(deg)
    pose = kin.clamp(pose)
    shift = np.eye(4)
    if d.ref is not None:
        idx = [kin.site_names.index(s) for s in d.sites]

        def mean_xz(key: KeyPosture) -> np.ndarray:
            g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])
            return g[idx, :3, 3].mean(axis=0) * np.array([1.0, 0.0, 1.0])

        shift[:3, 3] = d.fraction * (mean_xz(_derive(kin, keys, d.ref)) - mean_xz(base))
    if d.hike:
        g = kin.site_globals(pose, shift @ base.locations[SOLDIER])
        other = "right" if d.hike_side == "left" else "left"
        pivot = g[kin.site_names.index(f"lower_torso.{other}_hip"), :3, 3]
        up = g[kin.site_names.index(f"lower_torso.{d.hike_side}_hip"), :3, 3]
        a = np.arcsin(d.hike / np.linalg.norm(up - pivot)) * np.sign(up[0] - pivot[0])
        turn = np.eye(4)
        turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]  # about world Z
        about = np.eye(4)
        about[:3, 3] = pivot
        shift = about @ turn @ rigid_inverse(about) @ shift
    locations = {f: shift @ loc for f, loc in base.locations.items()}
    if d.hold:
        goals = []
        for site, src in d.hold:
            key = _derive(kin, keys, src)
            g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])[kin.site_names.index(site)]
            rot = g[:3, :3] if site.endswith(".heel") else None
            goals.append(ik.Goal(site, g[:3, 3], rot, 1.0, 1, leg(site.split("_")[0])))
        pose, _ = ik.solve(
            kin, pose, goals, locations[SOLDIER], iterations=200, rest_pose=pose, rest_gain=0.1
        )
    keys[name] = KeyPosture(name, {**base.poses, SOLDIER: pose}, locations)
    return keys[name]


def with_derived_keys(
    kin: FigureKinematics, keys: Mapping[str, KeyPosture], spec: TransitionSpec
) -> Mapping[str, KeyPosture]:
    """``keys`` plus the :data:`DERIVED_KEYS` that ``spec`` steps to (other specs get ``keys`` unchanged)."""
    wanted = sorted({st.to for st in spec.steps if st.to in DERIVED_KEYS and st.to not in keys})
    if not wanted:
        return keys
    out = dict(keys)
    for name in wanted:
        _derive(kin, out, name)
    return out


# --- recording a transition ---------------------------------------------------------------------------------


def _progress(step: Step, times: np.ndarray) -> np.ndarray:
    s = np.clip((times - step.start) / max(step.duration, 1e-9), 0.0, 1.0)
    return np.asarray(step.velocity(s), np.float64)


def _foot_track(
    kin: FigureKinematics,
    side: str,
    steps: Sequence[Step],
    keys: Mapping[str, KeyPosture],
    first: KeyPosture,
    times: np.ndarray,
) -> np.ndarray:
    """Heel frames over the clip: planted, then each step's arc to its key's heel frame.

    A step's ``arc_site`` (a site of the foot segment) is the point that follows the lerp + lift arc while
    the foot turns about it; stepping back into a kneel it is the ball, so the ball leaves the ground at once
    instead of being pressed down as the heel rises (the heel arc dragged it along the ground)."""
    cur = heel_frame(kin, side, first.poses[SOLDIER], first.locations[SOLDIER])
    out = np.broadcast_to(cur, (len(times), 4, 4)).copy()
    for st in sorted(steps, key=lambda s: s.start):
        key = keys[st.to]
        nxt = heel_frame(kin, side, key.poses[SOLDIER], key.locations[SOLDIER])
        off = np.eye(4)
        if st.arc_site != "heel":  # the site's frame relative to the heel's (both on the foot segment)
            g = kin.site_globals(first.poses[SOLDIER], first.locations[SOLDIER])
            heel = g[kin.site_names.index(f"{side}_foot.heel")]
            off = rigid_inverse(heel) @ g[kin.site_names.index(f"{side}_foot.{st.arc_site}")]
        live = times >= st.start
        u = _progress(st, times[live])
        track = slerp_frames(cur @ off, nxt @ off, u)
        if st.arc_site != "heel":  # the foot turns ahead of its travel (the heel peels up first), so the
            # ankle need not bend past its limit while the knee is still straight
            track[:, :3, :3] = slerp_frames(cur @ off, nxt @ off, np.sqrt(u))[:, :3, :3]
        s = np.clip((times[live] - st.start) / max(st.duration, 1e-9), 0.0, 1.0)
        track[:, 1, 3] += st.lift * np.sin(np.pi * s)
        out[live] = track @ rigid_inverse(off)
        cur = nxt
    return out


def _knee_track(
    kin: FigureKinematics,
    side: str,
    steps: Sequence[Step],
    keys: Mapping[str, KeyPosture],
    first: KeyPosture,
    times: np.ndarray,
) -> np.ndarray:
    """Kneecap positions over the clip: planted, then each step's arc (lerp + ``lift``) to its key's. A knee
    goes over to its new place only in the middle 70 % of the step, so it leaves and lands vertically
    instead of sliding along the ground."""
    i = kin.site_names.index(f"{side}_lower_leg.knee")

    def at(key: KeyPosture) -> np.ndarray:
        return kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])[i, :3, 3]

    cur = at(first)
    out = np.broadcast_to(cur, (len(times), 3)).copy()
    for st in sorted(steps, key=lambda s: s.start):
        nxt = at(keys[st.to])
        live = times >= st.start
        u = _progress(st, times[live])
        s = np.clip((times[live] - st.start) / max(st.duration, 1e-9), 0.0, 1.0)
        u_over = np.asarray(st.velocity(np.clip((s - 0.15) / 0.7, 0.0, 1.0)), np.float64)
        out[live] = cur + u_over[:, None] * (nxt - cur)
        out[live, 1] = cur[1] + u * (nxt[1] - cur[1]) + st.lift * np.sin(np.pi * s)
        cur = nxt
    return out


def _fold_knee(
    kin: FigureKinematics,
    side: str,
    steps: Sequence[Step],
    track: np.ndarray,
    poses: np.ndarray,
    roots: np.ndarray,
    times: np.ndarray,
) -> np.ndarray:
    """For each ``follow`` step of this foot: fold the knee of the interpolated ``poses`` (in place) by a
    smooth bump, the least that keeps the foot ``lift`` cm clear of the ground (scaled by the arc), and
    return ``track`` with the step's window replaced by the heel frames of those poses (shifted so they meet
    the track at both ends)."""
    out = np.array(track)
    knee = kin.dof_slices[f"{side}_knee"].start
    contacts = [kin.site_names.index(c.format(s=side)) for c in CONTACTS]
    for st in steps:
        if not st.follow:
            continue
        live = (times >= st.start) & (times <= st.start + st.duration)
        if not live.any():
            continue
        s = np.clip((times[live] - st.start) / max(st.duration, 1e-9), 0.0, 1.0)
        arc = np.sin(np.pi * s)
        base = poses[live]
        mid = arc >= 0.5  # (at the ends of the step the foot is at its keys' places, on the ground)
        for bump in np.radians(np.arange(0.0, 91.0, 5.0)):  # fixed candidates: deterministic
            q = base.copy()
            q[:, knee] = np.minimum(q[:, knee] + bump * arc, kin.upper[knee])
            low = kin.site_globals(q, roots[live])[:, contacts, 1, 3].min(axis=1)
            if np.all(low[mid] >= st.lift * arc[mid]):
                break
        poses[live] = q
        fk = heel_frame(kin, side, q, roots[live])
        i, j = np.flatnonzero(live)[[0, -1]]
        a = track[i - 1] if i > 0 else track[i]  # planted before the step, at its key after it
        b = track[min(j + 1, len(track) - 1)]
        fix = slerp_frames(a @ rigid_inverse(fk[0]), b @ rigid_inverse(fk[-1]), _progress(st, times[live]))
        out[live] = fix @ fk
    return out


def _goal_weight(steps: Sequence[Step], times: np.ndarray, fade: float = 0.0) -> float | np.ndarray:
    """1 where a foot or knee goal holds, 0 during its ``free`` steps (scalar 1 when it has none); with
    ``fade`` (s) eased from 1 to 0 over a free step's first ``fade`` s (let go gently; taken up again at
    once: the free limb arrives where its goal resumes). A step free from the clip's start fades too: its
    goal holds the first ``fade`` s (faded only where it was let go, ststow2crawl's left foot still popped,
    1.9 m/s, where its free step ended; fading that end as well skated it 29 cm)."""
    free = [st for st in steps if st.free]
    if not free:
        return 1.0
    w = np.ones(len(times))
    for st in free:
        inside = (times >= st.start) & (times < st.start + st.duration)
        if fade > 0.0:
            w[inside] = np.minimum(w[inside], 1.0 - smoothstep((times[inside] - st.start) / fade))
        else:
            w[inside] = 0.0
    return w


def script_for(
    spec: TransitionSpec, keys: Mapping[str, KeyPosture], figures: Sequence[Figure]
) -> MotionScript:
    """The primitive motions of ``spec`` as a motion script (rifle location = its carry, see module doc)."""
    soldier, rifle = figures
    kin = FigureKinematics(soldier)
    keys = with_derived_keys(kin, keys, spec)
    first = keys[spec.start]
    initial = KeyPosture(
        "initial",
        {SOLDIER: first.poses[SOLDIER], RIFLE: np.zeros(0)},
        {SOLDIER: first.locations[SOLDIER], RIFLE: carry_of(kin, first)},
    )
    script = MotionScript([soldier, rifle], initial, duration=spec.duration)
    for st in spec.steps:
        key = keys[st.to]
        if st.part == "root":
            target = LocationTarget(key.locations[SOLDIER])
            script.add(Motion(SOLDIER, st.start, st.duration, target, st.velocity, name=f"root->{st.to}"))
        elif st.part == "rifle":
            target = LocationTarget(carry_of(kin, key))
            script.add(Motion(RIFLE, st.start, st.duration, target, st.velocity, name=f"rifle->{st.to}"))
        elif st.part in PARTS:
            q = key.poses[SOLDIER]
            angles = {
                j: q[kin.dof_slices[j]]
                for j in PARTS[st.part]
                if kin.dof_slices[j].stop > kin.dof_slices[j].start
            }
            script.add(
                Motion(
                    SOLDIER,
                    st.start,
                    st.duration,
                    JointTarget(angles),
                    st.velocity,
                    name=f"{st.part}->{st.to}",
                )
            )
        elif st.part not in FEET + KNEES:
            raise KeyError(f"{spec.name}: unknown body part {st.part!r}")
    return script


def _in_right_hand(
    kin: FigureKinematics,
    rkin: FigureKinematics,
    first: KeyPosture,
    last: KeyPosture,
    poses: np.ndarray,
    roots: np.ndarray,
    times: np.ndarray,
    spec: TransitionSpec,
) -> np.ndarray:
    """Rifle placements held by the right palm: the grip stays on the palm (its offset blending from the
    start key's to the end key's over the hand turn), so the right hand never leaves it, while the rifle
    turns in the hand, relative to the chest, from where the turn finds it to the end key's carry (a slerp).
    Turned with the palm, it took every swing of the interpolated forearm: it whipped muzzle-up past the
    shoulder (25 degrees in 0.1 s) and through the right upper arm (5 cm)."""
    i = kin.site_names.index("right_palm.palmcenter")
    palm = kin.site_globals(poses, roots)[:, i]
    grip = rkin.site_globals(np.zeros(0))[rkin.site_names.index("rifle.grip")]

    def rel(key: KeyPosture) -> np.ndarray:  # the grip's frame relative to the palm (turning about the grip)
        g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])[i]
        return rigid_inverse(g) @ key.locations[RIFLE] @ grip

    a, b = spec.hand_turn or (0.0, spec.duration)
    u = np.asarray(EASE(np.clip((times - a) / (b - a), 0.0, 1.0)), np.float64)
    held = palm @ np.stack([slerp_frames(rel(first), rel(last), np.array([w]))[0] for w in u])
    chest = carrier_globals(kin, poses, roots)
    end = rigid_inverse(chest[-1]) @ last.locations[RIFLE] @ grip
    k = int(np.searchsorted(times, a))
    start = rigid_inverse(chest[k]) @ held[k]
    turned = chest @ slerp_frames(start, end, u)
    turned[:, :3, 3] = held[:, :3, 3]  # the grip where the palm holds it
    return np.where((times < a)[:, None, None], held, turned) @ rigid_inverse(grip)


# tracked back from the end key with at most 10 steps of 0.02 rad a frame (~11 degrees), as the crawl's
# arms are
SMALL_STEPS: dict[str, Any] = {"iterations": 10, "max_dof_step": 0.02, "backward_only": True}


def _tracking(spec: TransitionSpec) -> dict[str, Any]:
    """How :func:`track_solve` tracks ``spec``'s arms (default: its defaults)."""
    if spec.guide_elbow:
        return SMALL_STEPS
    return {}


def _turn_weight(spec: TransitionSpec, times: np.ndarray) -> np.ndarray:
    """1 outside the hand turn, down to 0 in its middle: while the rifle turns in the right hand the left
    palm keeps hold of the handguard but may turn on it (held to its grip there, the wrist ran into its
    limits and the arm jumped between solutions)."""
    a, b = spec.hand_turn or (0.0, spec.duration)
    s = np.clip((times - a) / (b - a), 0.0, 1.0)
    return 1.0 - np.sin(np.pi * s) ** 2


def _elbow_guide(
    kin: FigureKinematics,
    first: KeyPosture,
    last: KeyPosture,
    poses: np.ndarray,
    roots: np.ndarray,
    times: np.ndarray,
    spec: TransitionSpec,
) -> ik.Goal:
    """A low-priority goal for the left elbow: its place relative to the chest blends from the start key's
    to the end key's over the hand turn. Without it the solved arm (palm on the rifle) kept whichever side
    of its swivel it began on, and the clip had to jump to the end key's elbow on the ground."""
    i = kin.site_names.index("left_upper_arm.distal")

    def rel(key: KeyPosture) -> np.ndarray:
        g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])
        c = carrier_globals(kin, key.poses[SOLDIER], key.locations[SOLDIER])
        return (rigid_inverse(c) @ g[i])[:3, 3]

    a, b = spec.hand_turn or (0.0, spec.duration)
    u = np.asarray(EASE(np.clip((times - a) / (b - a), 0.0, 1.0)), np.float64)
    local = rel(first)[None] + u[:, None] * (rel(last) - rel(first))[None]
    c = carrier_globals(kin, poses, roots)
    pos = np.einsum("nij,nj->ni", c[:, :3, :3], local) + c[:, :3, 3]
    return ik.Goal("left_upper_arm.distal", pos, None, 1.0 - _turn_weight(spec, times), 1, arm("left"))


def _planted_goals(kin: FigureKinematics, key: KeyPosture, sites: Sequence[str]) -> list[ik.Goal]:
    """Each of ``sites`` (an arm's) held where it lies in ``key``, above the palms' priority (3): the
    clavicle and the arm give round it."""
    g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])
    return [
        ik.Goal(
            s,
            g[kin.site_names.index(s), :3, 3],
            None,
            1.0,
            4,
            (f"{s.split('_')[0]}_clavicle", *arm(s.split("_")[0])),
        )
        for s in sites
    ]


def record_transition(
    spec: TransitionSpec, keys: Mapping[str, KeyPosture], figures: Sequence[Figure], fps: float = FPS
) -> ClipFrames:
    """Evaluate ``spec`` into frames (see the module docstring)."""
    soldier, rifle = figures
    kin = FigureKinematics(soldier)
    rkin = FigureKinematics(rifle)
    keys = with_derived_keys(kin, keys, spec)
    frames = script_for(spec, keys, figures).evaluate(fps)
    times = frames.times
    poses = frames.poses[SOLDIER]
    roots = frames.locations[SOLDIER]
    rifles = carrier_globals(kin, poses, roots) @ frames.locations[RIFLE]
    first, last = keys[spec.start], keys[spec.end]
    if spec.in_hand:  # the rifle sits in the right hand as it moves with the interpolated arm
        rifles = _in_right_hand(kin, rkin, first, last, poses, roots, times, spec)
    # palms: on the rifle, turned as in the start key blending to the end key with the rifle's carry
    rifle_steps = [s for s in spec.steps if s.part == "rifle"]
    u_rifle = np.zeros(len(times))
    for st in rifle_steps:
        u_rifle = np.where(times >= st.start, _progress(st, times), u_rifle)
    off_a, off_b = palm_offsets(kin, rkin, first), palm_offsets(kin, rkin, last)
    goals: list[ik.Goal] = []
    turn_w = _turn_weight(spec, times) if spec.guide_elbow else 1.0
    for side in ("left",) if spec.in_hand else ("right", "left"):
        tgt = palm_targets(rkin, rifles, side) @ slerp_frames(off_a[side], off_b[side], u_rifle)
        chain = arm(side)
        goals.append(ik.Goal(f"{side}_palm.palmcenter", tgt[:, :3, 3], None, 1.0, 3, chain))
        goals.append(
            ik.Goal(
                f"{side}_palm.palmcenter", None, tgt[:, :3, :3], turn_w, 1, arm(side), orientation_weight=8.0
            )
        )
    if spec.guide_elbow:
        goals.append(_elbow_guide(kin, first, last, poses, roots, times, spec))
    goals += _planted_goals(kin, first, spec.planted)
    for foot in FEET:
        side = foot.split("_")[0]
        steps = [s for s in spec.steps if s.part == foot]
        if not steps:
            continue
        track = _foot_track(kin, side, steps, keys, first, times)
        track = _fold_knee(kin, side, steps, track, poses, roots, times)
        w = _goal_weight(steps, times, spec.free_fade)
        goals.append(ik.Goal(f"{side}_foot.heel", track[:, :3, 3], track[:, :3, :3], w, 2, leg(side)))
    for knee in KNEES:  # only kneeling transitions have knee steps
        side = knee.split("_")[0]
        steps = [s for s in spec.steps if s.part == knee]
        if steps:
            pos = _knee_track(kin, side, steps, keys, first, times)
            w = _goal_weight(steps, times, spec.free_fade)
            goals.append(ik.Goal(f"{side}_lower_leg.knee", pos, None, w, 2, leg(side)))
    q = track_solve(kin, poses, goals, roots, **_tracking(spec))
    # the ends are the graph's postures exactly
    q[0], q[-1] = first.poses[SOLDIER], last.poses[SOLDIER]
    rifles[0], rifles[-1] = first.locations[RIFLE], last.locations[RIFLE]
    roots[0], roots[-1] = first.locations[SOLDIER], last.locations[SOLDIER]
    lift_off_ground(kin, q, roots, rifles)
    clip = ClipFrames(q, roots, rifles, fps)
    if spec.end == "DEAD":  # deaths are left as they are (recorded by physics, not by these steps)
        return clip
    if spec.rifle_pace is not None:
        clip = rifle_pace.paced(soldier, rkin, clip, spec.rifle_pace)
    return easing.ease_ends(kin, rkin, clip)


# --- the seventeen transitions ------------------------------------------------------------------------------


def _whole(to: str, start: float, duration: float, parts: Sequence[str] | None = None) -> tuple[Step, ...]:
    """Every body part (or ``parts``) to ``to`` together."""
    names = parts or ("root", "legs", "spine", "head", "arms", "hands", "rifle")
    return tuple(Step(p, to, start, duration) for p in names)


def _planted(to: str, duration: float) -> tuple[Step, ...]:
    return (Step("left_foot", to, 0.0, duration), Step("right_foot", to, 0.0, duration))


def _raise_rifle(src: str, dst: str, t: float) -> tuple[Step, ...]:
    """Stowed -> fire in place: bring the rifle up into the shoulder, lean in, cheek onto the stock."""
    return (
        Step("rifle", dst, 0.05 * t, 0.7 * t),
        Step("arms", dst, 0.05 * t, 0.7 * t),
        Step("spine", dst, 0.0, 0.75 * t),
        Step("head", dst, 0.3 * t, 0.65 * t),
        Step("hands", dst, 0.0, 0.4 * t),
        Step("legs", dst, 0.0, t),
        Step("root", dst, 0.0, t),
    )


def _kneel_down(dst: str, t: float, right: tuple[float, float] = (0.35, 0.5)) -> tuple[Step, ...]:
    """Standing -> kneeling on the right knee: step the left foot forward, lower the hips, right knee down.
    The right foot leaves the ground only once the left has landed (leaving at 0.2 t, with the left still
    in the air, he hopped 3.4-3.8 cm down onto the knee: nothing held him up for 0.08-0.13 s); ``right``:
    when it leaves and how long it takes (fractions of ``t``)."""
    return (
        Step("left_foot", dst, 0.0, 0.35 * t, lift=8.0),
        Step("right_foot", dst, right[0] * t, right[1] * t, lift=10.0, arc_site="ball"),
        Step("root", dst, 0.08 * t, 0.8 * t),
        Step("legs", dst, 0.08 * t, 0.8 * t),
        Step("spine", dst, 0.15 * t, 0.8 * t),
        Step("head", dst, 0.25 * t, 0.75 * t),
    )


def _arms(dst: str, start: float, duration: float) -> tuple[Step, ...]:
    """Arms and fingers to ``dst`` (the rifle in the right hand follows them): an in-between carry of an
    ``in_hand`` clip, whose palms keep their start grip until its one rifle step (the last carry)."""
    return (Step("arms", dst, start, duration), Step("hands", dst, start, duration))


def _carry(dst: str, start: float, duration: float) -> tuple[Step, ...]:
    """Arms, fingers and rifle to ``dst`` together (the carry changes, e.g. low ready -> cradled)."""
    return (
        Step("arms", dst, start, duration),
        Step("rifle", dst, start, duration),
        Step("hands", dst, start, duration),
    )


def _left_knee_down(t0: float, t1: float) -> tuple[Step, ...]:
    """On the right knee (knees where the crawl has them), bring the left leg back onto its knee beside the
    right one by ``t1``: the left heel comes up behind the thigh (:data:`FOLD`, the foot peels off the
    ground along an arc: left to the folding leg it slid back 2 cm first), the thigh swings down until the
    knee is on its place (:data:`TUCK`), then the shin comes down behind onto the toes; knee and toes stay
    from then on. The arms come down from :data:`RAISED` only once the knee is past them."""
    d = t1 - t0
    return (
        Step("left_foot", FOLD, t0, 0.25 * d, lift=6.0, arc_site="ball"),  # peeled off, not dragged back
        Step("left_foot", KNEES_AT_CRAWL, t0 + 0.25 * d, 0.75 * d, free=True),
        Step("left_knee", KNEES_AT_CRAWL, 0.0, t1, free=True),
        Step("right_foot", KNEES_AT_CRAWL, t0, d),
        Step("right_knee", KNEES_AT_CRAWL, t0, d),
        Step("legs", FOLD, t0, 0.25 * d),
        Step("legs", TUCK, t0 + 0.25 * d, 0.45 * d),
        Step("legs", KNEES_AT_CRAWL, t0 + 0.7 * d, 0.3 * d),
        Step("root", TUCK, t0, 0.6 * d),
        Step("root", KNEES_AT_CRAWL, t0 + 0.6 * d, 0.4 * d),
        Step("spine", KNEES_AT_CRAWL, t0, d),
        Step("head", KNEES_AT_CRAWL, t0, d),
        *_arms(KNEES_AT_CRAWL, t0 + 0.3 * d, 0.7 * d),
    )


FREE_FADE = 0.15  # s: ststow2crawl lets go of a foot or knee goal gently (TransitionSpec.free_fade)


def _stand_to_crawl(ta: float, tb: float, t: float) -> tuple[Step, ...]:
    """Standing -> crawl: kneel down (the right foot steps back onto its knee where the crawl has it, the
    left foot forward: :data:`SHUFFLED` at ``ta``), bring the left knee down beside the right one (``tb``),
    then pivot forward about knees and toes onto the forearms (``t``)."""
    return (
        *_kneel_down(SHUFFLED, ta, right=(0.2, 0.65)),  # as recorded before 109971c: none unsupported
        Step("right_knee", SHUFFLED, 0.0, ta, free=True),
        *_arms(RAISED, 0.1 * ta, 0.85 * ta),
        *_left_knee_down(ta, tb),
        *_down_to_crawl(tb, t),
    )


def _kneel_to_crawl(ta: float, tb: float, t: float) -> tuple[Step, ...]:
    """Kneeling -> crawl: shuffle the right knee back (the right hip hikes, the knee is lifted and put down
    where the crawl has it: :data:`SHUFFLED` at ``ta``), bring the left knee down beside the right
    (``tb``), then pivot forward onto the forearms (``t``)."""
    return (
        Step("right_foot", SHUFFLED, 0.05 * ta, 0.8 * ta, lift=5.0, arc_site="ball"),
        Step("right_knee", SHUFFLED, 0.05 * ta, 0.8 * ta, lift=5.0),
        Step("left_foot", SHUFFLED, 0.0, ta),
        Step("root", SHUFFLING, 0.0, 0.5 * ta),
        Step("root", SHUFFLED, 0.5 * ta, 0.5 * ta),
        Step("legs", SHUFFLED, 0.0, ta),
        *_arms(RAISED, 0.0, ta),
        *_left_knee_down(ta, tb),
        *_down_to_crawl(tb, t),
    )


def _down_to_crawl(src_end: float, t: float) -> tuple[Step, ...]:
    """From both knees (reached at ``src_end``) forward onto the forearms: the CRAWL posture at ``t``. The
    knees and toes are already where the crawl has them, so the body pivots about them (feet held)."""
    d = t - src_end
    return (
        Step("left_foot", "CRAWL", src_end, d),
        Step("right_foot", "CRAWL", src_end, d),
        Step("left_knee", "CRAWL", src_end, d),
        Step("right_knee", "CRAWL", src_end, d),
        Step("root", "CRAWL", src_end, d),
        Step("legs", "CRAWL", src_end, d),
        Step("spine", "CRAWL", src_end, 0.85 * d),
        Step("head", "CRAWL", src_end + 0.15 * d, 0.85 * d),
        *_carry("CRAWL", src_end, 0.9 * d),
    )


# degrees per second: down onto the forearms the rifle swung 21-24 degrees in 0.1 s with the chest
PACE = 110.0
# name, start, end, seconds (the arc times of seed 002 Figure 7; the elided ones invented), primitive motions.
# The seven deaths (`*2dead`) have no steps: they are simulated (authoring.deaths), not scripted.
TRANSITIONS: tuple[TransitionSpec, ...] = (
    TransitionSpec(
        "ststow2stfire",
        "STAND_STOWED",
        "STAND_FIRE",
        0.8,
        _raise_rifle("STAND_STOWED", "STAND_FIRE", 0.8) + _planted("STAND_FIRE", 0.8),
    ),
    TransitionSpec(
        "ststow2kstow",
        "STAND_STOWED",
        "KNEEL_STOWED",
        1.6,
        _kneel_down("KNEEL_STOWED", 1.6) + _carry("KNEEL_STOWED", 0.2, 1.3),
    ),
    TransitionSpec(
        "ststow2crawl",
        "STAND_STOWED",
        "CRAWL",
        2.0,
        _stand_to_crawl(0.75, 1.35, 2.0),
        hand_turn=(1.4, 1.95),
        rifle_pace=PACE,
        free_fade=FREE_FADE,
    ),
    TransitionSpec(
        "ststow2kfire",
        "STAND_STOWED",
        "KNEEL_FIRE",
        1.8,
        (
            *_kneel_down("KNEEL_FIRE", 1.5),
            Step("arms", "KNEEL_FIRE", 0.6, 1.1),
            Step("rifle", "KNEEL_FIRE", 0.6, 1.1),
            Step("hands", "KNEEL_FIRE", 0.9, 0.6),
            Step("head", "KNEEL_FIRE", 1.2, 0.6),
        ),
    ),
    TransitionSpec("ststow2dead", "STAND_STOWED", "DEAD", 1.5),
    TransitionSpec(
        "stfire2kfire",
        "STAND_FIRE",
        "KNEEL_FIRE",
        1.2,
        _kneel_down("KNEEL_FIRE", 1.2) + _carry("KNEEL_FIRE", 0.0, 1.15),
    ),
    TransitionSpec("stfire2dead", "STAND_FIRE", "DEAD", 1.2),
    TransitionSpec(
        "kstow2kfire",
        "KNEEL_STOWED",
        "KNEEL_FIRE",
        0.8,
        _raise_rifle("KNEEL_STOWED", "KNEEL_FIRE", 0.8) + _planted("KNEEL_FIRE", 0.8),
    ),
    TransitionSpec(
        "kstow2crawl",
        "KNEEL_STOWED",
        "CRAWL",
        1.4,
        _kneel_to_crawl(0.3, 0.85, 1.4),
        hand_turn=(0.88, 1.4),
        rifle_pace=PACE,
    ),
    TransitionSpec("kstow2dead", "KNEEL_STOWED", "DEAD", 1.0),
    TransitionSpec("kfire2dead", "KNEEL_FIRE", "DEAD", 1.0),
    # recorded limb by limb (authoring.crawl_prone), not by steps; its arc time is crawl_prone.DURATION
    TransitionSpec("crawl2prstow", "CRAWL", "PRONE_STOWED", 1.6),
    TransitionSpec(
        "prstow2prfire",
        "PRONE_STOWED",
        "PRONE_FIRE",
        0.8,
        _raise_rifle("PRONE_STOWED", "PRONE_FIRE", 0.8),
    ),
    TransitionSpec("crawl2dead", "CRAWL", "DEAD", 1.0),
    TransitionSpec("prstow2dead", "PRONE_STOWED", "DEAD", 1.0),
    TransitionSpec("prfire2dead", "PRONE_FIRE", "DEAD", 0.8),
    TransitionSpec(
        "stfire2kstow",
        "STAND_FIRE",
        "KNEEL_STOWED",
        1.6,
        _kneel_down("KNEEL_STOWED", 1.6) + _carry("KNEEL_STOWED", 0.0, 0.9),
    ),
)
# Big changes of carry (down onto the forearms): the rifle stays in the right hand, whose arm
# swings by interpolation, and only the left hand is solved onto it (IK on both arms jumped between
# elbow solutions on the way). Not crawl -> prone: from the crawl's cradle the left arm, solved onto the
# rifle in the right hand, could not get round to the prone grip (its elbow kept the wrong side of its
# swivel at either end, joint limits in between); both palms solved on the carried rifle move smoothly.
IN_HAND = frozenset(
    {
        "ststow2crawl",
        "kstow2crawl",
    }
)
# the left arm swings from its stowed grip round to the crawl's cradle: its elbow is guided (see _elbow_guide)
GUIDED_ELBOW = frozenset({"ststow2crawl", "kstow2crawl"})
TRANSITIONS = tuple(
    dataclasses.replace(
        t,
        in_hand=t.name in IN_HAND,
        guide_elbow=t.name in GUIDED_ELBOW,
    )
    for t in TRANSITIONS
)


def transition_specs() -> dict[str, TransitionSpec]:
    return {t.name: t for t in TRANSITIONS}
