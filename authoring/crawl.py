"""Crawling (seed 002, 3.3): the high crawl of the US Army's infantry manual, a start clip and one full cycle.

The seed's crawl was made by hand from two animations: one from the base (prone) posture into the cyclic
state, and one complete cycle; ending a crawl plays the start backwards. The base here is the graph's
``CRAWL`` posture: on forearms and knees, the body off the ground, the rifle cradled across the hands.

The high crawl moves the right elbow with the left knee, then the left elbow with the right knee (a trot of
diagonal pairs). Each limb touches the ground at the elbow (``upper_arm.distal``, the forearm lying behind
it), the kneecap (``lower_leg.knee``) and the tip of the toes (``toes.distal``); a planted limb stays where
it is in the world while the body glides over it; once per cycle of ``CYCLE`` seconds each pair (the right
knee's half a cycle after the left knee's) rises clear of the ground (``LIFT``), is carried forwards
``2 * STRIDE`` cm and put down again, so nothing drags. The start clip keeps one pair planted while the body
gets going and moves the other the part stride that puts every limb where the cycle starts with it.

The pelvis follows the planted knees (it may rise, pitch, yaw and roll: ``PELVIS_DOFS``, held back towards
its glide by ``PELVIS_HOLD``) and the spine keeps the chest on its own smooth glide: one batched IK solve of
the body from the posture. The rifle is carried by the forearms: it makes the ground-plane move that best
follows both elbows (``RIFLE_ON_FOREARMS`` of it, the rest the chest's carry), so it advances and yaws a
little with each arm's step and the hands stay within reach of the planted elbows. Then the arms are solved
on that body frame after frame in small steps (palms on the rifle first, then the elbows on their tracks):
a batched solve flipped the shoulders between Euler branches near their pole. The cycle's arms are tracked
round until they close the loop; the start clip blends a track out of the posture with one back from the
cycle's first frame. Like the gait clips the clips are local motion (the body's glide removed as a ramp,
``stride_length`` / ``ground_speed`` recorded).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from authoring import ik
from authoring.motion import KeyPosture
from authoring.postures import RIFLE, SOLDIER, SPINE, leg
from authoring.signal_shaping import hann_smooth, smoothstep
from authoring.transitions import CARRIER, ClipFrames, lift_off_ground
from peabody import values as V
from peabody.fk import FigureKinematics, rigid_inverse

FPS = 60
BASE = "CRAWL"
CYCLE = 0.8  # seconds per full cycle (each diagonal pair moves once)
STRIDE = 13.2  # cm the body glides per half cycle: 0.33 m/s
START = 0.4  # seconds of the start clip
SWING = 0.36  # seconds a limb takes to move forwards
LIFT = {"knee": 3.5, "toes": 4.5, "elbow": 5.0}  # cm a contact rises while it moves
ELBOW_CLEAR = 1.5  # cm the planted elbows sit higher in the cyclic state than in the posture
ELBOW_DELAY = 0.1  # s the start clip's first elbow move waits (the arm leaves the posture gently)
# the forearm planted through the start clip turns (the elbow's twist) from the posture's arm to the cycle's:
# it first lifts clear in START_CLEAR s (straight up, START_HOP cm above its cyclic height), then turns in
# the air and comes down to the cycle's height; turned on the ground it dragged its underside 3.5 cm sideways
START_CLEAR = 0.1
START_HOP = 2.0
START_SMOOTH = 3  # frames either side the start clip's arms are smoothed over (its tracks' twists jump apart)
ROLL = 3.0  # degrees the chest rolls towards the planted side
SWAY = 1.0  # cm the chest sways sideways
PELVIS_DOFS = ("ty", "rx", "ry", "rz")  # the pelvis rises, pitches, yaws and rolls over the planted knees
PELVIS_HOLD = 0.4  # weight of the pull back towards the pelvis's glide (more: the knees slide instead)
CHEST_HOLD = 0.1  # weight of the chest's glide (more: the spine's bend gets jerky, and DI's slaving with it)
RIFLE_ON_FOREARMS = 1.0  # how much the rifle follows the elbows' steps rather than the chest's glide
# (less than 1 moved the hands out of the reach of a planted elbow)
# the arms follow their goals frame by frame in at most ARM_ITERATIONS steps of ARM_DOF_STEP rad: no joint
# turns more than ~11 degrees from one frame to the next (near the shoulder's gimbal the solver would swap
# large, opposite changes of two angles for a small move of the arm)
ARM_ITERATIONS = 10
ARM_DOF_STEP = 0.02
CYCLE_PASSES = 2  # times the cycle's arms are tracked round again from where they ended
# contact sites of one leg: the kneecap and the tip of the toes (dug into the ground behind)
LEG_SITES = {"knee": "{s}_lower_leg.knee", "toes": "{s}_toes.distal"}
ELBOW_SITE = "{s}_upper_arm.distal"
# the diagonal pairs: a limb moves with the knee on this side (the right elbow with the left knee)
PAIR = {
    ("knee", "left"): "left",
    ("knee", "right"): "right",
    ("elbow", "right"): "left",
    ("elbow", "left"): "right",
}
CRAWL_NODES: tuple[str, ...] = ("CRAWL", "CRAWLING")


def lifts_slave_forearms(name: str) -> bool:
    """Whether clip ``name``'s DI slave has its arms re-solved by :mod:`authoring.slave_forearm_lift` (its
    forearms on the ground no longer than the master's): the cycle (4.46 -> 1.98 cm); its M16 slave passes
    without (2.98; 3.4-3.6 with). Also prstow2prfire (prone, not a crawl): the master's left forearm stays
    1.8 cm up and still while the rifle comes up, DI's dipped to 1.23 cm and slid 3.4 cm with the arm (its
    M16 slave 1.3). Every other clip is slaved as before."""
    return name in SLAVE_FOREARMS_LIFTED


SLAVE_FOREARMS_LIFTED = ("crawl_cycle", "prstow2prfire")


def crawl_arcs() -> list[tuple[str, str, str, bool]]:
    """(from, to, clip, forward) of the crawl graph; ``CRAWLING`` is the cyclic state."""
    return [
        ("CRAWL", "CRAWLING", "crawl_start", True),
        ("CRAWLING", "CRAWLING", "crawl_cycle", True),
        ("CRAWLING", "CRAWL", "crawl_start", False),
    ]


def _speed() -> float:
    return 2.0 * STRIDE / CYCLE


def body_travel(t: np.ndarray) -> np.ndarray:
    """The body's glide (cm along +Z, so negative = forwards) at time ``t``: still at first, reaching the
    cycle speed when the cycle starts (a Hermite ease that ends with the cycle's slope), then steady."""
    v = _speed()
    d_start = 0.5 * v * START
    u = np.clip(t / START, 0.0, 1.0)
    return np.where(t <= START, -d_start * (2.0 * u**3 - u**4), -d_start - v * (t - START))


def _first_swing() -> float:
    """Cycle time the left leg starts to move (the right moves half a cycle later): the time that puts the
    left knee, planted through the whole start clip, exactly where the cycle starts with it."""
    v = _speed()
    half = 0.5 * v * (CYCLE - SWING)
    return CYCLE - SWING - (half - float(body_travel(np.array(START)))) / v


def swings(side: str, t_end: float) -> list[tuple[float, float]]:
    """(start time, cm forwards) of every move of one diagonal pair (named by its knee) up to ``t_end``.

    In the cycle each pair moves ``2 * STRIDE`` once, the left knee's at :func:`_first_swing`, the right
    knee's half a cycle later; between its moves a limb stays planted while the body glides over it. In the
    start clip the body glides ``-body_travel(START)`` cm while the left knee's pair stays planted (its cycle
    timing is chosen so that this is exactly where the cycle wants it), and the other pair makes the one
    shorter move that puts it where the cycle starts with it: every contact of the start clip's last frame is
    the cycle's first.
    """
    v = _speed()
    a = _first_swing() + (0.0 if side == "left" else 0.5 * CYCLE)
    if a < 0.0 or a + SWING > CYCLE + 1e-9:
        raise ValueError("a limb's move must fit in the cycle")
    # where the contact is relative to the body (0 = where the CRAWL posture has it) at the cycle's start:
    # in stance since (a + SWING - CYCLE), from half a stance's glide ahead of the posture's place
    half = 0.5 * v * (CYCLE - SWING)
    rel = -half + v * (CYCLE - a - SWING)
    out: list[tuple[float, float]] = []
    first = -(float(body_travel(np.array(START))) + rel)  # how far the start clip must move it
    if abs(first) > 1e-6:
        t0 = START + a - CYCLE  # so that it lands when its stance of the cycle begins
        if t0 < -1e-9 or first < 0.0:
            raise ValueError("the start clip cannot put this leg where the cycle starts")
        out.append((t0, first))
    k = 0
    while START + a + k * CYCLE < t_end:
        out.append((START + a + k * CYCLE, 2.0 * STRIDE))
        k += 1
    return out


def contact_progress(s: np.ndarray) -> np.ndarray:
    """How far along its path a moving contact is (0..1) at ``s`` (0..1) of its move: it rises first and
    travels while clear of the ground."""
    return smoothstep((s - 0.12) / 0.76)


def contact_rise(s: np.ndarray) -> np.ndarray:
    """Height (fraction of the lift) of a moving contact at ``s`` of its move: up, across, down."""
    inside = (s > 0.0) & (s < 1.0)
    return np.where(inside, np.minimum(smoothstep(s / 0.3), smoothstep((1.0 - s) / 0.3)), 0.0)


def contact_track(
    p0: np.ndarray, t: np.ndarray, moves: list[tuple[float, float]], lift: float, delay: float = 0.0
) -> np.ndarray:
    """World track ``(n, 3)`` of a contact that starts at ``p0``: planted, except during its moves. A move
    that starts within ``delay`` s of the clip's start starts ``delay`` later and lands on time (quicker)."""
    track = np.tile(p0, (len(t), 1))
    for t0, dist in moves:
        late = delay if t0 < delay else 0.0
        s = (t - t0 - late) / (SWING - late)
        track[:, 2] -= dist * contact_progress(s)
        track[:, 1] += lift * contact_rise(s)
    return track


def _rigid_xz(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)``: per frame the move in the ground plane (a turn about +Y and a shift) that best takes the
    points ``a`` ``(k, 3)`` to ``b`` ``(n, k, 3)`` (2-D Procrustes; heights follow the mean)."""
    ca = a.mean(axis=0)
    cb = b.mean(axis=1)
    pa = (a - ca)[:, [0, 2]]
    pb = (b - cb[:, None, :])[..., [0, 2]]
    cross = (pa[None, :, 0] * pb[..., 1] - pa[None, :, 1] * pb[..., 0]).sum(axis=1)
    dot = (pa[None] * pb).sum(axis=(1, 2))
    ang = np.arctan2(cross, dot)  # turn in the x-z plane, x towards z
    c, s = np.cos(ang), np.sin(ang)
    out = np.broadcast_to(np.eye(4), (len(b), 4, 4)).copy()
    out[:, 0, 0], out[:, 0, 2], out[:, 2, 0], out[:, 2, 2] = c, -s, s, c
    out[:, :3, 3] = cb - np.einsum("nij,j->ni", out[:, :3, :3], ca)
    return out


def carried_rifle(
    rifle0: np.ndarray, chest0: np.ndarray, chest: np.ndarray, elbows: dict[str, np.ndarray]
) -> np.ndarray:
    """Rifle placements ``(n, 4, 4)``: carried by the chest (``chest0`` -> ``chest``), blended
    (:data:`RIFLE_ON_FOREARMS`) with the ground-plane move that follows the elbows (``elbows[side]``: world
    tracks ``(n, 3)``, the posture's places first) so each hand goes forwards with its forearm's step."""
    from authoring.transitions import slerp_frames

    by_chest = chest @ rigid_inverse(chest0) @ rifle0
    a = np.stack([elbows["left"][0], elbows["right"][0]])
    b = np.stack([elbows["left"], elbows["right"]], axis=1)
    by_arms = _rigid_xz(a, b) @ rifle0
    by_arms[:, 1, 3] = by_chest[:, 1, 3]
    out = np.empty_like(by_chest)
    for i in range(len(out)):  # blend each frame: positions lerp, rotations slerp
        out[i] = slerp_frames(by_chest[i], by_arms[i], np.array([RIFLE_ON_FOREARMS]))[0]
    return out


def rifle_hand_goals(
    kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture, rifles: np.ndarray
) -> list[ik.Goal]:
    """Palm centres on the rifle (first priority) and turned to hold it, each exactly as in the posture."""
    from authoring.postures import arm, palm_targets
    from authoring.transitions import palm_offsets

    off = palm_offsets(kin, rkin, key)
    goals = []
    for side in ("right", "left"):
        tgt = palm_targets(rkin, rifles, side) @ off[side]
        site = f"{side}_palm.palmcenter"
        goals.append(ik.Goal(site, tgt[:, :3, 3], None, 1.0, 3, arm(side)))
        goals.append(ik.Goal(site, None, tgt[:, :3, :3], 1.0, 0, arm(side), orientation_weight=2.0))
    return goals


def _track(
    kin: FigureKinematics,
    body: np.ndarray,
    goals: list[ik.Goal],
    roots: np.ndarray,
    order: np.ndarray,
    first: np.ndarray,
) -> np.ndarray:
    """Solve the arms frame after frame in ``order``, from the arms of ``first`` and then each from (and
    pulled towards) the previous frame's arms on this frame's body, in small steps, so they cannot jump
    between IK branches from one frame to the next. Returns the poses of the frames in ``order``."""
    arms = np.zeros(kin.ndof, dtype=bool)
    for side in ("left", "right"):
        for j in (f"{side}_clavicle", f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"):
            arms[kin.dof_slices[j]] = True
    out = np.empty((len(order), kin.ndof))
    prev = first
    for k, i in enumerate(order):
        start = np.where(arms, prev, body[i])
        out[k] = prev = ik.solve_frame(kin, start, goals, roots, i, ARM_ITERATIONS, ARM_DOF_STEP)
    return out


def solve_arms(
    kin: FigureKinematics,
    body: np.ndarray,
    goals: list[ik.Goal],
    roots: np.ndarray,
    n_start: int,
    start_goals: list[ik.Goal] | None = None,
    start_blend: np.ndarray | None = None,
    start_smooth: int = 0,
) -> np.ndarray:
    """The arms over the start clip and the cycle (frames ``n_start`` to the last, which is the first one
    cycle on): the cycle is tracked from where it ends until its arms come round to where they started (a
    loop without a jump), the start clip forwards from the posture and backwards from the cycle's first
    frame, the two blended (ease in/out, or per frame and DOF ``start_blend`` ``(n_start + 1, ndof)``) so it
    leaves the posture and meets the cycle exactly. ``start_goals`` (default ``goals``) are the start clip's:
    the cycle is tracked on ``goals`` alone; ``start_smooth``: the blend smoothed over that many frames
    either side (its ends kept)."""
    n = len(body)
    cycle = np.arange(n_start, n)
    cyc = _track(kin, body, goals, roots, np.arange(n), body[0])[n_start:]
    for _ in range(CYCLE_PASSES):
        cyc = _track(kin, body, goals, roots, cycle, cyc[-1])
    goals = goals if start_goals is None else start_goals
    fwd = _track(kin, body, goals, roots, np.arange(n_start + 1), body[0])
    bwd = _track(kin, body, goals, roots, np.arange(n_start, -1, -1), cyc[0])[::-1]
    w = smoothstep(np.linspace(0.0, 1.0, n_start + 1))[:, None] if start_blend is None else start_blend
    blend = fwd + w * (bwd - fwd)
    if start_smooth:  # the tracks' twists swing apart within a few frames: spread the blend's change out
        ends = smoothstep(np.minimum(np.arange(n_start + 1), np.arange(n_start, -1, -1)) / start_smooth)
        arms = np.zeros(kin.ndof, dtype=bool)
        for side in ("left", "right"):
            for j in (f"{side}_clavicle", f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"):
                arms[kin.dof_slices[j]] = True
        blend[:, arms] += ends[:, None] * (hann_smooth(blend[:, arms], start_smooth) - blend[:, arms])
    rows = slice(0, n_start + 1)  # and the blend's hands put back on the rifle, in a few very small steps
    blend, _ = ik.solve(
        kin,
        blend,
        [g.rows(rows) for g in goals],
        roots[rows],
        iterations=4,
        rest_pose=blend,
        rest_gain=0.1,
        max_dof_step=0.5 * ARM_DOF_STEP,
    )
    return np.concatenate([blend, cyc[1:]])


def solve_body(
    kin: FigureKinematics,
    q0: np.ndarray,
    chest: np.ndarray,
    roots: np.ndarray,
    legs: Callable[[str, str], np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """The body (pelvis, spine, legs) over the frames, one batched IK solve from the posture ``q0``: the chest
    kept lightly on its frames ``chest`` (the carrier's), the pelvis free to follow the planted knees (it may
    rise, pitch, yaw and roll: ``PELVIS_DOFS``) but held back towards ``roots`` (moving it is cheap for the
    solver, and a pelvis that rolls to lift the moving leg twists the planted one), each kneecap and toe tip
    on its world track ``legs(side, part)``. Returns the poses and the pelvis's frames."""
    goals: list[ik.Goal] = [
        ik.Goal(
            f"{CARRIER}.proximal",
            chest[:, :3, 3],
            chest[:, :3, :3],
            CHEST_HOLD,
            1,
            SPINE,
            orientation_weight=40.0,
        ),
        ik.Goal(kin.root_name, roots[:, :3, 3], roots[:, :3, :3], PELVIS_HOLD, 1, ()),
    ]
    for side in ("left", "right"):
        for part, fmt in LEG_SITES.items():
            chain = leg(side) if part == "knee" else (f"{side}_hip", f"{side}_knee", f"{side}_toes")
            goals.append(ik.Goal(fmt.format(s=side), legs(side, part), None, 1.0, 1, chain))
    rest = np.broadcast_to(q0, (len(roots), kin.ndof)).copy()
    poses, report = ik.solve(
        kin, rest, goals, roots, iterations=80, rest_pose=rest, rest_gain=0.1, root_dofs=PELVIS_DOFS
    )
    assert report.root_location is not None  # solved with root DOFs: the solve reports where the root went
    return poses, report.root_location


def record_crawl(kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture) -> tuple[np.ndarray, ...]:
    """Frames of the start clip followed by one cycle: (t, poses, roots, rifles, progression z)."""
    from authoring.postures import arm

    n_start = round(START * FPS)
    n_cycle = round(CYCLE * FPS)
    n = n_start + n_cycle + 1
    t = np.arange(n) / FPS
    tc = t - START  # cycle time (negative during the start)
    q0, root0, rifle0 = key.poses[SOLDIER], key.locations[SOLDIER], key.locations[RIFLE]
    z = body_travel(t)
    w = smoothstep(t / START)  # how far into the cyclic state
    g0 = kin.site_globals(q0, root0)
    roots = np.broadcast_to(root0, (n, 4, 4)).copy()
    roots[:, 2, 3] += z
    # the chest glides with the body, rolling a little towards the planted elbow
    chest0 = kin.segment_globals(q0, root0)[kin.segment_names.index(CARRIER)]
    phase = 2.0 * np.pi * (tc - _first_swing() - 0.5 * SWING) / CYCLE
    roll = w * ROLL * np.sin(phase) * np.pi / 180.0
    chest = np.broadcast_to(chest0, (n, 4, 4)).copy()
    chest[:, :3, :3] = np.stack([V.rot_z(r)[:3, :3] for r in roll]) @ chest0[:3, :3]
    chest[:, 2, 3] += z
    chest[:, 0, 3] += w * SWAY * np.sin(phase)

    def legs(side: str, part: str) -> np.ndarray:
        moves = swings(PAIR["knee", side], float(t[-1]))
        return contact_track(
            g0[kin.site_names.index(LEG_SITES[part].format(s=side)), :3, 3], t, moves, LIFT[part]
        )

    poses, roots = solve_body(kin, q0, chest, roots, legs)
    # then the arms on the body: elbows on their tracks, the palms on the rifle the forearms carry
    elbows: dict[str, np.ndarray] = {}
    arm_goals: list[ik.Goal] = []
    for side in ("left", "right"):
        site = ELBOW_SITE.format(s=side)
        moves = swings(PAIR["elbow", side], float(t[-1]))
        elbows[side] = contact_track(
            g0[kin.site_names.index(site), :3, 3], t, moves, LIFT["elbow"], delay=ELBOW_DELAY
        )
        elbows[side][:, 1] += ELBOW_CLEAR * w  # (the forearm pivots about the elbow: off the ground)
        arm_goals.append(ik.Goal(site, elbows[side], None, 1.0, 1, (f"{side}_clavicle", *arm(side)[:2])))
    chest_now = kin.segment_globals(poses, roots)[:, kin.segment_names.index(CARRIER)]
    rifles = carried_rifle(rifle0, chest0, chest_now, elbows)
    hands = rifle_hand_goals(kin, rkin, key, rifles)
    start_goals, start_blend = _start_lift(kin, t, elbows, arm_goals, n_start)
    poses = solve_arms(
        kin, poses, hands + arm_goals, roots, n_start, hands + start_goals, start_blend, int(START_SMOOTH)
    )
    poses[0], roots[0], rifles[0] = q0, root0, rifle0
    lift_off_ground(kin, poses, roots, rifles)
    # the cycle's last frame is its first, one cycle further on (pose, pelvis and rifle)
    poses[-1] = poses[n_start]
    for frames in (roots, rifles):
        frames[-1] = frames[n_start]
        frames[-1, 2, 3] += z[-1] - z[n_start]
    return t, poses, roots, rifles, z


def _start_lift(
    kin: FigureKinematics, t: np.ndarray, elbows: dict[str, np.ndarray], goals: list[ik.Goal], n_start: int
) -> tuple[list[ik.Goal], np.ndarray]:
    """The start clip's elbow goals and arm blend ``(n_start + 1, ndof)``: the elbow planted through it
    (its pair moves first in the cycle) lifts clear first (:data:`START_CLEAR`, :data:`START_HOP`) and its
    arm turns from the posture's into the cycle's only then; the other arm as :func:`solve_arms` blends it."""
    u = t[: n_start + 1] / START
    w = smoothstep(u)
    blend = np.repeat(w[:, None], kin.ndof, axis=1)
    out = []
    for side, goal in zip(("left", "right"), goals, strict=True):
        if any(t0 < START for t0, _ in swings(PAIR["elbow", side], float(t[-1]))):
            out.append(goal)
            continue
        up = smoothstep(t / START_CLEAR)
        hop = up - smoothstep((t - START_CLEAR) / (START - START_CLEAR))
        track = elbows[side].copy()
        track[:, 1] += ELBOW_CLEAR * (up - smoothstep(t / START)) + START_HOP * hop
        out.append(dataclasses.replace(goal, target_position=track))
        late = smoothstep((u - START_CLEAR / START) / (1.0 - START_CLEAR / START))
        for j in (f"{side}_clavicle", f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"):
            blend[:, kin.dof_slices[j]] = late[:, None]
    return out, blend


def _cut(
    t: np.ndarray, poses: np.ndarray, roots: np.ndarray, rifles: np.ndarray, z: np.ndarray, i0: int, i1: int
) -> tuple[ClipFrames, float, float]:
    sl = slice(i0, i1 + 1)
    travel = z[i1] - z[i0]
    u = (t[sl] - t[i0]) / (t[i1] - t[i0])
    r, f = roots[sl].copy(), rifles[sl].copy()
    shift = z[i0] + u * travel
    r[:, 2, 3] -= shift
    f[:, 2, 3] -= shift
    dist = abs(float(travel))
    return ClipFrames(poses[sl].copy(), r, f, FPS), dist, dist / (t[i1] - t[i0])


_CACHE: dict[int, dict[str, tuple[ClipFrames, float, float]]] = {}


def _record(ctx: Any) -> dict[str, tuple[ClipFrames, float, float]]:
    if id(ctx) not in _CACHE:
        _CACHE.clear()
        kin, rkin = FigureKinematics(ctx.soldier), FigureKinematics(ctx.rifle)
        t, poses, roots, rifles, z = record_crawl(kin, rkin, ctx.keys[BASE])
        ns = round(START * FPS)
        _CACHE[id(ctx)] = {
            "crawl_start": _cut(t, poses, roots, rifles, z, 0, ns),
            "crawl_cycle": _cut(t, poses, roots, rifles, z, ns, len(t) - 1),
        }
    return _CACHE[id(ctx)]


def crawl_clips() -> dict[str, Callable[[Any], tuple[ClipFrames, float, float]]]:
    """Clip name -> generator taking the build context."""
    return {name: _clip_of(name) for name in ("crawl_start", "crawl_cycle")}


def _clip_of(name: str) -> Callable[[Any], tuple[ClipFrames, float, float]]:
    """One generator per clip (a lambda in a loop would late-bind the name)."""
    return lambda ctx: _record(ctx)[name]
