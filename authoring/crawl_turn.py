"""Turning in place on forearms and knees (issue 16): CRAWL to CRAWL turned about the belly.

A crawling soldier cannot turn while he crawls: a leopard crawl always has two limbs a metre apart on the
ground, so a body turning over them drags them. Like a person on the ground he turns on the spot instead,
about a pivot under the belly (halfway between the elbows and the knees): the front (both forearms, the
hands and the rifle between them, as the CRAWL posture has them) is lifted a little, carried round the pivot
by a step of at most ``STEP`` degrees and set down, the knees and toes staying where they are; then the
knees and toes are lifted and swung round after it while the forearms stay; and so on until the turn is
done (:func:`part_moves`). Moving the forearms together keeps the rifle in both hands without stretching an
arm: one forearm stepping sideways alone changed the elbows' distance by 10-12 cm, the other arm could not
follow and its planted elbow slid 11 cm. A planted limb stays where it is in the world.

The chest turns mostly with the front and the pelvis mostly with the knees (:data:`CHEST_FRONT`,
:data:`PELVIS_FRONT`); the pelvis is free to rise, pitch, yaw and roll over the planted knees, held back
towards its turn, and the spine keeps the chest on its own (one batched IK solve of the body, as in
:mod:`authoring.crawl`); then the arms are tracked frame after frame (palms on the rifle first, then the
elbows on their tracks), so no joint leaps between IK branches.

A crawler turns so too, but on the move (``crawlarc_*``, :data:`ARC_ADVANCE`): each move also carries its
part forward, along the heading it turns to, as a crawl stride would, so that the pivot under the belly moves
with the entity (turned on the spot he ended 1.3 m behind a crawling entity and caught up over 5 s). A
crawler whose entity reverses (``crawlarc_r180``, :data:`U_TURN`) comes round so too, each move carrying him
along the new heading, the way his entity now crawls, little while he faces away from it and more as he
comes round (:func:`part_yaw`): he edges back, sidles, then crawls along it as he turns (the 90° on the spot
and the 90° arc after it left him 90 cm from his entity, 75 cm beside its path).

Like the standing turns (:mod:`authoring.turns`) these clips really move the soldier: the clip frame is
CRAWL's, the last frame is CRAWL moved by the ground-plane rigid move recorded as the channelset's
``end_offset`` (x cm, z cm, yaw deg, + = left).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import numpy as np

from authoring import easing, ik
from authoring.crawl import (
    ELBOW_SITE,
    LEG_SITES,
    LIFT,
    contact_progress,
    contact_rise,
    rifle_hand_goals,
    solve_body,
)
from authoring.ground_frames import turned_about
from authoring.motion import KeyPosture
from authoring.postures import RIFLE, SOLDIER, SPINE, arm
from authoring.signal_shaping import gaussian, smoothstep
from authoring.transitions import CARRIER, ClipFrames, lift_off_ground, track_solve
from peabody.fk import FigureKinematics

FPS = 60
BASE = "CRAWL"
SIDES = ("left", "right")
TURN_ANGLES = (30, 45, 90)  # a crawling soldier turns the nearest (another after it if far off)
# ... a crawler's turns: the U-turn too, carried along its end heading, to his right (either way serves a
# reversal)
U_TURN = "crawlarc_r180"
# ... and the shorter ones, built the same way (a 135-165° reversal: turned on the spot and then the arcs he
# ended 108 cm from his entity at 150°; the U-turn and the rest turned crawling on, 34 cm at 165°), to his
# right and to his left
U_TURN_ANGLES = (135, 150, 165, 180)
LEFT_U_TURN_ANGLES = (135, 150, 165)
# share of the front's carry in the chest's and the pelvis's on a U-turn to his left: the body follows the
# forearms, not the knees. The rifle across his body, his right elbow is near its reach in CRAWL: with
# ADVANCE_FRONT the knees' moves carried the shoulders away from it to his left and the planted right forearm
# slid 31 cm at 150°, the palms left the rifle 2.7 cm; 0.8: 7.0 cm; 1.0: 2.8 cm at 165° (the check's 3 cm),
# 3.0 at 150°, 3.5 at 135°, as the knees make their last move (the chest carried 1.1-1.2 of the front's:
# 4.4-4.5 cm; chest and pelvis 1.2-1.4: the right forearm 2.2-2.5 but the pelvis dragged the left thigh 4-8
# cm); with the pelvis's share below, 1.8-2.0 cm at 150° and 1.0 at 135°
LEFT_U_TURN_AHEAD = 1.0
# ... and in the pelvis's alone, each pair of moves (its front move and the knees' after it): carried with
# the forearms a whole move ahead of the knees, the DI slave's pelvis pulled its thighs flat, its belly lay on
# the ground and slid 6.1 cm and its hips popped up (20.4 degrees in a frame) as the knees made their last
# move; its right knee slid 5.8 cm as the fifth front move carried the pelvis. Less in the last two pairs (the
# soldier's right elbow no longer at its reach as he comes round) and a little less in the first (at 1.0 the
# DI's right wrist flicked 15.2 degrees there). Sensitive, the DI's left wrist above all: 0.5 throughout, the
# soldier's right forearm slid 4.3 cm in the fourth pair; 0.75 throughout, 3.5 cm in the last; 0.6 in the
# last, the DI's hips popped 24 degrees; in the fifth 0.5, 0.55, 0.6: its left wrist flicked 15.1, 18.5, 15.1
# degrees; 0.7: the M16 slave's right forearm slid 4.1 cm. 150° and 135° (five pairs): the 165°'s last two
# at 150°, the DI's left wrist flicked 19.2 degrees (at its limits, holding the handguard), the M16's belly
# stepped 18.6 onto another branch as the knees made their last move; 1.0 in the fourth pair and 0.45 in the
# last, 14.3 and 10.9 (0.5 in the last: the M16's belly 18.2; 0.6: 14.5). At 135° 1.0 in the fourth pair
# dragged the DI's right knee 5.3 cm; with 0.45 there the DI's left wrist flicked 15.8-20.0 degrees whatever
# the last pair's (0.45, 0.5, 0.6) or the fourth's (0.5): eased (LEFT_U_TURN_WRISTS_EASED)
LEFT_U_TURN_PELVIS_AHEAD = {
    165.0: (0.75, 1.0, 1.0, 1.0, 0.45, 0.5),
    150.0: (0.75, 1.0, 1.0, 1.0, 0.45),
    135.0: (0.75, 1.0, 1.0, 0.45, 0.5),
}
# ... the U-turns to his left whose DI/M16 slaves have their wrists eased where they flick (slave_wrists): the
# DI's left wrist 15.85 -> 12.0 degrees at 135°, 14.3 -> 9.0 at 150° (the palm 0.58 and 0.50 cm off the rifle)
LEFT_U_TURN_WRISTS_EASED = (135, 150)
# ... and a U-turn for a faster entity, carrying him further as fast: more, shorter moves, each as quick in
# degrees a second (143.5 cm in 4.2 s at the server's GROUND_TURN_RATE; 0.45 m/s: the U-turn's 103.5 cm in
# 4 s left him 48 cm behind, played faster his body would swing over 360°/s; 25-30 cm a move, his arms fell
# 9-13 cm short; moves at 0.7 of MOVE swung his body at 365°/s)
U_TURN_FAR = "crawlarc_r180_far"
U_TURN_FAR_STEP, U_TURN_FAR_TEMPO = 22.5, 0.75  # degrees a move at most, share of MOVE it takes
STEP = 30.0  # degrees a part turns at most in one move (elbows and knees ~25 cm, the toes ~48 cm)
MOVE = {"front": 0.4, "back": 0.46}  # s a part takes to move (the crawl's limbs: 0.36 s for 26 cm)
ELBOW_LIFT = 3.0  # cm the forearms (and the rifle) rise while the front moves
CHEST_FRONT = 1.0  # share of the front's turn in the chest's (the rest the knees': 0.8 put the right
# elbow, near the end of its reach in CRAWL, 2-4 cm off its place while it was down)
PELVIS_FRONT = 0.25  # ... in the pelvis's
GAP = 0.06  # s all four limbs are down between two moves
LEAD_IN = 0.25  # s before the first pair lifts (the body sets off)
SETTLE = 0.4  # s after the last pair lands (the body comes round to the end)
# cm a crawler's turn (crawlarc_*) carries each part forward per move, along the heading it turns to (a crawl
# stride: 26 cm): 60 cm over a 90° turn, about what a 0.3 m/s entity crawls while the server plays it (2.2 s)
ARC_ADVANCE = 20.0
# share of the front's advance in the chest's and the pelvis's (the chest carried with the front and the
# pelvis 0.25 of it stretched the trunk 15 cm: the arms fell short, forearms slid 3.3-4.4 cm, palms 3 cm)
ADVANCE_FRONT = 0.5
# a U-turn's moves carry him ARC_ADVANCE on average, in proportion to this + the cosine of the angle between
# the way the part turns to and the end heading: 13.5 cm the first move (facing away), 25 the last. 20 cm
# each pushed his right upper arm 1.1 cm into the rifle as he edged back; 10.5-28 cm (2 + cos) pulled a
# planted knee 1.6 cm as he came round (3 + cos: 0.7 and 1.5)
U_TURN_EVEN = 3.0
# how a U-turn to his right tracks its arms over the clip (transitions.track_solve): from the start alone,
# his right arm, its elbow planted near its reach as the knees carry the shoulders on, ran its clavicle,
# shoulder and wrist into their limits and leapt 9-12 degrees a joint onto another branch in one frame (the
# upper arm 3.1-4.2 cm, pop_m_s 1.67-1.89) as the knees made their first (135°, 150°: frame 66) or fourth
# (165°, 180°: frame 242) move. Tracked back from the end the 135° and 150° keep one branch (pop_m_s 1.24,
# 1.10; from both ends 1.72, 1.54), the 165° and 180° from both ends, blended (1.39, 1.30; back alone 1.47,
# 1.60). The far U-turn leaps whichever way (1.99 both, 2.45 back): left as it was
ArmTrack = Literal["forward", "backward", "both"]
U_TURN_ARMS: dict[float, ArmTrack] = {135.0: "backward", 150.0: "backward", 165.0: "both", 180.0: "both"}

# frames the U-turns to his left smooth their spine over (:func:`smooth_spine`, before the arms are solved):
# the body solve, his chest carried with the forearms, left his vertebrae taking turns at their limits, 1-6
# degrees a frame back and forth, and the chest popped 2.2-2.6 m/s as the forearms set off (135°: 2.49 ->
# 0.65 m/s; sigma 1.5: 1.41 but the right forearm slid 5.3 cm; solved frame after frame, each from the last,
# or to full convergence, the spine jittered as much)
LEFT_U_TURN_SPINE_SIGMA = 0.8
# share of each front move at either end the U-turns to his left lift and set down their forearms in place
# (Plan.front_clear): travelling from 0.12 to 0.88 of the move (authoring.crawl.contact_progress), 3 cm up at
# most, the forearms came down still travelling and the planted right forearm skimmed 2.5 cm as it landed,
# within the check's LIFT_OFF_CM (135°: the right forearm 3.25 -> 1.31 cm; M16 4.54 -> 2.24 but its belly pops
# 1.72 m/s; 165°: 3.04 -> 1.81, M16 4.90 -> 2.80 and its right upper arm's pop 2.03 -> 0.89). At 150° the
# right thigh and the DI's right knee drag with the pelvis whatever the forearms do (4.1, 5.2 cm), and the
# slaves popped 1.8-2.1 m/s: left as it was. Lifted 4.5 cm as well, the DI's right forearm slid 4.8 cm at 165°
# (s21: with 0.1 and the fourth pair's pelvis 0.6, 0.75, 0.85 the thigh stays put but the planted right
# forearm drags as the knees' move carries the pelvis the rest, frames 208-254: 5.49, 5.70, 3.56 cm; the DI's
# right knee 4.27 cm at 0.85 (right foot pop 1.34-1.79 m/s), the M16's right forearm 7.76-7.88 whatever the
# pelvis; 0.92: the soldier's right forearm 3.23 cm; 0.85 without front_clear: 4.30)
LEFT_U_TURN_FRONT_CLEAR = {135.0: 0.1, 165.0: 0.1}


def clip_name(direction: str, angle: float, advance: float = 0.0) -> str:
    return f"crawl{'arc' if advance else 'turn'}_{direction[0]}{angle:g}"


class Plan(NamedTuple):
    """How one turn on the ground is recorded."""

    direction: str  # "left" or "right"
    angle: float  # degrees
    advance: float = 0.0  # cm a move carries its part forward
    step: float = STEP  # degrees a move turns at most
    tempo: float = 1.0  # share of MOVE a move takes
    ahead: float = ADVANCE_FRONT  # share of the front's carry in the chest's and the pelvis's
    pelvis_ahead: tuple[float, ...] | None = None  # ... in the pelvis's, each pair of moves (None: ``ahead``)
    slave_wrists_eased: bool = False  # the DI/M16 slaves' wrists eased where they flick (slave_wrists)
    arms: ArmTrack = "forward"  # the arms tracked from the start, "backward" from the end, "both" blended
    spine_sigma: float = 0.0  # frames the body solve's spine is smoothed over before the arms (0: not)
    front_clear: float = 0.0  # share of a front move at either end the forearms rise or land in place


_PLANS: dict[str, Plan] = {
    clip_name(d, a, adv): Plan(d, float(a), adv)
    for adv in (0.0, ARC_ADVANCE)
    for d in SIDES
    for a in TURN_ANGLES
}
_PLANS.update(
    {
        clip_name("right", a, ARC_ADVANCE): Plan("right", float(a), ARC_ADVANCE, arms=U_TURN_ARMS[float(a)])
        for a in U_TURN_ANGLES
    }
)
_PLANS[U_TURN_FAR] = Plan("right", 180.0, ARC_ADVANCE, U_TURN_FAR_STEP, U_TURN_FAR_TEMPO)
_PLANS.update(
    {
        clip_name("left", a, ARC_ADVANCE): Plan(
            "left",
            float(a),
            ARC_ADVANCE,
            ahead=LEFT_U_TURN_AHEAD,
            pelvis_ahead=LEFT_U_TURN_PELVIS_AHEAD[float(a)],
            slave_wrists_eased=a in LEFT_U_TURN_WRISTS_EASED,
            spine_sigma=LEFT_U_TURN_SPINE_SIGMA,
            front_clear=LEFT_U_TURN_FRONT_CLEAR.get(float(a), 0.0),
        )
        for a in LEFT_U_TURN_ANGLES
    }
)
CRAWL_TURN_CLIPS: tuple[str, ...] = tuple(_PLANS)


def plan_of(name: str) -> Plan:
    """How clip ``name`` (one of :data:`CRAWL_TURN_CLIPS`) is recorded."""
    return _PLANS[name]


def eases_slave_wrists(name: str) -> bool:
    """Whether clip ``name``'s DI/M16 slaves have their wrists eased where they flick
    (:mod:`authoring.slave_wrists`): a turn on the ground whose plan asks for it."""
    plan = _PLANS.get(name)
    return plan is not None and plan.slave_wrists_eased


def crawl_turn_arcs() -> list[tuple[str, str, str, bool]]:
    """(from, to, clip, forward): every clip is a self-loop on CRAWL (it moves the soldier)."""
    return [(BASE, BASE, name, True) for name in CRAWL_TURN_CLIPS]


def part_moves(
    direction: str, angle: float, step: float = STEP, tempo: float = 1.0
) -> tuple[dict[str, list[tuple[float, float, float]]], float]:
    """Per part (``"front"``: the forearms and the rifle, ``"back"``: the knees and toes) its moves (start
    s, yaw from, yaw to; degrees, + = left) and the time the last one lands: the front turns a ``step`` of at
    most ``STEP`` degrees, then the back catches up, and again, until the turn is done; each move takes
    ``tempo`` times its MOVE."""
    sign = 1.0 if direction == "left" else -1.0
    steps = math.ceil(angle / step - 1e-9)
    moves: dict[str, list[tuple[float, float, float]]] = {"front": [], "back": []}
    t = LEAD_IN
    for k in range(steps):
        a, b = sign * angle * k / steps, sign * angle * (k + 1) / steps
        for part in ("front", "back"):
            moves[part].append((t, a, b))
            t += MOVE[part] * tempo + GAP
    return moves, t - GAP


def part_yaw(
    t: np.ndarray,
    moves: list[tuple[float, float, float]],
    duration: float,
    advance: float = 0.0,
    along: float | None = None,
    clear: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A part's yaw (degrees) about the pivot at ``t``, how far (share of its lift) it is raised, and
    ``(n, 2)`` how far (X, Z cm) it is carried: ``advance`` cm a move along the heading it turns to (or
    along the heading ``along`` degrees, every move). It rises first and moves while clear of the ground
    (:func:`authoring.crawl.contact_progress`)."""
    yaw = np.zeros(len(t))
    up = np.zeros(len(t))
    carried = np.zeros((len(t), 2))
    share = np.ones(len(moves))
    if along is not None:  # less while he faces away from it, more as he comes round to it
        share = U_TURN_EVEN + np.cos(np.radians([along - b for _, _, b in moves]))
        share *= len(moves) / share.sum()
    for (t0, a, b), w in zip(moves, share.tolist(), strict=True):
        s = (t - t0) / duration
        go = contact_progress((s - clear) / (1.0 - 2.0 * clear))
        yaw += (b - a) * go
        up = np.maximum(up, contact_rise(s))
        carried += w * advance * go[:, None] * _ahead(b if along is None else along)
    return yaw, up, carried


def _ahead(yaw: float) -> np.ndarray:
    """(X, Z) of the clip's forward (-Z) turned ``yaw`` degrees."""
    return (turned_about((0.0, 0.0), np.array([yaw]))[0, :3, :3] @ [0.0, 0.0, -1.0])[[0, 2]]


def _carried(pivot: tuple[float, float], yaw: np.ndarray, carried: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` ground moves: turned ``yaw`` degrees about ``pivot``, then carried ``carried`` (X, Z)."""
    m = turned_about(pivot, yaw)
    m[:, 0, 3] += carried[:, 0]
    m[:, 2, 3] += carried[:, 1]
    return m


def _site(kin: FigureKinematics, q: np.ndarray, root: np.ndarray, site: str) -> np.ndarray:
    return kin.site_globals(q, root)[kin.site_names.index(site), :3, 3]


def pivot_of(kin: FigureKinematics, key: KeyPosture) -> tuple[float, float]:
    """The ground point (X, Z cm) the soldier turns about: under the belly, halfway between the elbows'
    middle and the knees' middle, on the pelvis's line."""
    q, root = key.poses[SOLDIER], key.locations[SOLDIER]
    z = [_site(kin, q, root, f.format(s=s))[2] for s in SIDES for f in (ELBOW_SITE, LEG_SITES["knee"])]
    return float(root[0, 3]), float(np.mean(z))


def limb_track(p0: np.ndarray, moves: np.ndarray, up: np.ndarray, lift: float) -> np.ndarray:
    """World track ``(n, 3)`` of a contact at ``p0``: moved by the ground ``moves`` ``(n, 4, 4)``, raised
    ``up * lift`` cm."""
    track = (moves @ np.append(p0, 1.0))[:, :3]
    track[:, 1] += lift * up
    return track


def smooth_spine(kin: FigureKinematics, poses: np.ndarray, sigma: float) -> np.ndarray:
    """``poses`` with their spine's DOFs smoothed along the frames (a Gaussian of ``sigma`` frames): the body
    solve leaves a spine pushed to its limits jittering 1-6 degrees a frame, its vertebrae taking turns at
    a limit (the chest popped 2.2-2.6 m/s on the U-turns to his left)."""
    cols = np.concatenate([np.arange(kin.ndof)[kin.dof_slices[j]] for j in SPINE])
    out = poses.copy()
    out[:, cols] = gaussian(poses[:, cols], sigma)
    return out


def record_crawl_turn(
    kin: FigureKinematics, rkin: FigureKinematics, key: KeyPosture, plan: Plan
) -> tuple[ClipFrames, tuple[float, float, float]]:
    """The frames of one turn (see the module docstring) by ``plan``: each move carrying its part
    ``plan.advance`` cm forward (its moves of ``plan.step`` degrees at most, at ``plan.tempo`` times MOVE;
    the chest and the pelvis carried ``plan.ahead`` of the front's carry and the rest of the knees', the
    pelvis ``plan.pelvis_ahead`` a pair of moves where given; the arms tracked ``plan.arms``), and its
    ``end_offset``."""
    direction, angle, advance, step, tempo, ahead, pelvis_ahead, _, arms, spine_sigma, clear = plan
    moves, t_land = part_moves(direction, angle, step, tempo)
    t_end = round((t_land + SETTLE) * FPS) / FPS
    n = round(t_end * FPS) + 1
    t = np.arange(n) / FPS
    q0, root0, rifle0 = key.poses[SOLDIER], key.locations[SOLDIER], key.locations[RIFLE]
    pivot = pivot_of(kin, key)
    yaw = (1.0 if direction == "left" else -1.0) * angle
    along = yaw if angle > max(TURN_ANGLES) else None  # a U-turn: every move along the end heading
    (front, f_up, f_on), (back, b_up, b_on) = (
        part_yaw(t, moves[p], MOVE[p] * tempo, advance, along, clear if p == "front" else 0.0)
        for p in ("front", "back")
    )

    def mix(share: float, carry: float | np.ndarray) -> np.ndarray:
        # the body between the parts: ``share`` of the front's turn, ``carry`` of its carry
        on = carry * f_on + (1.0 - carry) * b_on
        return _carried(pivot, share * front + (1.0 - share) * back, on)

    pelvis_carry: float | np.ndarray = ahead
    if pelvis_ahead is not None:  # each pair's from its front move on (the parts level before it)
        starts = np.array([t0 for t0, _, _ in moves["front"]])
        pair = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        pelvis_carry = np.asarray(pelvis_ahead)[pair][:, None]
    roots = mix(PELVIS_FRONT, pelvis_carry) @ root0
    chest0 = kin.segment_globals(q0, root0)[kin.segment_names.index(CARRIER)]
    chest = mix(CHEST_FRONT, ahead) @ chest0
    chest[:, 1, 3] += ELBOW_LIFT * f_up  # the shoulders rise with the forearms
    front_moves, back_moves = _carried(pivot, front, f_on), _carried(pivot, back, b_on)

    def legs(side: str, part: str) -> np.ndarray:
        p0 = _site(kin, q0, root0, LEG_SITES[part].format(s=side))
        return limb_track(p0, back_moves, b_up, LIFT[part])

    poses, roots = solve_body(kin, q0, chest, roots, legs)
    if spine_sigma:  # the spine alone: the legs' contacts hang from the pelvis, the arms are solved after
        poses = smooth_spine(kin, poses, spine_sigma)
    # the arms on that body: the palms on the rifle the front carries round, then the elbows on their tracks
    rifles = front_moves @ rifle0
    rifles[:, 1, 3] += ELBOW_LIFT * f_up
    arm_goals = rifle_hand_goals(kin, rkin, key, rifles)
    for side in SIDES:
        site = ELBOW_SITE.format(s=side)
        track = limb_track(_site(kin, q0, root0, site), front_moves, f_up, ELBOW_LIFT)
        arm_goals.append(ik.Goal(site, track, None, 1.0, 1, (f"{side}_clavicle", *arm(side)[:2])))
    poses = track_solve(
        kin,
        poses,
        arm_goals,
        roots,
        iterations=10,
        max_dof_step=0.02,
        forward_only=arms == "forward",
        backward_only=arms == "backward",
    )
    if advance:  # all limbs down, the body still: the arms settle into CRAWL's own solution (carried
        # forward, the left clavicle came to rest 1 cm off it and leapt there in the last frames, 0.33 m/s;
        # turned on the spot they end on it)
        settle = smoothstep((t - t_land) / SETTLE)[:, None]
        poses = (1.0 - settle) * poses + settle * q0
    end = _carried(pivot, np.array([yaw]), b_on[-1:])[0]
    end_offset = (float(end[0, 3]), float(end[2, 3]), yaw)
    poses[0], roots[0], rifles[0] = q0, root0, rifle0
    poses[-1], roots[-1], rifles[-1] = q0, end @ root0, end @ rifle0
    lift_off_ground(kin, poses, roots, rifles)
    return easing.ease_ends(kin, rkin, ClipFrames(poses, roots, rifles, FPS)), end_offset


def _record(name: str, ctx: Any) -> tuple[ClipFrames, tuple[float, float, float]]:
    """One clip of the build context ``ctx`` (each clip is recorded once a build: nothing to share)."""
    kin, rkin = FigureKinematics(ctx.soldier), FigureKinematics(ctx.rifle)
    return record_crawl_turn(kin, rkin, ctx.keys[BASE], _PLANS[name])


def crawl_turn_clips() -> dict[str, Callable[[Any], tuple[ClipFrames, tuple[float, float, float]]]]:
    """Clip name -> generator taking the build context: (frames, end_offset)."""
    return {name: functools.partial(_record, name) for name in CRAWL_TURN_CLIPS}
