"""``crawl2prstow``: from the crawl (forearms, knees) down onto the belly, then turned over on it to prone.

The two postures' contacts are far apart: prone lies turned about 55 degrees round the pelvis (its chest 36
cm right of and 26 cm behind the crawl's, the left toes a metre sideways), so interpolating the joints drags
every limb along the ground, and turning while still up on the forearms and knees left him in the air for
half a second (issue 14). So the clip goes in the order a man does it, always something of him on the ground:

1. the forearms stay planted where the crawl has them while the legs go back, each knee and its toes lifted
   and set down in turn (the left leg, then the right) where prone has them *before* its turn, and the pelvis
   comes down onto the belly and thighs (the body takes prone's shape, still facing the crawl's way);
2. with the belly down, the forearms and the rifle between them rise, the legs clear the ground, and the body
   turns over on the belly about the vertical through the pelvis (the belly stays where it lies) to prone's
   heading; the rifle goes over from the forearms to the chest's carry;
3. the legs and then the forearms are set down at prone's places.

The body (pelvis, spine, legs) is one batched IK solve from the interpolated joints with the knees and toes on
their tracks and the pelvis held firmly to its path, then the legs tracked back from prone frame after frame;
the arms are tracked frame after frame from the crawl (palms on the rifle, elbows on their tracks) so no joint
jumps between IK branches. The clip starts exactly in ``CRAWL``, ends exactly in ``PRONE_STOWED`` and is eased
at both ends; played backwards (prone to crawl) the same order holds the other way round.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TypedDict

import numpy as np

from authoring import easing, ik
from authoring.crawl import contact_progress, contact_rise
from authoring.motion import KeyPosture
from authoring.postures import RIFLE, SOLDIER, arm, leg, palm_targets
from authoring.signal_shaping import gaussian, smoothstep
from authoring.transitions import (
    ClipFrames,
    carrier_globals,
    carry_of,
    lift_off_ground,
    palm_offsets,
    slerp_frames,
    track_solve,
)
from peabody.fk import FigureKinematics
from peabody.model import Figure

FPS = 60
NAME = "crawl2prstow"
START, END = "CRAWL", "PRONE_STOWED"
DURATION = 1.6  # s
BODY = (0.1, 0.65)  # s: pelvis, spine, legs and head take prone's shape (still facing the crawl's way)
SETTLE = (0.25, 0.55)  # s: the pelvis comes down onto the belly (once the left leg is back)
TURN = (0.65, 1.45)  # s: the body turns over on the belly to prone's heading
BELLY_DOWN_S = 0.12  # s: after the turn a DI/M16 slave's belly, held clear while turning, comes down
ARMS = (0.6, 1.45)  # s: the arms' joints (the IK pulls towards them) and the rifle's carry
HOLD = (0.6, 1.2)  # s: the rifle, first left where the forearms hold it, goes over to the chest's carry
# (start, duration) in s of each knee's move (with its toes) back to where prone has it before the turn
MOVES = {
    ("knee", "left"): (0.0, 0.3),
    ("knee", "right"): (0.15, 0.3),
}
LIFT = {"knee": 10.0, "toes": 8.0, "elbow": 6.0}  # cm a contact rises while it moves
SHORT = {"knee": 0.1, "toes": 0.3}  # share of the way back a knee or toes stop short before the turn
LEGS_CLEAR = {"knee": 3.0, "toes": 1.5}  # cm the legs are held up while the body turns over on the belly
LEGS_DOWN = (1.35, 1.5)  # s
# s: a DI/M16 slave's feet, held higher than his by its belly's lift, brought down to his (slave_feet_down):
# eased in as the pelvis comes down, out as the legs are set down (the clip's ends as slaved)
SLAVE_FEET_DOWN = ((0.3, 0.5), (1.4, 1.58))
# how hard the pelvis keeps to its path against the legs' tracks (softer, it rolls over a moving leg)
ROOT_WEIGHT = 1.5
ROOT_DOFS: tuple[str, ...] = ()
LEG_SITES = {"knee": "{s}_lower_leg.knee", "toes": "{s}_toes.distal"}
ELBOW_SITE = "{s}_upper_arm.distal"
ELBOW_PRIORITY = 4
ELBOW_FIRST = (0.5, 0.7)  # s
SWITCH_SMOOTH = (2.0, 0.06)  # (frames, s): the Gaussian over the frames, and how far either side of it
# the forearms stay planted until the belly is down, rise as the body turns over on it (the shoulders swing
# 40-70 cm: a planted elbow is dragged) and land once it is still; the rifle rises and comes down with them
ELBOW_UP = (0.52, 0.62)  # s
ELBOW_ALONG = (0.65, 1.45)  # s
ELBOW_DOWN = (1.38, 1.55)  # s
# cm in the chest's (upper torso's) frame, -z out in front of the chest: the rifle is held this far off the
# chin and the left upper arm while it turns over from the cradle to the prone carry
RIFLE_AWAY = (0.0, 0.0, -6.0)
RIFLE_AWAY_IN, RIFLE_AWAY_OUT = (0.65, 0.9), (1.1, 1.3)  # s


class _Tracking(TypedDict):
    iterations: int
    max_dof_step: float


LEG_TRACKING: _Tracking = {"iterations": 30, "max_dof_step": 0.01}  # at most ~17 degrees a frame
ARM_TRACKING: _Tracking = {"iterations": 10, "max_dof_step": 0.02}


def _ramp(t: np.ndarray, a: float, b: float) -> np.ndarray:
    return smoothstep((t - a) / (b - a))


def _up(t: np.ndarray, up: tuple[float, float], down: tuple[float, float]) -> np.ndarray:
    return np.minimum(_ramp(t, *up), 1.0 - _ramp(t, *down))


def move_track(
    p0: np.ndarray, p1: np.ndarray, t: np.ndarray, start: float, duration: float, lift: float
) -> np.ndarray:
    """World track ``(n, 3)`` of a contact planted at ``p0`` that rises ``lift`` cm, travels to ``p1`` while
    clear of the ground and is set down there over ``[start, start + duration]``."""
    s = (t - start) / duration
    track = p0[None] + contact_progress(s)[:, None] * (p1 - p0)[None]
    track[:, 1] += lift * contact_rise(s)
    return track


def arms_up(t: np.ndarray) -> np.ndarray:
    """How far (share of ``LIFT["elbow"]``) the forearms and the rifle between them are raised at ``t``."""
    return _up(t, ELBOW_UP, ELBOW_DOWN)


def turn_about(pivot: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Frames ``(n, 4, 4)``: turns of ``angle`` (rad, about +Y) about the vertical through ``pivot``."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.tile(np.eye(4), (len(angle), 1, 1))
    out[:, 0, 0], out[:, 0, 2], out[:, 2, 0], out[:, 2, 2] = c, s, -s, c
    out[:, :3, 3] = pivot[None] - np.einsum("fij,j->fi", out[:, :3, :3], pivot)
    return out


def heading(key: KeyPosture) -> float:
    """Heading (rad about +Y) of the pelvis: its left-to-right axis on the ground (both postures hold the
    legs alike about it, so turned back by the difference, prone's knees and toes lie either side of the
    crawl's)."""
    x = key.locations[SOLDIER][:3, 0]
    return float(np.arctan2(-x[2], x[0]))


def _site(kin: FigureKinematics, key: KeyPosture, site: str) -> np.ndarray:
    g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])
    return g[kin.site_names.index(site), :3, 3]


def _apply(frames: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.einsum("fij,fj->fi", frames[:, :3, :3], points) + frames[:, :3, 3]


def rifle_track(
    kin: FigureKinematics, first: KeyPosture, last: KeyPosture, chest: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """The rifle's world frames ``(n, 4, 4)``: first left where the forearms hold it, then carried by the
    chest (``chest``: the carrier's frames), its carry turning from the cradle to the prone one; raised with
    the forearms and held off the chin and the left upper arm (:data:`RIFLE_AWAY`) while it turns."""
    carried = chest @ slerp_frames(carry_of(kin, first), carry_of(kin, last), _ramp(t, *ARMS))
    hold = _ramp(t, *HOLD)
    rifles = np.stack(
        [slerp_frames(first.locations[RIFLE], c, hold[i : i + 1])[0] for i, c in enumerate(carried)]
    )
    rifles[:, 1, 3] += LIFT["elbow"] * arms_up(t)
    away = np.minimum(_ramp(t, *RIFLE_AWAY_IN), 1.0 - _ramp(t, *RIFLE_AWAY_OUT))
    rifles[:, :3, 3] += away[:, None] * np.einsum("fij,j->fi", chest[:, :3, :3], np.asarray(RIFLE_AWAY))
    return rifles


def record_crawl_to_prone(keys: Mapping[str, KeyPosture], figures: Sequence[Figure]) -> ClipFrames:
    """The frames of ``crawl2prstow`` (see the module docstring)."""
    soldier, rifle = figures
    kin, rkin = FigureKinematics(soldier), FigureKinematics(rifle)
    first, last = keys[START], keys[END]
    n = round(DURATION * FPS) + 1
    t = np.arange(n) / FPS
    q0, q1 = first.poses[SOLDIER], last.poses[SOLDIER]
    u_body, u_arms = _ramp(t, *BODY), _ramp(t, *ARMS)
    arm_dofs = np.zeros(kin.ndof, dtype=bool)
    for side in ("left", "right"):
        for j in (f"{side}_clavicle", *arm(side)):
            arm_dofs[kin.dof_slices[j]] = True
    u = np.where(arm_dofs[None], u_arms[:, None], u_body[:, None])
    rest = q0[None] + u * (q1 - q0)[None]
    # prone turned back to the crawl's heading about the belly's pivot: where he lies before turning over
    pivot = last.locations[SOLDIER][:3, 3] * np.array([1.0, 0.0, 1.0])  # the vertical through the pelvis
    total = heading(last) - heading(first)
    total = (total + np.pi) % (2 * np.pi) - np.pi
    turn = turn_about(pivot, total * _ramp(t, *TURN))
    back = turn_about(pivot, np.array([-total]))[0]
    lying = back @ last.locations[SOLDIER]
    # the pelvis comes down and levels out together (levelled still up, it lifts the shoulders off the elbows)
    roots = slerp_frames(first.locations[SOLDIER], lying, _ramp(t, *SETTLE))
    roots = turn @ roots
    # the body: knees and toes on their tracks, the pelvis held to its path
    goals: list[ik.Goal] = [ik.Goal(kin.root_name, roots[:, :3, 3], roots[:, :3, :3], ROOT_WEIGHT, 1, ())]
    for side in ("left", "right"):
        a, d = MOVES["knee", side]
        for part, fmt in LEG_SITES.items():
            site = fmt.format(s=side)
            p0, p1 = _site(kin, first, site), back[:3, :3] @ _site(kin, last, site) + back[:3, 3]
            # set down short of prone's place (out of reach of a pelvis still up), and carried on as he turns
            pa = p0 + (1.0 - SHORT[part]) * (p1 - p0)
            base = move_track(p0, pa, t, a, d, 0.0) + _ramp(t, *TURN)[:, None] * (p1 - pa)[None]
            track = _apply(turn, base)
            held = np.minimum(_ramp(t, a + 0.3 * d, a + 0.6 * d), 1.0 - _ramp(t, *LEGS_DOWN))
            rise = LIFT[part] * contact_rise((t - a) / d)
            track[:, 1] += np.maximum(rise, LEGS_CLEAR[part] * held)
            chain = leg(side) if part == "knee" else (f"{side}_hip", f"{side}_knee", f"{side}_toes")
            goals.append(ik.Goal(site, track, None, 1.0, 1, chain))
    poses, report = ik.solve(
        kin,
        rest,
        goals,
        roots,
        iterations=80,
        rest_pose=rest,
        rest_gain=0.1,
        root_dofs=ROOT_DOFS,
    )
    if report.root_location is not None:
        roots = report.root_location
    # ... and the legs again on that pelvis, frame after frame, so no joint leaps between IK branches
    poses = track_solve(kin, rest, goals[1:], roots, **LEG_TRACKING, backward_only=True)
    poses = np.where(arm_dofs[None], rest, poses)
    # the elbows: planted until the belly is down, then up and carried over with the turning body
    elbows = {}
    for side in ("left", "right"):
        site = ELBOW_SITE.format(s=side)
        p0 = _site(kin, first, site)
        p1 = back[:3, :3] @ _site(kin, last, site) + back[:3, 3]
        track = _apply(turn, p0[None] + _ramp(t, *ELBOW_ALONG)[:, None] * (p1 - p0)[None])
        track[:, 1] += LIFT["elbow"] * arms_up(t)
        elbows[side] = track
    rifles = rifle_track(kin, first, last, carrier_globals(kin, poses, roots), t)
    off_a, off_b = palm_offsets(kin, rkin, first), palm_offsets(kin, rkin, last)
    arm_goals: list[ik.Goal] = []
    for side in ("right", "left"):
        tgt = palm_targets(rkin, rifles, side) @ slerp_frames(off_a[side], off_b[side], u_arms)
        site = f"{side}_palm.palmcenter"
        arm_goals.append(ik.Goal(site, tgt[:, :3, 3], None, 1.0, 3, arm(side)))
        arm_goals.append(ik.Goal(site, None, tgt[:, :3, :3], 1.0, 2, arm(side), orientation_weight=8.0))
    # the planted forearms come first (the palms keep to the rifle as they can), the hands once they are up
    planted = 1.0 - _ramp(t, *ELBOW_FIRST)
    for side in ("left", "right"):
        site = ELBOW_SITE.format(s=side)
        chain = (f"{side}_clavicle", *arm(side)[:2])
        arm_goals.append(ik.Goal(site, elbows[side], None, planted, ELBOW_PRIORITY, chain))
        arm_goals.append(ik.Goal(site, elbows[side], None, 1.0 - planted, 1, chain))
    # tracked forwards from the crawl only (tracked back from prone, the arms reach the crawl's first frames
    # turned another way and a blend of the two leaves the palms off the rifle)
    poses = track_solve(kin, poses, arm_goals, roots, **ARM_TRACKING, forward_only=True)
    # where the elbows give way to the palms the arms change solution within a frame or two: smoothed there
    # over the frames, and the palms put back on the rifle
    near = np.exp(-0.5 * ((t - ELBOW_FIRST[1]) / SWITCH_SMOOTH[1]) ** 2)[:, None] * arm_dofs[None]
    smooth = poses + near * (gaussian(poses, SWITCH_SMOOTH[0]) - poses)
    rows = np.flatnonzero(near.max(axis=1) > 0.01)
    fixed, _ = ik.solve(
        kin,
        smooth[rows],
        [g.rows(rows) for g in arm_goals[:4]],
        roots[rows],
        iterations=4,
        rest_pose=smooth[rows],
        rest_gain=0.1,
        max_dof_step=0.02,
    )
    smooth[rows] += near[rows] * (fixed - smooth[rows])
    poses = smooth
    poses[0], poses[-1] = q0, q1
    roots[0], roots[-1] = first.locations[SOLDIER], last.locations[SOLDIER]
    rifles[0], rifles[-1] = first.locations[RIFLE], last.locations[RIFLE]
    lift_off_ground(kin, poses, roots, rifles)
    return easing.ease_ends(kin, rkin, ClipFrames(poses, roots, rifles, FPS))
