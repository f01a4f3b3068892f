"""Quality checks of the motion library: does it look like soldiers moving? (``ttes author check``).

Everything is measured on every frame, vectorised, in the *world* frame: locomotion clips are recorded in
place, so the entity's ground motion at the recorded ``ground_speed`` is added back (along -Z, the facing
direction; +Z for backward clips; the crawl too); clips with an ``end_offset`` really move and need nothing.

Per clip (a channelset bound to its soldier figure and rifle):

* contacts, by **height alone** (a fast skim just above the ground is sliding, not swinging): every mesh node
  (psurf node) below ``CONTACT_HEIGHT_CM`` is on the ground, and its slide is the horizontal extent of its
  positions over one such run of frames (:mod:`authoring.body_parts`); a part other than a foot stays on
  the ground while it is within ``LIFT_OFF_CM`` of it either side of such a run (dragged as it lifts off, it
  slides; one that never comes down is in the air, but one within ``LIFT_OFF_CM`` at a static end rests
  there, as the posture check's ``rest_contact_cm`` holds it). ``foot_skate_cm`` is the worst
  over the feet (heels, balls, toes), ``contact_slide_cm`` over every other part (knees, hands, forearms,
  upper arms, chest, belly, pelvis, head), ``contact_slide_part`` names it, ``contact_slides`` has each part.
  A foot node near its foot's pivot (the forefoot round the ball) is judged by its slide about that pivot:
  a foot turning on its ball does not skate, a heel left on the ground while it turns does
  (:mod:`~authoring.quality_turns`).
* turns in place (:mod:`~authoring.quality_turns`): ``turn_travel_cm``, how far a ``turn_*`` clip's
  ``end_offset`` carries the figure from where it stood (the server keeps it as root offset), and
  ``pivot_deg`` (every clip, information), the most a foot turns while it touches the ground.
* ``ground_penetration_cm`` (body mesh below y = 0), ``rifle_penetration_cm`` (rifle mesh below y = 0) and
  ``rifle_in_body_cm``: how deep rifle mesh nodes go into the body, measured against the convex hull (Qhull)
  of each body segment's mesh in the segment's frame — the hands and fingers that hold it excepted — with
  bounding spheres to pick the candidate (frame, segment, node) triples first.
* ``rifle_slide_cm`` (information, no limit): the rifle's slide on the ground, e.g. once a death drops it.
* ``rifle_pitch_jump_deg`` — the largest change of the rifle's pitch (the butt-to-muzzle line's angle
  above the horizontal) over any ``PITCH_WINDOW_S`` (0.1 s) while it is held: raising it to aim turns it
  8-10 degrees per 0.1 s, a recoil 6, a rifle swung muzzle-up across the shoulder 22-34 (a pose may be
  frame-to-frame smooth and still whip the rifle round); a clip whose rifle lacks ``butt`` or ``muzzle``
  sites is not judged.
* ``rifle_turn_deg`` — the largest angle the butt-to-muzzle line turns through over any ``PITCH_WINDOW_S``
  while it is held, whichever way: a rifle swung flat across the body keeps its pitch (kstow2crawl's swing
  from the kneeling carry round to the crawl's cradle: 24 degrees in 0.1 s read 17 as pitch); carried
  through the crawl cycle it turns 16, through a crawl turn 14.
* ``palm_rifle_cm`` — right palm centre to the rifle's ``grip``, left palm centre to its ``handguard``, only
  while the rifle is held (before the channelset's ``release_frame``).
* ``end_speed_m_s`` — at each end of the clip that is a static posture (both ends of a static-graph clip, the
  base-posture ends of locomotion clips), the fastest site (body and rifle) over the first/last
  ``END_FRAMES`` frames: things ease in and out, deaths end at rest.
* ``joint_limit_violations`` (float32 slack allowed; a clip that ends in DEAD: its legs' passive range,
  :mod:`authoring.passive_range`) and ``max_frame_jump_deg`` (pops, IK flips).
* ``max_frame_flick_deg`` (any joint) and ``ankle_flick_deg`` (the ankles): the largest one-frame flick, a
  frame's turn of a joint angle that differs from *both* neighbouring frames' turns by this much (the smaller
  of the two second differences). A swing over a few frames, however fast, scores its change of speed
  (kfire2dead's ankle, 25 degrees in 3 frames: 3); a joint that jumps in one frame and stays, or jumps there
  and back, scores the jump: a held prone foot's ankle turning 11 degrees in a frame while the legs lie still
  (diskate14) stays under the 20-degree ``max_frame_jump_deg``.
* ``feet_up_cm`` — while the chest faces the ground (the upper torso's front pointing down, cosine at least
  ``FACE_DOWN_COS``), how far the higher foot's lowest node is above the pelvis' lowest node: a body falling
  or lying face down with its shins straight up (a ragdoll's knees whipping) reads as a scorpion, not a
  soldier; prone, crawling and dead bodies keep their feet down (not judged if the chest never faces down).
* ``lying_feet_up_cm`` — a clip that starts lying face down (the chest facing the ground and the pelvis within
  ``LYING_PELVIS_CM`` of it): the same height while he lies so. A man shot while prone has no fall to fling
  his legs: his lower legs lifting 13-17 cm as his chest came down (branch proneheels-s13) read as a kick
  and passed ``feet_up_cm``; every clip on main that starts lying keeps them within 4 cm.
* ``lying_feet_raised_s`` (:mod:`~authoring.quality_lying`): the longest time both feet are held up while
  the pelvis lies on the ground (crawl2prstow's "superman": both feet 8-15 cm up for 0.9 s as he turned).
* ``unsupported_s`` and, for a run clip, ``flight_s`` (:mod:`~authoring.quality_support`): the longest
  time nothing of the body is within 2 cm of the ground (a hover, a hop; a run's flight is judged apart).
* ``pop_m_s`` (:mod:`~authoring.quality_pops`): the largest one-frame pop of a body part in the world, its
  frame-to-frame speed's excess over both neighbours' (a hand jumping 15 cm in a frame at the let-go; a
  swing, however fast, speeds up over several frames).
* ``limb_through_cm`` (:mod:`~authoring.quality_limbs`): how deep a limb goes through another part of the
  body (an arm into a leg, a forearm into the trunk, a shin into the other leg).
* ``rifle_rest_overhang_cm`` (:mod:`~authoring.quality_rifle_rest`): a clip that ends in DEAD with its rifle
  let go, how far the rifle's centre lies outside what it rests on at the end (a rifle left standing on its
  magazine or muzzle, held up by nothing).
* ``rifle_throw_m`` and ``rifle_upright_s`` (:mod:`~authoring.quality_rifle_drop`): a clip whose rifle is let
  go, how far it ends from where the hands let it go (a rifle thrown, not dropped), and how long it stands
  on an end on the ground.
* ``rifle_top_down_s`` and ``rifle_rest_roll_deg`` (:mod:`~authoring.quality_rifle_roll`): a clip whose
  rifle is let go, how long it lies on the ground on its top (sights down, magazine up), and (ending in DEAD)
  its roll about the barrel at the end: a dropped rifle lies on a side or its magazine.
* a clip that ends in DEAD (:mod:`~authoring.quality_rest`): ``rest_rise_cm``, how far a limb rises once
  the body is down, ``limb_rest_lag_s``, how long after the body the last limb part comes to rest,
  ``propped_s`` (limit 1 s: the prone deaths 0.92-1.00, every other death <= 0.25), how
  long after the pelvis comes near the ground the head and chest come down (a dead man left propped on his
  elbows looks alive), and ``trunk_rise_cm`` (information, no limit yet: the proposed 2 cm fails the DI/M16
  slaves of the prone deaths, 4.2-5.3), how far the pelvis or chest rises once down (a dead man lifting his
  hips), and ``dead_limb_speed_m_s`` (limit 4.5 m/s: every death <= 4.2), the fastest a limb moves once
  the trunk is down (a dead arm swung, not dropped), and ``legs_rise_cm`` (limit 8 cm: every other death
  <= 6.0), how far a foot, shin or knee rises once the pelvis is near the ground (a dead man's kick);
  and ``dying_rise_cm`` (:mod:`~authoring.quality_rising`, limit 7 cm: every death <= 5.61), how far the
  pelvis' or chest's lowest node rises above the first frame (a dying man getting up).
* locomotion clips: ``stride_length`` (cm), ``ground_speed`` (cm/s) and the cadence they imply must be
  recorded (``locomotion_recorded``) unless the clip has an ``end_offset`` (it moves, it is not in place);
  cycle clips are judged for realism, ``gait_speed_m_s`` and ``gait_steps_per_s`` against ``GAIT_LIMITS`` (a
  walk or run cycle clip holds one step, cut at footfalls; the crawl cycle both legs' moves).

Across clips, along every posture graph, at each posture node:

* continuity: the poses where arcs arrive (forward: last frame, backward: first frame) and leave must agree —
  ``continuity_deg`` (joint angles), ``continuity_root_cm`` / ``continuity_root_deg`` (the figure channel)
  and ``continuity_rifle_cm``. A clip's last frame is taken back by its ``end_offset`` (the ground-plane
  move ``x, z, yaw about +Y``) before it is compared, so a turn arrives at its posture.
* resting postures rest (``REST_PARTS``; ``NAME@variant`` is a variant of ``NAME``): at every endpoint the
  weight-bearing parts' lowest nodes are on the ground, ``rest_contact_cm`` (prone: chest or belly and both
  forearms; kneeling: the right kneecap; crawl: both kneecaps and forearms; DEAD: the lowest point, the
  pelvis and the chest or belly) and, DEAD only, ``rest_foot_cm`` (each foot's heel and lowest node),
  ``rest_head_cm`` (the head's lowest node) and ``rest_arm_cm`` (the highest arm part's lowest node).

:func:`check_library` returns one object per clip, one per posture node and a ``summary`` with, per threshold,
the limit, the worst value, where it happened and pass/fail. Playing clips on figures lives in
:mod:`~authoring.quality_frames`, the posture-node checks in :mod:`~authoring.quality_postures`,
body parts, contact runs and segment hulls in :mod:`~authoring.body_parts`.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from authoring.body_parts import FOOT_PARTS, contact_runs, contact_slides, true_runs
from authoring.passive_range import passive_limits
from authoring.quality_frames import ClipFrames, FigureSet, QualityError, play
from authoring.quality_limbs import LIMB_THROUGH_LIMIT_CM, limbs_through
from authoring.quality_lying import RAISED_LIMIT_S, lying_feet_raised
from authoring.quality_pops import POP_LIMIT_M_S, pops
from authoring.quality_postures import POSTURE_LIMITS, check_continuity, static_nodes
from authoring.quality_reactions import REACTION_LIMITS, reaction_amplitude
from authoring.quality_rest import (
    LAG_LIMIT_S,
    LEGS_RISE_LIMIT_CM,
    PROPPED_LIMIT_S,
    RISE_LIMIT_CM,
    WHIP_M_S,
    dead_legs,
    dead_trunk,
    rest_lag,
    rest_rise,
)
from authoring.quality_rifle_drop import THROW_LIMIT_M, UPRIGHT_LIMIT_S, rifle_drop
from authoring.quality_rifle_rest import OVERHANG_LIMIT_CM, dropped_rifle_rest
from authoring.quality_rifle_roll import ROLL_LIMIT_DEG, TOP_DOWN_LIMIT_S, rifle_lie
from authoring.quality_rising import DYING_RISE_LIMIT_CM, dying_rise
from authoring.quality_support import FLIGHT_LIMIT_S, UNSUPPORTED_LIMIT_S, support
from authoring.quality_turns import (
    TRAVEL_LIMIT_CM,
    foot_pivots,
    pivot_slides,
    segment_yaw,
    turn_pivot_row,
    turn_travel,
)
from server.motion.channelset import Channelset
from server.motion.posture_change import load_posture_graph

__all__ = [
    "ClipFrames",
    "FigureSet",
    "QualityError",
    "check_clip",
    "check_continuity",
    "check_library",
    "clip_matches",
    "only_clips",
    "play",
    "summarise",
]

THRESHOLDS: dict[str, float] = {
    "foot_skate_cm": 2.0,
    "contact_slide_cm": 3.0,
    "ground_penetration_cm": 1.0,
    "rifle_penetration_cm": 1.0,
    "rifle_in_body_cm": 1.0,
    "palm_rifle_cm": 1.0,
    "rifle_pitch_jump_deg": 18.0,
    "rifle_turn_deg": 18.0,  # ... and its turn any way (a swing across the body keeps its pitch)
    "end_speed_m_s": 0.5,
    "joint_limit_violations": 0.0,
    "max_frame_jump_deg": 20.0,
    "max_frame_flick_deg": 15.0,  # any joint: a one-frame flick (see frame_flicks)
    "ankle_flick_deg": 8.0,  # ... an ankle's (a foot twitching at 60 fps)
    "feet_up_cm": 20.0,
    "lying_feet_up_cm": 6.0,  # ... and of a clip that starts lying face down (no fall flings the legs)
    "lying_feet_raised_s": RAISED_LIMIT_S,  # lying, both feet are not held up (quality_lying)
    "rest_rise_cm": RISE_LIMIT_CM,  # a clip that ends in DEAD: nothing rises once the body is down
    "legs_rise_cm": LEGS_RISE_LIMIT_CM,  # ... nor a leg once the pelvis is down (a dead man's kick)
    "dying_rise_cm": DYING_RISE_LIMIT_CM,  # ... nor his hips or chest above the first frame (quality_rising)
    "limb_rest_lag_s": LAG_LIMIT_S,  # ... and no limb comes to rest long after the trunk
    "dead_limb_speed_m_s": WHIP_M_S,  # ... and no limb is flung once the trunk is down (a whip, not a fall)
    "propped_s": PROPPED_LIMIT_S,  # ... and the head and chest come down with the pelvis (none lies propped)
    "rifle_rest_overhang_cm": OVERHANG_LIMIT_CM,  # ... and the rifle he let go lies on something
    "rifle_throw_m": THROW_LIMIT_M,  # a rifle let go falls by him, not thrown (quality_rifle_drop)
    "rifle_upright_s": UPRIGHT_LIMIT_S,  # ... and does not stand on an end on the ground
    "rifle_top_down_s": TOP_DOWN_LIMIT_S,  # ... nor lie on its top (quality_rifle_roll)
    "rifle_rest_roll_deg": ROLL_LIMIT_DEG,  # ... and comes to rest on a side or its magazine, not its top
    "limb_through_cm": LIMB_THROUGH_LIMIT_CM,  # no limb passes through another part of the body
    "unsupported_s": UNSUPPORTED_LIMIT_S,  # something of the body is on the ground (quality_support) ...
    "flight_s": FLIGHT_LIMIT_S,  # ... but for a run's flight
    "turn_travel_cm": TRAVEL_LIMIT_CM,  # a turn in place ends where it started (quality_turns)
    "pop_m_s": POP_LIMIT_M_S,  # no body part jumps for one frame (quality_pops)
    **POSTURE_LIMITS,
}
POSTURE_KEYS = tuple(POSTURE_LIMITS)
# (low, high) per gait family of cycle clips; None: recorded only
GAIT_LIMITS: dict[str, dict[str, tuple[float, float] | None]] = {
    "walk": {"gait_speed_m_s": (1.2, 1.6), "gait_steps_per_s": (1.7, 2.1)},
    "run": {"gait_speed_m_s": (3.0, 5.0), "gait_steps_per_s": None},
    "crawl": {"gait_speed_m_s": (0.3, 0.6), "gait_steps_per_s": None},
    "bwalk": {"gait_speed_m_s": None, "gait_steps_per_s": None},
}
STEPS_PER_CYCLE_CLIP = {"crawl": 2}  # gait.py cuts one step per cycle clip; crawl.py one full cycle
FACE_DOWN_COS = 0.5  # the chest's front points down at least this much (cosine): he lies face down
LYING_PELVIS_CM = 3.0  # face down, the pelvis' lowest node this low: he lies on the ground
CONTACT_HEIGHT_CM = 1.25  # a 1 cm skim is contact; a toe leaving the ground at 2 cm is not
# cm: a part other than a foot that came down to the contact height is on the ground until it rises past this
# (either side of it): crawl2dead's M16 slave's right upper arm swept 1.4-2.5 cm a frame 1.0-2.0 cm up as it
# lifted off, a drag the contact height alone cut to two frames (a foot's toe leaves the ground stepping)
LIFT_OFF_CM = 2.0
END_FRAMES = 3  # frames over which an end's speed is measured
LIMIT_SLACK = 1e-4  # rad / cm: float32 rounding of recorded angles
PITCH_WINDOW_S = 0.1  # s over which a rifle's change of pitch is measured
PALM_PAIRS = (("right_palm.palmcenter", "grip"), ("left_palm.palmcenter", "handguard"))
LOCOMOTION_GRAPH_WORDS = ("loco", "crawl")
BACKWARD_WORDS = ("bwalk", "backward", "back_walk", "walkback")


def foot_skate(points: np.ndarray, fps: float) -> tuple[float, int]:
    """Largest horizontal slide (cm) of contact points ``(n, k, 3)`` (world) while below the contact height
    (judged by height alone), and the number of contact runs of three frames or more."""
    del fps  # contact no longer depends on speed: a fast skim at ground level is a slide
    if points.shape[0] < 2:
        return 0.0, 0
    slide, _ = contact_slides(points, CONTACT_HEIGHT_CM)
    phases = sum(1 for k in range(points.shape[1]) for a, b in true_runs(points[:, k, 1] <= CONTACT_HEIGHT_CM)
                 if b - a >= 3)  # fmt: skip
    return float(slide.max(initial=0.0)), phases


def rifle_pitch_jump(butt: np.ndarray, muzzle: np.ndarray, fps: float) -> tuple[float, int, int]:
    """Largest change (degrees) of the pitch of the line from ``butt`` to ``muzzle`` (``(n, 3)``, +Y up)
    over any window of ``PITCH_WINDOW_S``, with the window's first and last frame."""
    axis = muzzle - butt
    length = np.linalg.norm(axis, axis=1)
    sine = np.divide(axis[:, 1], length, out=np.zeros_like(length), where=length > 0)
    pitch = np.degrees(np.arcsin(np.clip(sine, -1.0, 1.0)))
    w = min(max(1, round(PITCH_WINDOW_S * fps)), len(pitch) - 1)
    if w < 1:
        return 0.0, 0, 0
    change = np.abs(pitch[w:] - pitch[:-w])
    at = int(np.argmax(change))
    return float(change[at]), at, at + w


def rifle_turn(butt: np.ndarray, muzzle: np.ndarray, fps: float) -> tuple[float, int, int]:
    """Largest angle (degrees) the line from ``butt`` to ``muzzle`` (``(n, 3)``) turns through over any
    window of ``PITCH_WINDOW_S``, with the window's first and last frame (yaw as well as pitch)."""
    w = min(max(1, round(PITCH_WINDOW_S * fps)), len(butt) - 1)
    if w < 1:
        return 0.0, 0, 0
    axis = muzzle - butt
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    unit = np.divide(axis, length, out=np.zeros_like(axis), where=length > 0)
    cosine = np.clip(np.einsum("ij,ij->i", unit[w:], unit[:-w]), -1.0, 1.0)
    turn = np.degrees(np.arccos(cosine))
    at = int(np.argmax(turn))
    return float(turn[at]), at, at + w


def feet_up(kin, segg: np.ndarray, heights: np.ndarray, parts: np.ndarray) -> dict[str, Any]:
    """``feet_up_cm`` and where: the higher foot's lowest node above the pelvis' lowest node (cm) in the
    frames where the chest faces the ground (``segg`` segment globals ``(n, nseg, 4, 4)``, ``heights`` the
    mesh nodes' ``(n, k)``, ``parts`` theirs); None when it never does (or the figure lacks the parts)."""
    if "upper_torso" not in kin.segment_names or not {"pelvis", *FOOT_PARTS} <= set(parts):
        return {"feet_up_cm": None}
    down = segg[:, kin.segment_names.index("upper_torso"), 1, 2] >= FACE_DOWN_COS  # front (-Z) down
    if not down.any():
        return {"feet_up_cm": None}
    pelvis = heights[:, parts == "pelvis"].min(axis=1)
    feet = np.stack([heights[:, parts == f].min(axis=1) for f in FOOT_PARTS], axis=1) - pelvis[:, None]
    out = _highest_foot("feet_up", feet, np.flatnonzero(down))
    lying = down & (pelvis <= LYING_PELVIS_CM)
    if lying[0]:  # he starts lying face down: no fall flings his legs up
        out.update(_highest_foot("lying_feet_up", feet, np.flatnonzero(lying)))
    return out


def _highest_foot(key: str, feet: np.ndarray, frames: np.ndarray) -> dict[str, Any]:
    """``{key}_cm`` and ``{key}_where``: the highest of ``feet`` ``(n, 2)`` over ``frames``."""
    f, side = np.unravel_index(int(np.argmax(feet[frames])), (len(frames), 2))
    at = int(frames[f])
    return {f"{key}_cm": round(float(feet[at, side]), 3), f"{key}_where": f"{FOOT_PARTS[side]}[{at}]"}


def one_frame_flicks(turn: np.ndarray) -> np.ndarray:
    """The one-frame flicks of turns ``turn`` ``(m, k)`` (``turn[t] = q[t+1] - q[t]``), of turns 1 .. m-2
    ``(m-2, k)``: the smaller of ``|turn(t) - turn(t-1)|`` and ``|turn(t) - turn(t+1)|`` (none for fewer
    than 3 turns). The check's flick limits and the stages that ease a flick (``leg_lift.eased_legs``,
    ``slave_wrists``) judge by this one measure."""
    if len(turn) <= 2:
        return np.zeros((0, turn.shape[1]))
    return np.minimum(np.abs(turn[1:-1] - turn[:-2]), np.abs(turn[1:-1] - turn[2:]))


def frame_flicks(q: np.ndarray, rot: np.ndarray, dof_slices: Mapping[str, slice]) -> dict[str, Any]:
    """The largest one-frame flick (degrees) of the rotational DOFs ``rot`` of poses ``q`` ``(n, ndof)``,
    over every joint (``max_frame_flick_deg``) and the ankles (``ankle_flick_deg``), with where: at frame
    ``t`` the smaller of ``|turn(t) - turn(t-1)|`` and ``|turn(t) - turn(t+1)|``, ``turn(t) = q[t+1] - q[t]``
    (a jump in a still joint scores the jump, a steady or smoothly changing turn little)."""
    flick = one_frame_flicks(np.degrees(np.diff(q, axis=0)))
    flick[:, ~rot] = 0.0
    ankles = np.zeros(q.shape[1], dtype=bool)
    for joint, sl in dof_slices.items():
        ankles[sl] = joint.endswith("ankle")
    out: dict[str, Any] = {}
    for key, cols in (("max_frame_flick", np.ones_like(ankles)), ("ankle_flick", ankles)):
        part = np.where(cols, flick, 0.0)
        out[f"{key}_deg"] = round(float(part.max(initial=0.0)), 3)
        out[f"{key}_where"] = None
        if part.size and part.max() > 0.0:
            at, dof = (int(v) for v in np.unravel_index(int(np.argmax(part)), part.shape))
            joint = next(j for j, sl in dof_slices.items() if sl.start <= dof < sl.stop)
            out[f"{key}_where"] = f"{joint}[{at + 1}-{at + 2}]"
    return out


def ground_shift(cs: Channelset, locomotion: bool, direction: float | None = None) -> np.ndarray:
    """``(n, 3)`` world travel to add to an in-place locomotion clip (zeros for every other clip)."""
    n = cs.nframes
    shift = np.zeros((n, 3))
    if locomotion and cs.ground_speed is not None:
        if direction is None:
            direction = 1.0 if any(w in cs.name.lower() for w in BACKWARD_WORDS) else -1.0
        shift[:, 2] = direction * cs.ground_speed * np.arange(n) / cs.fps
    return shift


def gait_family(name: str) -> str | None:
    """``walk``, ``bwalk``, ``run`` or ``crawl`` for a locomotion cycle clip's name, else None."""
    low = name.lower()
    if "cycle" not in low:
        return None
    return next((f for f in ("bwalk", "walk", "run", "crawl") if low.startswith(f)), None)


def end_speeds(pos: np.ndarray, names: Sequence[str], fps: float) -> dict[str, tuple[float, str]]:
    """Fastest site (m/s, name) of ``pos`` ``(n, k, 3)`` over the first and the last ``END_FRAMES``."""
    n = pos.shape[0]
    out: dict[str, tuple[float, str]] = {}
    if n < 2:
        return {"first": (0.0, ""), "last": (0.0, "")}
    k = min(END_FRAMES, n - 1)
    for end, part in (("first", pos[: k + 1]), ("last", pos[n - 1 - k :])):
        v = np.linalg.norm(np.diff(part, axis=0), axis=-1).max(axis=0) * fps / 100.0
        i = int(np.argmax(v))
        out[end] = (float(v[i]), names[i])
    return out


def _range_distance(value: float, limits: tuple[float, float] | None) -> float:
    """How far ``value`` lies outside ``limits`` (negative inside, ``-inf`` without limits)."""
    return -np.inf if limits is None else max(limits[0] - value, value - limits[1])


def _range_failure(value: float | None, limits: tuple[float, float] | None) -> bool:
    return value is not None and limits is not None and not (limits[0] <= value <= limits[1])


def check_clip(
    clip: ClipFrames | Channelset,
    figures: FigureSet,
    *,
    locomotion: bool = False,
    direction: float | None = None,
    file: str | None = None,
    static_ends: tuple[bool, bool] | None = None,
    ends_dead: bool = False,
) -> dict[str, Any]:
    """All per-clip metrics of one channelset (see the module docstring) and its pass/fail.

    ``static_ends``: whether the first and the last frame are static postures (speeds are checked there);
    default: both for a static clip, neither for a locomotion clip. ``ends_dead``: the clip ends in DEAD, so
    no leg or arm may rise once the body is down (:mod:`authoring.quality_rest`)."""
    frames = clip if isinstance(clip, ClipFrames) else play(clip, figures)
    cs = frames.channelset
    n = cs.nframes
    name = cs.name
    body_type = max(frames.poses, key=lambda k: figures.kin[k].ndof)
    rifle_type = next((k for k in frames.poses if k != body_type), None)
    kin = figures.kin[body_type]
    q, loc = frames.poses[body_type], frames.locations[body_type]
    out: dict[str, Any] = {
        "name": name,
        "file": file or cs.source,
        "figure": body_type,
        "rifle": rifle_type,
        "frames": n,
        "fps": cs.fps,
        "duration_s": round(cs.duration, 4),
        "locomotion": locomotion,
    }
    shift = ground_shift(cs, locomotion, direction)
    sites = kin.site_globals(q, loc)
    # every mesh node in the world: contacts and ground penetration
    nodes, segs = figures.nodes(body_type)
    parts = figures.node_parts(body_type)
    segg = kin.segment_globals(q, loc)  # (n, nseg, 4, 4)
    pts = np.einsum("fkij,kj->fki", segg[:, segs, :3, :], nodes) + shift[:, None, :]
    feet = np.isin(parts, FOOT_PARTS)
    if static_ends is None:
        static_ends = (not locomotion, not locomotion)
    # a part resting at a static end within LIFT_OFF_CM lies on the ground there (body_parts.contact_runs)
    lift = np.where(feet, CONTACT_HEIGHT_CM, LIFT_OFF_CM)
    runs = contact_runs(pts, CONTACT_HEIGHT_CM, lift, rest_ends=static_ends)
    # a pivoting foot's nodes are judged about its pivot, a node or its ball or heel (quality_turns)
    sole = {
        f: sites[:, [kin.site_names.index(f"{f}.{p}") for p in ("ball", "heel")]][..., :3, 3]
        + shift[:, None, :]
        for f in FOOT_PARTS
        if {f"{f}.ball", f"{f}.heel"} <= set(kin.site_names)
    }
    runs.slide = pivot_slides(runs, pts, parts, segment_yaw(segg)[:, segs], CONTACT_HEIGHT_CM, sole)
    slide, _ = runs.per_node(len(parts))
    shown = np.char.replace(parts.astype(str), "_kneecap", "_knee")  # a kneecap slides as the knee
    out["contact_slides"] = {
        str(p): round(float(slide[shown == p].max()), 3) for p in np.unique(shown[slide > 0])
    }
    for key, mask in (("foot_skate", feet), ("contact_slide", ~feet)):
        r = runs.worst(mask)
        val = 0.0 if r is None else float(runs.slide[r])
        out[f"{key}_cm"] = round(val, 3)
        out[f"{key}_part"] = str(shown[runs.node[r]]) if val > 0 else None
        out[f"{key}_frames"] = [int(runs.first[r]), int(runs.last[r])] if val > 0 else None
    foot_down = [(pts[:, parts == f, 1] <= CONTACT_HEIGHT_CM).any(axis=1) for f in FOOT_PARTS]
    out["stance_phases"] = sum(1 for row in foot_down for a, b in true_runs(row) if b - a >= 3)
    foot_yaw = {
        f: segment_yaw(segg[:, kin.segment_names.index(f)]) for f in FOOT_PARTS if f in kin.segment_names
    }
    out.update(foot_pivots(pts, parts, foot_yaw, CONTACT_HEIGHT_CM))
    out.update(turn_travel(cs))
    ys = pts[..., 1]
    out.update(support(name, ys, cs.fps))
    out.update(pops(pts, parts, cs.fps))
    out.update(feet_up(kin, segg, ys, parts))
    out.update(lying_feet_raised(ys, parts, cs.fps))
    # no limb passes through another part of the body (quality_limbs)
    limb_hulls = figures.limb_hulls(body_type)
    out.update(limbs_through(pts - shift[:, None, :], parts, limb_hulls, segg, list(kin.segment_names)))
    low = np.unravel_index(int(np.argmin(ys)), ys.shape)
    out["ground_penetration_cm"] = round(max(0.0, -float(ys[low])), 3)
    out["lowest_segment"] = kin.segment_names[int(segs[low[1]])]
    out["ground_penetration_where"] = f"{out['lowest_segment']}[{int(low[0])}]"
    site_pos = sites[..., :3, 3] + shift[:, None, :]
    site_names = list(kin.site_names)
    muzzle: np.ndarray | None = None
    if rifle_type is not None:
        rk = figures.kin[rifle_type]
        rq, rloc = frames.poses[rifle_type], frames.locations[rifle_type]
        rs = rk.site_globals(rq, rloc)
        rnames = {s.split(".", 1)[1]: i for i, s in enumerate(rk.site_names)}
        held = n if cs.release_frame is None else cs.release_frame
        out["release_frame"] = cs.release_frame
        worst = 0.0
        for palm, rsite in PALM_PAIRS:
            if palm in kin.site_names and rsite in rnames and held > 0:
                d = np.linalg.norm(
                    sites[:held, kin.site_names.index(palm), :3, 3] - rs[:held, rnames[rsite], :3, 3], axis=-1
                )
                out[f"{palm.split('.')[0]}_rifle_cm"] = round(float(d.max()), 3)
                if d.max() >= worst:
                    worst = float(d.max())
                    out["palm_rifle_where"] = f"{palm.split('.')[0]}[{int(np.argmax(d))}]"
        out["palm_rifle_cm"] = round(worst, 3)
        muzzle = rs[:, rnames["muzzle"], :3, 3] + shift if "muzzle" in rnames else None
        if "butt" in rnames and "muzzle" in rnames:
            butt, tip = (rs[:held, rnames[k], :3, 3] for k in ("butt", "muzzle"))
            jump, a, b = rifle_pitch_jump(butt, tip, cs.fps)
            out["rifle_pitch_jump_deg"] = round(jump, 3)
            out["rifle_pitch_jump_where"] = f"frames {a}-{b}" if jump > 0 else None
            turn, a, b = rifle_turn(butt, tip, cs.fps)
            out["rifle_turn_deg"] = round(turn, 3)
            out["rifle_turn_where"] = f"frames {a}-{b}" if turn > 0 else None
        rnodes, rsegs = figures.nodes(rifle_type)
        rg = rk.segment_globals(rq, rloc)
        rpts = np.einsum("fkij,kj->fki", rg[:, rsegs, :3, :], rnodes)
        out["rifle_penetration_cm"] = round(max(0.0, -float(rpts[..., 1].min(initial=np.inf))), 3)
        if out["rifle_penetration_cm"] > 0:
            out["rifle_penetration_where"] = f"frame {int(np.argmin(rpts[..., 1].min(axis=1)))}"
        rruns = contact_runs(rpts + shift[:, None, :], CONTACT_HEIGHT_CM)  # information: a dropped rifle
        r = rruns.worst(np.ones(len(rnodes), dtype=bool))
        out["rifle_slide_cm"] = 0.0 if r is None else round(float(rruns.slide[r]), 3)
        out["rifle_slide_frames"] = None if r is None else [int(rruns.first[r]), int(rruns.last[r])]
        # information: the rifle he let go rests on something (a clip that ends in DEAD; quality_rifle_rest)
        centre = rs[:, rnames.get("grip", 0), :3, 3] + shift  # a rifle's centre of mass: by its grip
        hulls = figures.hulls(body_type, hands=True)
        out.update(dropped_rifle_rest(cs, ends_dead, rpts + shift[:, None, :], centre, hulls, segg))
        ends = [rs[:, rnames[k], :3, 3] for k in ("butt", "muzzle") if k in rnames]
        axis = ends[1] - ends[0] if len(ends) == 2 else None  # the rifle's long axis, butt to muzzle
        out.update(rifle_drop(cs, rpts + shift[:, None, :], centre, axis, hulls, segg))
        out.update(rifle_lie(cs, ends_dead, rg[:, 0, :3, :3], rpts + shift[:, None, :]))
        depth, frame, seg = figures.hulls(body_type).depth(rpts, segg)
        out["rifle_in_body_cm"] = round(depth, 3)
        out["rifle_in_body_where"] = f"{kin.segment_names[seg]}[{frame}]" if seg >= 0 else None
        site_pos = np.concatenate([site_pos, rs[..., :3, 3] + shift[:, None, :]], axis=1)
        site_names += list(rk.site_names)
    # a reaction clip shows: the shoulders, head and muzzle move enough (quality_reactions)
    out.update(reaction_amplitude(name, site_pos, site_names, muzzle, cs.fps))
    # speeds at the ends that are static postures
    speeds = end_speeds(site_pos, site_names, cs.fps)
    checked = [(end, *speeds[end]) for end, ok in zip(("first", "last"), static_ends, strict=True) if ok]
    out["end_speeds_m_s"] = {end: round(v, 3) for end, (v, _) in speeds.items()}
    if checked:
        end, v, site = max(checked, key=lambda c: c[1])
        out["end_speed_m_s"] = round(v, 3)
        out["end_speed_where"] = f"{site} ({end} frames)"
    else:
        out["end_speed_m_s"] = None
    # joint limits and pops; a dead body's legs go to their passive range (authoring.passive_range)
    lower, upper = passive_limits(kin) if ends_dead else (kin.lower, kin.upper)
    viol = (q < lower - LIMIT_SLACK) | (q > upper + LIMIT_SLACK)
    out["joint_limit_violations"] = int(viol.sum())
    if viol.any():
        bad = np.flatnonzero(viol.any(axis=0))
        names = [j for j, sl in kin.dof_slices.items() if np.any((bad >= sl.start) & (bad < sl.stop))]
        out["violating_joints"] = names
    rot = np.array([d.kind == "R" for j in figures.figures[body_type].joints.values() for d in j.dofs])
    steps = np.abs(np.diff(q[:, rot], axis=0))
    out["max_frame_jump_deg"] = round(float(np.degrees(steps.max(initial=0.0))), 3)
    if steps.size:
        at, col = (int(v) for v in np.unravel_index(int(np.argmax(steps)), steps.shape))
        dof = int(np.flatnonzero(rot)[col])
        joint = next(j for j, sl in kin.dof_slices.items() if sl.start <= dof < sl.stop)
        out["max_frame_jump_where"] = f"{joint}[{at}-{at + 1}]"
    out.update(frame_flicks(q, rot, kin.dof_slices))
    if ends_dead:
        out.update(rest_rise(frames, figures))
        out.update(rest_lag(frames, figures))
        out.update(dead_trunk(frames, figures))
        out.update(dead_legs(frames, figures))
        out.update(dying_rise(ys, parts))
    failures = [k for k, lim in THRESHOLDS.items() if k in out and out[k] is not None and out[k] > lim]
    reacted = REACTION_LIMITS.get(out.get("reaction") or "", {})
    failures += [k for k, lim in reacted.items() if _range_failure(out[k], lim)]
    if locomotion:
        speed, stride = cs.ground_speed, cs.stride_length
        out["stride_length"] = stride
        out["ground_speed"] = speed
        out["cadence"] = round(speed / stride, 4) if speed and stride else None
        # an in-place clip must say how fast it goes; one with an end_offset (a turn, a side-step) moves
        out["locomotion_recorded"] = (speed is not None and stride is not None) or cs.end_offset is not None
        if not out["locomotion_recorded"]:
            failures.append("locomotion_recorded")
        family = gait_family(name)
        if family is not None and speed is not None and stride is not None and cs.duration > 0:
            out["gait"] = family
            out["gait_speed_m_s"] = round(float(speed) / 100.0, 4)
            out["gait_steps_per_s"] = round(STEPS_PER_CYCLE_CLIP.get(family, 1) / cs.duration, 4)
            for key, limits in GAIT_LIMITS[family].items():
                if _range_failure(out[key], limits):
                    failures.append(key)
    out["failures"] = failures
    out["pass"] = not failures
    return out


# --- the library ------------------------------------------------------------------------------------------


def _is_locomotion(graph_path: Path) -> bool:
    stem = graph_path.stem.lower()
    return any(w in stem for w in LOCOMOTION_GRAPH_WORDS)


def check_library(
    graphs: Sequence[str | Path],
    figures_dir: str | Path,
    *,
    clips: Sequence[str | Path] = (),
    figures: FigureSet | None = None,
) -> dict[str, Any]:
    """Check every clip of the posture graphs (and any extra channelset files) and every graph's posture
    nodes.

    Figures are read from ``figures_dir`` by the channelsets' protofiletypes. Returns ``{"clips": [...],
    "continuity": [...], "summary": {...}}``; ``summary["pass"]`` is False when any threshold fails.
    """
    from server.motion.cache import load_channelset

    figset = figures or FigureSet({})

    def figures_for(cs: Channelset) -> None:
        need = sorted({c.protofiletype for c in cs.channels} - set(figset.figures))
        if need:
            extra = FigureSet.from_dir(Path(figures_dir), need)
            figset.figures.update(extra.figures)
            figset.kin.update(extra.kin)

    # first every graph: which clips are locomotion, which of their ends are static postures
    info: dict[str, dict[str, Any]] = {}
    loaded_graphs = []
    for gpath in map(Path, graphs):
        loaded = load_posture_graph(gpath)
        loco = _is_locomotion(gpath)
        still = static_nodes(loaded, loco)
        tokens: dict[int, str] = {}
        for token, (cs, fname) in enumerate(zip(loaded.channelsets, loaded.graph.files, strict=True)):
            key = str((gpath.parent / fname).resolve())
            tokens[token] = key
            row = info.setdefault(
                key,
                {
                    "cs": cs,
                    "file": str(gpath.parent / fname),
                    "loco": loco,
                    "graphs": [],
                    "ends": [False] * 2,
                    "dead": False,
                },
            )
            if gpath.name not in row["graphs"]:
                row["graphs"].append(gpath.name)
        for arc in loaded.graph.arcs:
            first, last = (arc.start, arc.end) if arc.forward else (arc.end, arc.start)
            ends = info[tokens[arc.channelset]]["ends"]
            ends[0] |= first in still
            ends[1] |= last in still
            info[tokens[arc.channelset]]["dead"] |= last.split("@")[0] == "DEAD"
        loaded_graphs.append((loaded, tokens))
    played: dict[str, ClipFrames] = {}
    seen: dict[str, dict[str, Any]] = {}
    for key, row in info.items():
        figures_for(row["cs"])
        played[key] = play(row["cs"], figset)
        seen[key] = check_clip(
            played[key], figset, locomotion=row["loco"], file=row["file"], static_ends=tuple(row["ends"]),
            ends_dead=row["dead"],
        )  # fmt: skip
        seen[key]["graphs"] = row["graphs"]
    continuity: list[dict] = []
    for loaded, tokens in loaded_graphs:
        continuity.extend(check_continuity(loaded, {t: played[k] for t, k in tokens.items()}, figset))
    for path in map(Path, clips):
        key = str(path.resolve())
        if key in seen:
            continue
        cs = load_channelset(path)
        figures_for(cs)
        seen[key] = check_clip(play(cs, figset), figset, file=str(path))
        seen[key]["graphs"] = []
    clip_rows = list(seen.values())
    return {"clips": clip_rows, "continuity": continuity, "summary": summarise(clip_rows, continuity)}


def _part_frames(row: Mapping[str, Any], key: str) -> str | None:
    """``left_foot, frames 5-8`` for a slide metric of a clip row."""
    part, frames = row.get(f"{key}_part"), row.get(f"{key}_frames")
    return f"{part}, frames {frames[0]}-{frames[1]}" if part and frames else part


def where_detail(row: Mapping[str, Any], key: str) -> str | None:
    """Where in a clip (part, segment, site, frames) or at which posture endpoint a metric's value was
    measured, for the reports."""
    if key in ("foot_skate_cm", "contact_slide_cm"):
        return _part_frames(row, key.removesuffix("_cm"))
    if key.startswith("rest_"):
        return row.get(f"{key.removesuffix('_cm')}_where")
    base = key.removesuffix("_cm").removesuffix("_m_s").removesuffix("_deg").removesuffix("_s")
    return row.get(f"{base}_where")


def _where(row: Mapping[str, Any], key: str) -> str:
    name = row.get("name") or f"{row.get('graph')}:{row.get('posture')}"
    detail = where_detail(row, key)
    return f"{name} ({detail})" if detail else name


def _range_row(
    key: str,
    judged: Sequence[tuple[Mapping[str, Any], tuple[float, float] | None]],
    ranges: Mapping[str, Any],
) -> dict[str, Any]:
    """The summary row of a metric judged against a range per family (gaits, reactions): ``judged`` pairs a
    clip row with its family's range (None: recorded only)."""
    judged = [(c, lim) for c, lim in judged if lim is not None]
    bad = [(c, lim) for c, lim in judged if _range_failure(c[key], lim)]
    # the worst: furthest outside its range, else the value closest to an edge
    pick = max(judged, key=lambda cl: _range_distance(cl[0][key], cl[1])) if judged else None
    return {
        "limit": dict(ranges),
        "worst": None if pick is None else pick[0][key],
        "where": None if pick is None else pick[0]["name"],
        "failing": len(bad),
        "pass": not bad,
    }


def summarise(clips: Sequence[Mapping[str, Any]], continuity: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per threshold: limit, worst value, where, pass; plus counts and the overall verdict."""
    rows: dict[str, Any] = {}
    for key, limit in THRESHOLDS.items():
        source = continuity if key in POSTURE_KEYS else clips
        vals = [(r[key], r) for r in source if r.get(key) is not None]
        if not vals:
            rows[key] = {"limit": limit, "worst": None, "where": None, "failing": 0, "pass": True}
            continue
        worst, row = max(vals, key=lambda x: x[0])
        failing = sum(1 for v, _ in vals if v > limit)
        rows[key] = {"limit": limit, "worst": worst, "where": _where(row, key), "failing": failing,
                     "pass": failing == 0}  # fmt: skip
    for key in ("gait_speed_m_s", "gait_steps_per_s"):
        judged = [(c, GAIT_LIMITS[c["gait"]][key]) for c in clips if c.get(key) is not None]
        rows[key] = _range_row(key, judged, {f: v[key] for f, v in GAIT_LIMITS.items() if v[key] is not None})
    for key in sorted({k for v in REACTION_LIMITS.values() for k in v}):
        ranges = {kind: v[key] for kind, v in REACTION_LIMITS.items() if key in v}
        judged = [
            (c, ranges.get(c["reaction"])) for c in clips if c.get(key) is not None and c.get("reaction")
        ]
        rows[key] = _range_row(key, judged, ranges)
    rows["turn_pivot_deg"] = turn_pivot_row(clips)
    loco = [c for c in clips if c.get("locomotion")]
    missing = [c["name"] for c in loco if not c.get("locomotion_recorded")]
    rows["locomotion_recorded"] = {
        "limit": "stride_length and ground_speed on every locomotion clip",
        "worst": None if not missing else f"{len(missing)} missing",
        "where": missing[0] if missing else None,
        "failing": len(missing),
        "pass": not missing,
    }
    ok = all(r["pass"] for r in rows.values())
    return {
        "clips": len(clips),
        "clips_failing": sum(1 for c in clips if not c.get("pass", True)),
        "postures_checked": len(continuity),
        "postures_failing": sum(1 for r in continuity if not r.get("pass", True)),
        "thresholds": rows,
        "pass": ok,
    }


def clip_matches(filename: str, pattern: str | None) -> bool:
    """Whether a clip file (``stfire2dead_low.chset.env``) matches a shell pattern on clip names
    (``stfire2dead``, ``*2dead``; a DI clip's ``_low`` suffix may be left out)."""
    if not pattern:
        return True
    name = Path(filename).name.split(".", 1)[0]
    names = (name, name.removesuffix("_low"), Path(filename).name)
    return any(fnmatch.fnmatchcase(n, pattern) for n in names)


def only_clips(result: Mapping[str, Any], pattern: str) -> dict[str, Any]:
    """A :func:`check_library` result cut down to the clips matching ``pattern`` (see :func:`clip_matches`)
    and the posture nodes where one of them arrives or leaves, with its own summary."""
    clips = [c for c in result["clips"] if clip_matches(c["file"] or c["name"], pattern)]
    names = {c["name"] for c in clips}
    nodes = [r for r in result["continuity"] if names & set(r.get("clips", ()))]
    return {"clips": clips, "continuity": nodes, "summary": summarise(clips, nodes), "only": pattern}
