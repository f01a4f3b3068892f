"""A fall's knees on the ground stay where they touched down: the body pivots over them (issue 14).

As a soldier collapses onto a knee and pitches forward, the ragdoll of :mod:`authoring.deaths` drags that
knee along (ststow2dead: 10.3 cm over frames 41-76; the hip travels 63 cm while the thigh reaches 52).
The slide is not the body's drift (:func:`authoring.planted.plant` takes that out) but a change of shape:
with knee and toes both down, the shin lays itself flat and the knee-to-toe distance grows (28 -> 35 cm).
A knee's place is set by the root, not by a limb, so it cannot be held by re-solving the leg alone
(:mod:`authoring.contact_pin`: the knee went into the ground and still slid 5 cm). So:

1. **the root follows the knees**: the recorded frames are moved back horizontally by the mean ground
   motion of the knee nodes on the ground (:func:`authoring.planted.ground_drift` over the knees alone),
   accumulated from the first frame and kept after the knees lift (the body lands a little short of where
   it fell; nothing is eased back, which would slide the trunk he lands on); the rifle moves with the root
   while the hands hold it, and after they let go as long as it is still moving (:data:`RIFLE_STILL`):
   left where they let go of it, the flung rifle kept its place while the body moved back under it
   (ststow2dead: 8.2 cm, and his right toes landed 1.5 cm inside it); once it lies still, it stays;
2. **the legs keep their contacts**: moved with the root, the feet would slide back (the toes 10-14 cm), so
   each leg is re-solved frame by frame (:func:`authoring.contact_pin.pin_contacts` with :data:`LEG_PINS`):
   a grounded knee held where it is by the hip alone, so the knee, ankle and toes are free to keep the foot
   where it touched down: the shin stays raised over the tucked toes instead of laying itself flat, or the
   foot lifts off (ground contact wins over the recorded pose);
3. both again (:data:`PASSES`): the re-solved leg rolls the kneecap's nodes a little.

The first frame is unchanged (the start posture); the last is the recorded DEAD shape, moved with the root.
"""

from __future__ import annotations

import numpy as np

from authoring.contact_pin import LEG, PINS, Pin, pin_contacts
from authoring.planted import ground_drift
from authoring.quality_frames import FigureSet
from authoring.slave_feet import part_points
from authoring.transitions import ClipFrames
from peabody.model import Figure

SIDES = ("left", "right")
DRIFT_HEIGHT_CM = 0.6  # knee nodes this low carry the body: their mean motion is taken out (at the check's
# contact height, 1.25, the kneecap rolling over the ground left ststow2dead's knee at 3.3 cm; 0.6: 3.1)
PASSES = 3  # root shift and leg solve, measured and done again (ststow2dead's knee: 4.8 cm after one, 3.23
# after two, 2.96 after three)
RIFLE_STILL = 0.05  # m/s: a let-go rifle slower than this lies still and is not moved with the body
# the foot's pin as contact_pin's; the knee's held by the hip alone (contact_pin's uses hip and knee, which
# leaves the foot only the ankle and toes: it cannot follow the root back)
LEG_PINS: tuple[Pin, ...] = (
    PINS[0],
    Pin(("{side}_knee", "{side}_kneecap", "{side}_thigh"), ("{side}_lower_leg.knee",), LEG[:1], 1, True),
)


def knee_drift(frames: ClipFrames, figures: FigureSet) -> np.ndarray:
    """``(n, 3)`` the horizontal offset (cm, accumulated from none at the first frame) that cancels the
    ground motion of the knees' nodes on the ground (both knees' parts, kneecaps as knees)."""
    parts = tuple(f"{side}_{p}" for side in SIDES for p in ("knee", "kneecap"))
    points = part_points(frames.poses, frames.roots, figures, "body", parts)
    sel = np.isin(figures.node_parts("body"), parts)
    labels = np.char.replace(figures.node_parts("body")[sel].astype(str), "_kneecap", "_knee")
    touching = points[..., 1] <= DRIFT_HEIGHT_CM
    return -np.cumsum(ground_drift(points, touching, labels), axis=0)


def _shifted(frames: ClipFrames, offset: np.ndarray, release: int) -> ClipFrames:
    """``frames`` with the root moved by ``offset`` ``(n, 3)``; the rifle with it up to the frame the hands
    let go of it (``release``) and after that by the offset's change over the frames it still moves in
    (faster than :data:`RIFLE_STILL`): a rifle lying still is not dragged along."""
    roots, rifles = np.array(frames.roots), np.array(frames.rifles)
    roots[:, :3, 3] += offset
    where = rifles[:, :3, 3]
    speed = np.linalg.norm(np.diff(where, axis=0, prepend=where[:1]), axis=1) * frames.fps / 100.0
    follows = (np.arange(len(offset)) <= release) | (speed > RIFLE_STILL)
    step = np.diff(offset, axis=0, prepend=np.zeros((1, 3)))
    rifles[:, :3, 3] += np.cumsum(step * follows[:, None], axis=0)
    return ClipFrames(frames.poses, roots, rifles, frames.fps)


def hold_knees(frames: ClipFrames, soldier: Figure, release: int = 0) -> ClipFrames:
    """``frames`` (a simulated fall of ``soldier``) with the knees on the ground held where they touched
    down and the legs re-solved so the feet do not slide (see the module docstring); ``release``: the frame
    the hands let go of the rifle."""
    figs = FigureSet({"body": soldier})
    for _ in range(PASSES):
        offset = knee_drift(frames, figs)
        if not np.abs(offset).any():
            break
        frames = _shifted(frames, offset, release)
        poses, _ = pin_contacts(frames.poses, frames.roots, figs, "body", table=LEG_PINS, head=False)
        frames = ClipFrames(poses, frames.roots, frames.rifles, frames.fps)
    return frames
