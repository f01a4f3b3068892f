"""The 17 static posture transitions of seed 002 (section 3.2, Figure 7) as motion scripts.

Each transition is what the 1994 animators typed into Jack: 10-15 primitive motions, each moving one body
part (legs, hips, spine, head, arms, fingers, the rifle, one foot) from where it is to its place in a target
key posture, with its own start, duration and velocity control ("step the left foot forward, lower the hips,
bring the rifle up"). Targets are the graph's postures (:mod:`server.authoring.postures`) or in-between keys
(both knees down, falling). Recording a transition:

1. :class:`~server.authoring.motion.MotionScript` interpolates the joint groups and the pelvis placement
   (``soldier``) and the rifle's placement *relative to the upper torso* (``AK_47``: the soldier carries it,
   so the gun moves with the body and only its carry changes);
2. the rifle is put in the world (``upper_torso`` global times the carry);
3. one batched IK solve over all frames (:func:`server.authoring.ik.solve`) keeps the palm centres on the
   rifle's grip and handguard (highest priority) and the feet on their trajectories (planted, or stepping
   along an arc with ``lift``), pulling towards the interpolated joints in the null space.

Every target of step 3 interpolates the *actual* states of the start and end key postures, so the first
and last frames are exactly the graph's postures and consecutive clips join without a jump.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from server.authoring import ik
from server.authoring.motion import (
    JointTarget,
    KeyPosture,
    LocationTarget,
    Motion,
    MotionScript,
    VelocityControl,
)
from server.authoring.postures import RIFLE, SOLDIER, SPINE, arm, leg, palm_targets
from server.motion import quaternion
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset
from server.peabody.fk import FigureKinematics, rigid_inverse
from server.peabody.model import Figure

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
SPECIAL = ("root", "rifle", *FEET)
CONTACTS = ("{s}_foot.heel", "{s}_foot.ball", "{s}_toes.distal")  # the points of a foot that touch the ground


@dataclass(frozen=True)
class Step:
    """One primitive motion: move ``part`` to its place in key posture ``to`` over
    ``[start, start + duration]``.

    ``part`` is a joint group of :data:`PARTS`, ``"root"`` (the pelvis placement), ``"rifle"`` (the carry of
    the gun) or a foot (``"left_foot"``: the heel frame follows an arc ``lift`` cm high; outside its steps a
    foot with any step is planted where it last was, a foot without steps is free). A foot step with
    ``follow`` goes where the interpolated leg carries it, the knee folded just enough to clear the ground
    by the arc (:func:`_fold_knee`), instead of the straight path: where that path needs a pose far from the
    interpolation (the front leg of a kneeling man swinging back under him), IK tracking it wanders through
    a hip singularity and pops.
    """

    part: str
    to: str
    start: float
    duration: float
    velocity: VelocityControl = EASE
    lift: float = 0.0
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


def _goal_rows(goal: ik.Goal, rows: slice) -> ik.Goal:
    def pick(v: object, ndim: int) -> object:
        if v is None:
            return None
        a = np.asarray(v, np.float64)
        return a[rows] if a.ndim > ndim else a

    return ik.Goal(
        goal.site,
        pick(goal.target_position, 1),
        pick(goal.target_orientation, 2),
        pick(goal.weight, 0),
        goal.priority,
        goal.joints,
        goal.orientation_weight,
    )


def _track(
    kin: FigureKinematics,
    poses: np.ndarray,
    goals: Sequence[ik.Goal],
    roots: np.ndarray,
    order: np.ndarray,
    iterations: int,
) -> np.ndarray:
    """Solve frame after frame in ``order``, each frame starting from the previous solution moved by the
    interpolated motion and pulled towards that start (not towards the interpolated pose)."""
    out = np.array(poses, dtype=np.float64)
    prev_in = poses[order[0]]
    prev_out = poses[order[0]]
    for i in order:
        start = kin.clamp(prev_out + (poses[i] - prev_in))
        sub = [_goal_rows(g, slice(i, i + 1)) for g in goals]
        q, _ = ik.solve(
            kin,
            start[None],
            sub,
            roots[i : i + 1],
            iterations=iterations,
            rest_pose=start[None],
            rest_gain=0.1,
        )
        prev_in, prev_out = poses[i], q[0]
        out[i] = q[0]
    return out


def track_solve(
    kin: FigureKinematics,
    poses: np.ndarray,
    goals: Sequence[ik.Goal],
    roots: np.ndarray,
    iterations: int = 40,
) -> np.ndarray:
    """IK over a clip without jumps between solutions.

    A batched solve from the interpolated poses can pick a different elbow branch in neighbouring frames,
    and a clip must also end exactly in its end key. So the goals are tracked forwards from the first frame
    and backwards from the last (each frame warm-started from its neighbour), the two tracks are blended
    with an ease-in/ease-out weight, and a short final solve from the blend puts the hands back on the
    rifle with small steps (``max_dof_step``), so it cannot leave the blend's branch.
    """
    n = len(poses)
    fwd = _track(kin, poses, goals, roots, np.arange(n), iterations)
    bwd = _track(kin, poses, goals, roots, np.arange(n)[::-1], iterations)
    w = (1.0 - np.cos(np.pi * np.linspace(0.0, 1.0, n))) / 2.0
    blend = fwd + w[:, None] * (bwd - fwd)
    q, _ = ik.solve(kin, blend, goals, roots, iterations=40, rest_pose=blend, rest_gain=0.1, max_dof_step=0.1)
    return q


def lift_off_ground(
    kin: FigureKinematics, poses: np.ndarray, roots: np.ndarray, rifles: np.ndarray
) -> np.ndarray:
    """Raise the soldier (and his rifle) in frames where part of the body would sink into the ground;
    returns the lift per frame (cm). In place."""
    from server.authoring.postures import lowest_point

    lift = np.maximum(0.0, -lowest_point(kin, poses, roots))
    roots[:, 1, 3] += lift
    rifles[:, 1, 3] += lift
    return lift


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
    """Heel frames over the clip: planted, then each step's arc to its key's heel frame."""
    cur = heel_frame(kin, side, first.poses[SOLDIER], first.locations[SOLDIER])
    out = np.broadcast_to(cur, (len(times), 4, 4)).copy()
    for st in sorted(steps, key=lambda s: s.start):
        key = keys[st.to]
        nxt = heel_frame(kin, side, key.poses[SOLDIER], key.locations[SOLDIER])
        live = times >= st.start
        u = _progress(st, times[live])
        track = slerp_frames(cur, nxt, u)
        s = np.clip((times[live] - st.start) / max(st.duration, 1e-9), 0.0, 1.0)
        track[:, 1, 3] += st.lift * np.sin(np.pi * s)
        out[live] = track
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


def script_for(
    spec: TransitionSpec, keys: Mapping[str, KeyPosture], figures: Sequence[Figure]
) -> MotionScript:
    """The primitive motions of ``spec`` as a motion script (rifle location = its carry, see module doc)."""
    soldier, rifle = figures
    kin = FigureKinematics(soldier)
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
        elif st.part not in FEET:
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
    """Rifle placements held by the right palm: its grip relative to the palm blends from the start key's to
    the end key's (over the clip), so the right hand never leaves it."""
    i = kin.site_names.index("right_palm.palmcenter")
    palm = kin.site_globals(poses, roots)[:, i]
    grip = rkin.site_globals(np.zeros(0))[rkin.site_names.index("rifle.grip")]

    def rel(key: KeyPosture) -> np.ndarray:  # the grip's frame relative to the palm (turning about the grip)
        g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])[i]
        return rigid_inverse(g) @ key.locations[RIFLE] @ grip

    u = np.asarray(EASE(np.clip(times / spec.duration, 0.0, 1.0)), np.float64)
    held = np.stack([slerp_frames(rel(first), rel(last), np.array([w]))[0] for w in u])
    return palm @ held @ rigid_inverse(grip)


def record_transition(
    spec: TransitionSpec, keys: Mapping[str, KeyPosture], figures: Sequence[Figure], fps: float = FPS
) -> ClipFrames:
    """Evaluate ``spec`` into frames (see the module docstring)."""
    soldier, rifle = figures
    kin = FigureKinematics(soldier)
    rkin = FigureKinematics(rifle)
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
    for side in ("left",) if spec.in_hand else ("right", "left"):
        tgt = palm_targets(rkin, rifles, side) @ slerp_frames(off_a[side], off_b[side], u_rifle)
        chain = arm(side)
        goals.append(ik.Goal(f"{side}_palm.palmcenter", tgt[:, :3, 3], None, 1.0, 3, chain))
        goals.append(
            ik.Goal(
                f"{side}_palm.palmcenter", None, tgt[:, :3, :3], 1.0, 1, arm(side), orientation_weight=8.0
            )
        )
    for foot in FEET:
        side = foot.split("_")[0]
        steps = [s for s in spec.steps if s.part == foot]
        if not steps:
            continue
        track = _foot_track(kin, side, steps, keys, first, times)
        track = _fold_knee(kin, side, steps, track, poses, roots, times)
        goals.append(ik.Goal(f"{side}_foot.heel", track[:, :3, 3], track[:, :3, :3], 1.0, 2, leg(side)))
    q = track_solve(kin, poses, goals, roots)
    # the ends are the graph's postures exactly
    q[0], q[-1] = first.poses[SOLDIER], last.poses[SOLDIER]
    rifles[0], rifles[-1] = first.locations[RIFLE], last.locations[RIFLE]
    roots[0], roots[-1] = first.locations[SOLDIER], last.locations[SOLDIER]
    lift_off_ground(kin, q, roots, rifles)
    return ClipFrames(q, roots, rifles, fps)


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


def _kneel_down(dst: str, t: float) -> tuple[Step, ...]:
    """Standing -> kneeling on the right knee: step the left foot forward, lower the hips, right knee down."""
    return (
        Step("left_foot", dst, 0.0, 0.35 * t, lift=8.0),
        Step("right_foot", dst, 0.2 * t, 0.65 * t, lift=4.0),
        Step("root", dst, 0.08 * t, 0.8 * t),
        Step("legs", dst, 0.08 * t, 0.8 * t),
        Step("spine", dst, 0.15 * t, 0.8 * t),
        Step("head", dst, 0.25 * t, 0.75 * t),
    )


def _carry(dst: str, start: float, duration: float) -> tuple[Step, ...]:
    """Arms, fingers and rifle to ``dst`` together (the carry changes, e.g. low ready -> cradled)."""
    return (
        Step("arms", dst, start, duration),
        Step("rifle", dst, start, duration),
        Step("hands", dst, start, duration),
    )


def _down_to_crawl(src_end: float, t: float) -> tuple[Step, ...]:
    """From both knees (reached at ``src_end``) forward onto the forearms: the CRAWL posture at ``t``."""
    d = t - src_end
    return (
        Step("root", "CRAWL", src_end, d),
        Step("legs", "CRAWL", src_end, d),
        Step("spine", "CRAWL", src_end, 0.85 * d),
        Step("head", "CRAWL", src_end + 0.15 * d, 0.85 * d),
        *_carry("CRAWL", src_end, 0.9 * d),
    )


def _fall(src: str, t: float, knees: bool = True, kneeling: bool = False) -> tuple[Step, ...]:
    """Killed: the knees buckle onto the ground (``SLUMP``, the first ~40 %), then the body falls forward.

    No foot slides along the ground: a foot on it is planted (IK) until it moves, and it moves along an arc
    clear of the ground. Standing, both feet kick back off the ground as the knees hit it (the kneeling
    ``SLUMP`` has the feet behind the knees); ``kneeling`` (on the right knee), the shin on the ground stays
    where it is and the front foot lifts as its knee goes down beside the other. Then the legs flop up
    into ``DEAD`` as the body lands."""
    out: tuple[Step, ...] = ()
    t1 = 0.4 * t if knees else 0.0
    if knees:
        out += (
            Step("root", "SLUMP", 0.0, t1, VelocityControl.ACCELERATE),
            Step("legs", "SLUMP", 0.0, t1, EASE if kneeling else VelocityControl.ACCELERATE),
            Step("spine", "SLUMP", 0.0, t1),
            Step("head", "SLUMP", 0.05 * t, t1),
            *_carry("SLUMP", 0.0, t1),
        )
        if kneeling:
            out += (Step("left_foot", "SLUMP", 0.0, t1, lift=6.0, follow=True),)
        else:
            out += (
                Step("left_foot", "SLUMP", 0.05 * t, t1 - 0.08 * t, lift=8.0),
                Step("right_foot", "SLUMP", 0.08 * t, t1 - 0.1 * t, lift=8.0),
            )
    fall = t - t1
    d = 0.05 * t if knees else 0.0  # from the knees the feet leave just after the body starts to fall
    out += (
        Step("left_foot", "DEAD", t1 + d, fall - d, lift=12.0),
        Step("right_foot", "DEAD", t1 + d + 0.05 * t, fall - d - 0.05 * t, lift=12.0),
    )
    return (
        *out,
        Step("root", "DEAD", t1, fall, VelocityControl.ACCELERATE),
        Step("legs", "DEAD", t1, fall),
        Step("spine", "DEAD", t1, fall),
        Step("head", "DEAD", t1 + 0.1 * fall, 0.9 * fall),
        Step("arms", "DEAD", t1, fall),
        Step("rifle", "DEAD", t1, fall, VelocityControl.ACCELERATE),
        Step("hands", "DEAD", t1, 0.7 * fall),
    )


def _whole_to(dst: str, t: float, velocity: VelocityControl = EASE, lift: float = 0.0) -> tuple[Step, ...]:
    """Every body part to ``dst`` together; with ``lift`` the feet leave the ground along arcs that high
    (IK) rather than drag their toes to their new places."""
    feet = tuple(Step(f, dst, 0.0, t, velocity, lift) for f in FEET) if lift else ()
    return feet + tuple(
        Step(p, dst, 0.0, t, velocity) for p in ("root", "legs", "spine", "head", "arms", "hands", "rifle")
    )


# name, start, end, seconds (the arc times of seed 002 Figure 7; the elided ones invented), primitive motions
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
        (
            Step("root", "KNEEL_BOTH", 0.0, 0.9),
            Step("legs", "KNEEL_BOTH", 0.0, 0.9),
            Step("spine", "KNEEL_BOTH", 0.1, 0.8),
            Step("head", "KNEEL_BOTH", 0.1, 0.8),
            *_carry("KNEEL_BOTH", 0.1, 0.8),
            *_down_to_crawl(0.9, 2.0),
        ),
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
    TransitionSpec("ststow2dead", "STAND_STOWED", "DEAD", 1.5, _fall("STAND_STOWED", 1.5)),
    TransitionSpec(
        "stfire2kfire",
        "STAND_FIRE",
        "KNEEL_FIRE",
        1.2,
        _kneel_down("KNEEL_FIRE", 1.2) + _carry("KNEEL_FIRE", 0.0, 1.15),
    ),
    TransitionSpec("stfire2dead", "STAND_FIRE", "DEAD", 1.2, _fall("STAND_FIRE", 1.2)),
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
        (
            Step("root", "KNEEL_BOTH", 0.0, 0.5),
            Step("legs", "KNEEL_BOTH", 0.0, 0.5),
            Step("spine", "KNEEL_BOTH", 0.0, 0.5),
            Step("head", "KNEEL_BOTH", 0.0, 0.5),
            *_carry("KNEEL_BOTH", 0.0, 0.5),
            *_down_to_crawl(0.5, 1.4),
        ),
    ),
    TransitionSpec("kstow2dead", "KNEEL_STOWED", "DEAD", 1.0, _fall("KNEEL_STOWED", 1.0, kneeling=True)),
    TransitionSpec("kfire2dead", "KNEEL_FIRE", "DEAD", 1.0, _fall("KNEEL_FIRE", 1.0, kneeling=True)),
    TransitionSpec(
        "crawl2prstow",
        "CRAWL",
        "PRONE_STOWED",
        0.8,
        (
            Step("left_foot", "PRONE_STOWED", 0.0, 0.6, lift=8.0),
            Step("right_foot", "PRONE_STOWED", 0.1, 0.6, lift=8.0),
            Step("root", "PRONE_STOWED", 0.0, 0.8),
            Step("legs", "PRONE_STOWED", 0.0, 0.7),
            Step("spine", "PRONE_STOWED", 0.1, 0.7),
            Step("head", "PRONE_STOWED", 0.2, 0.6),
            *_carry("PRONE_STOWED", 0.05, 0.75),
        ),
    ),
    TransitionSpec(
        "prstow2prfire",
        "PRONE_STOWED",
        "PRONE_FIRE",
        0.8,
        _raise_rifle("PRONE_STOWED", "PRONE_FIRE", 0.8),
    ),
    TransitionSpec("crawl2dead", "CRAWL", "DEAD", 1.0, _fall("CRAWL", 1.0, knees=False)),
    TransitionSpec("prstow2dead", "PRONE_STOWED", "DEAD", 1.0, _whole_to("DEAD", 1.0, lift=10.0)),
    TransitionSpec("prfire2dead", "PRONE_FIRE", "DEAD", 0.8, _whole_to("DEAD", 0.8, lift=10.0)),
    TransitionSpec(
        "stfire2kstow",
        "STAND_FIRE",
        "KNEEL_STOWED",
        1.6,
        _kneel_down("KNEEL_STOWED", 1.6) + _carry("KNEEL_STOWED", 0.0, 0.9),
    ),
)
# Big changes of carry (down onto the forearms, falling dead): the rifle stays in the right hand, whose arm
# swings by interpolation, and only the left hand is solved onto it (IK on both arms jumped between
# elbow solutions on the way).
IN_HAND = frozenset(
    {
        "ststow2crawl",
        "kstow2crawl",
        "crawl2prstow",
        "ststow2dead",
        "stfire2dead",
        "kstow2dead",
        "kfire2dead",
        "crawl2dead",
    }
)
TRANSITIONS = tuple(dataclasses.replace(t, in_hand=t.name in IN_HAND) for t in TRANSITIONS)
DEAD_TO_STAND_SECONDS = 10.0  # DEAD -> STAND_STOWED: ststow2dead played backwards (seed 002 Figure 7)


def transition_specs() -> dict[str, TransitionSpec]:
    return {t.name: t for t in TRANSITIONS}
