"""``crawl2prstow``: from the crawl (forearms, knees) down to prone (belly, thighs, forearms), limb by limb.

The two postures' contacts are far apart (the left elbow 60 cm, the knees 40 cm, the left toes a metre
sideways: prone lies turned about 60 degrees round the pelvis, its chest 36 cm right of and 26 cm behind the
crawl's), so interpolating the joints drags every limb along the ground. Instead, as in the crawl
(:mod:`authoring.crawl`), each limb is lifted, carried and set down in turn while the others stay planted: the
hips and legs go down first (each knee and its toes lifted back to where prone has them, the left leg then the
right; the toes held a little higher while the pelvis settles onto them). The forearms cannot stay planted
meanwhile (the shoulders swing 40-70 cm with the turning chest and would drag them), so both rise while the
chest still holds, travel in the air with the body and land at their prone places once it is still; the rifle
between them, carried by the chest from the crawl's cradle to the prone carry, rises and lands with them and
is held off the chin and the left upper arm. The body (pelvis, spine, legs) is one batched IK solve from the
interpolated joints with the knees and toes on their tracks and the pelvis held firmly to its turn from the
crawl to prone, kept at the crawl's height until the legs are back (a pelvis left free rolls over the moving
leg and back, and the rifle on the chest with it; one lowered early drags the thigh); the arms are then
tracked frame after frame from the crawl (palms on the rifle first, then the elbows on their tracks) so no
joint jumps between IK branches. The clip starts exactly in ``CRAWL``, ends exactly in ``PRONE_STOWED`` and is
eased at both ends.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TypedDict

import numpy as np

from authoring import easing, ik
from authoring.crawl import contact_progress, contact_rise
from authoring.motion import KeyPosture
from authoring.postures import RIFLE, SOLDIER, arm, leg, palm_targets
from authoring.signal_shaping import smoothstep
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
BODY = (0.1, 1.0)  # s: pelvis, spine, legs and head turn over to prone
SETTLE = (0.5, 1.0)  # s: the pelvis comes down from the crawl's height (after the left leg is back)
ARMS = (0.0, 1.1)  # s: the arms' joints (the IK pulls towards them) and the rifle's carry
HOLD = (0.0, 0.7)  # s: the rifle, first left where the forearms hold it, goes over to the chest's carry
# (start, duration) in s of each knee's move (with its toes): the left leg, then the right
MOVES = {
    ("knee", "left"): (0.0, 0.55),
    ("knee", "right"): (0.3, 0.6),
}
LIFT = {"knee": 12.0, "toes": 8.0, "elbow": 6.0}  # cm a contact rises while it moves (the thigh clears too)
# how hard the pelvis keeps to its path (the turn from crawl to prone) against the legs' tracks: softer, and
# it rolls 38 degrees over the moving leg and back, flicking the carried rifle 34 degrees in 0.1 s
ROOT_WEIGHT = 1.5
LEG_SITES = {"knee": "{s}_lower_leg.knee", "toes": "{s}_toes.distal"}
ELBOW_SITE = "{s}_upper_arm.distal"
# the forearms: both elbows rise while the chest still holds (it sets off at BODY[0]), travel in the air while
# the body turns over (the shoulders swing 40-70 cm: a planted elbow is dragged) and land once it is still;
# the rifle between the forearms rises and comes down with them (lifted less, the arms' track loses the rifle)
ELBOW_UP = (0.0, 0.15)  # s
ELBOW_ALONG = (0.1, 1.1)  # s
ELBOW_DOWN = (1.3, 1.55)  # s
# cm the toes are held higher while the pelvis settles onto them (the left toes skimmed the ground, 1.8 cm
# on soldier.fig, 2.1 cm on DI.fig whose foot reaches lower), eased down onto prone's toes once it is down
TOES_CLEAR = 1.5
TOES_CLEAR_IN, TOES_CLEAR_OUT = (0.5, 0.8), (1.0, 1.3)  # s
# cm in the chest's (upper torso's) frame, -z out in front of the chest: the rifle is held this far off the
# chin and the left upper arm while it turns over from the cradle to the prone carry (2.9 cm into them if not)
RIFLE_AWAY = (0.0, 0.0, -6.0)
RIFLE_AWAY_IN, RIFLE_AWAY_OUT = (0.2, 0.5), (0.8, 1.1)  # s


class _Tracking(TypedDict):
    iterations: int
    max_dof_step: float


LEG_TRACKING: _Tracking = {"iterations": 30, "max_dof_step": 0.01}  # at most ~17 degrees a frame
ARM_TRACKING: _Tracking = {"iterations": 10, "max_dof_step": 0.02}


def _ramp(t: np.ndarray, a: float, b: float) -> np.ndarray:
    return smoothstep((t - a) / (b - a))


def move_track(
    p0: np.ndarray, p1: np.ndarray, t: np.ndarray, start: float, duration: float, lift: float
) -> np.ndarray:
    """World track ``(n, 3)`` of a contact planted at ``p0`` that rises ``lift`` cm, travels to ``p1`` while
    clear of the ground and is set down there over ``[start, start + duration]``."""
    s = (t - start) / duration
    track = p0[None] + contact_progress(s)[:, None] * (p1 - p0)[None]
    track[:, 1] += lift * contact_rise(s)
    return track


def _site(kin: FigureKinematics, key: KeyPosture, site: str) -> np.ndarray:
    g = kin.site_globals(key.poses[SOLDIER], key.locations[SOLDIER])
    return g[kin.site_names.index(site), :3, 3]


def arms_up(t: np.ndarray) -> np.ndarray:
    """How far (share of ``LIFT["elbow"]``) the forearms and the rifle between them are raised at ``t``."""
    return np.minimum(_ramp(t, *ELBOW_UP), 1.0 - _ramp(t, *ELBOW_DOWN))


def elbow_track(
    kin: FigureKinematics, first: KeyPosture, last: KeyPosture, t: np.ndarray, side: str
) -> np.ndarray:
    """World track ``(n, 3)`` of one elbow from where the crawl has it to where prone has it: it rises while
    the chest still holds, travels while the body turns over and lands once the chest is still (the
    shoulders swing 40-70 cm as the body turns over, so an elbow cannot stay planted)."""
    site = ELBOW_SITE.format(s=side)
    p0, p1 = _site(kin, first, site), _site(kin, last, site)
    track = p0[None] + _ramp(t, *ELBOW_ALONG)[:, None] * (p1 - p0)[None]
    track[:, 1] += LIFT["elbow"] * arms_up(t)
    return track


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
    roots = slerp_frames(first.locations[SOLDIER], last.locations[SOLDIER], u_body)
    y0, y1 = first.locations[SOLDIER][1, 3], last.locations[SOLDIER][1, 3]
    roots[:, 1, 3] = y0 + _ramp(t, *SETTLE) * (y1 - y0)  # the legs move under a pelvis still up
    # the body: knees and toes on their tracks, the pelvis free to rise and turn over them
    goals: list[ik.Goal] = [ik.Goal(kin.root_name, roots[:, :3, 3], roots[:, :3, :3], ROOT_WEIGHT, 1, ())]
    for side in ("left", "right"):
        a, d = MOVES["knee", side]
        for part, fmt in LEG_SITES.items():
            site = fmt.format(s=side)
            track = move_track(_site(kin, first, site), _site(kin, last, site), t, a, d, LIFT[part])
            if part == "toes":
                clear = np.minimum(_ramp(t, *TOES_CLEAR_IN), 1.0 - _ramp(t, *TOES_CLEAR_OUT))
                track[:, 1] += TOES_CLEAR * clear
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
        root_dofs=("ty", "rx", "ry", "rz"),
    )
    assert report.root_location is not None  # solved with root DOFs: the solve reports where the root went
    roots = report.root_location
    # ... and the legs again on that pelvis, frame after frame, so no joint leaps between IK branches (tracked
    # back from prone alone: the forward track puts the left toes on another branch, 25 degrees a frame)
    poses = track_solve(kin, rest, goals[1:], roots, **LEG_TRACKING, backward_only=True)
    poses = np.where(arm_dofs[None], rest, poses)
    elbows = {side: elbow_track(kin, first, last, t, side) for side in ("left", "right")}
    rifles = rifle_track(kin, first, last, carrier_globals(kin, poses, roots), t)
    off_a, off_b = palm_offsets(kin, rkin, first), palm_offsets(kin, rkin, last)
    arm_goals: list[ik.Goal] = []
    for side in ("right", "left"):
        tgt = palm_targets(rkin, rifles, side) @ slerp_frames(off_a[side], off_b[side], u_arms)
        site = f"{side}_palm.palmcenter"
        arm_goals.append(ik.Goal(site, tgt[:, :3, 3], None, 1.0, 3, arm(side)))
        arm_goals.append(ik.Goal(site, None, tgt[:, :3, :3], 1.0, 2, arm(side), orientation_weight=8.0))
    for side in ("left", "right"):
        site = ELBOW_SITE.format(s=side)
        arm_goals.append(ik.Goal(site, elbows[side], None, 1.0, 1, (f"{side}_clavicle", *arm(side)[:2])))
    # tracked forwards from the crawl only: tracked back from prone, the arms reach the crawl's first
    # frames turned another way (the left shoulder about 100 degrees apart, the elbows 9-12 cm off their
    # tracks), and a blend of the two leaves the palms off the rifle; the forward one holds it throughout
    poses = track_solve(kin, poses, arm_goals, roots, **ARM_TRACKING, forward_only=True)
    poses[0], poses[-1] = q0, q1
    roots[0], roots[-1] = first.locations[SOLDIER], last.locations[SOLDIER]
    rifles[0], rifles[-1] = first.locations[RIFLE], last.locations[RIFLE]
    lift_off_ground(kin, poses, roots, rifles)
    return easing.ease_ends(kin, rkin, ClipFrames(poses, roots, rifles, FPS))
