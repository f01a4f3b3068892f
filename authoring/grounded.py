"""A falling body that hovers a little is lowered onto the ground (issue 14, ``DeathSpec.grounded``).

The check's ``unsupported_s`` (:mod:`authoring.quality_support`) wants some body node within 2 cm of the
ground in every frame. As the kneeling soldier tips off his knee his front foot is the one part on the
ground in the physics, and the legs' lift (:mod:`authoring.leg_lift`) raises it to 2.5 cm where it would
skid: the body hung 2.2-2.7 cm up for 0.15-0.18 s (kstow2dead, kfire2dead, frames 40-52), his DI slaves,
shaped otherwise, 4.6 cm for 0.28-0.35 s. Where the lowest node is higher
than :data:`GROUNDED_CM`, the whole body (and a rifle the hands still hold) comes down by a smooth amount
that brings it there, never below :data:`CLEAR_CM`: over the check's contact height (1.25 cm), so no part
touches down that did not, and nothing new slides. Where a death asks (``DeathSpec.grounded_until_down``),
only until the pelvis is down (:func:`pelvis_down`): kstow2dead's DI slaves, lowered up to 3.7 cm as they
rolled onto their back after, then raised their pelvis 5.7 cm (trunk_rise_cm 1.64 -> 5.67).
"""

from __future__ import annotations

import numpy as np

from authoring.body_parts import true_runs
from authoring.postures import segment_heights
from authoring.quality import LIFT_OFF_CM
from authoring.quality_rest import PELVIS_NEAR_CM, near_from
from authoring.signal_shaping import smooth_above
from authoring.transitions import ClipFrames
from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

GROUNDED_CM = 1.8  # cm: a hovering body's lowest node comes down to this (the check's SUPPORT_CM: 2)
CLEAR_CM = 1.3  # cm: ... and no node comes lower than this (the check's CONTACT_HEIGHT_CM: 1.25)
SIGMA_FRAMES = 1.5  # frames: the drop eases in and out over a few frames (a hover lasts 9-17)
AIR_CM = LIFT_OFF_CM + 0.05  # cm: (``leave``) a part left in the air stays this high


PELVIS = "lower_torso"  # the segment whose lowest node is the check's pelvis (body_parts)


def drop(
    lowest: np.ndarray, until: int | None = None, leave: int = 0, parts: np.ndarray | None = None
) -> np.ndarray:
    """Per frame, how far (cm) to lower a body whose lowest node is ``lowest`` ``(n,)`` cm up: at least
    down to :data:`GROUNDED_CM`, smooth, never past :data:`CLEAR_CM` (0 where nothing hovers); a hover
    from frame ``until`` on left as it is (None: none). Given ``leave``, only each hover's first frames
    come down, its last ``leave`` left in the air (:func:`_lead_only`), and elsewhere no part of
    ``parts`` ``(k, n)`` (cm up; default: ``lowest``) off the ground comes within the lift-off height."""
    need = np.maximum(0.0, lowest - GROUNDED_CM)
    if until is not None:
        need[until:] = 0.0
    if leave:
        need = _lead_only(need, leave)
    if not need.any():
        return need
    floor = np.maximum(0.0, lowest - CLEAR_CM)
    if leave:  # a part in the air stays above the lift-off height: it touches down where and when it did
        h = lowest[None] if parts is None else parts
        kept = np.where(h <= LIFT_OFF_CM, h - CLEAR_CM, h - AIR_CM).min(axis=0)
        floor = np.where(need > 0, floor, np.maximum(0.0, kept))
    return np.minimum(smooth_above(need, SIGMA_FRAMES), floor)


def _lead_only(need: np.ndarray, leave: int) -> np.ndarray:
    """``need`` kept in each hover's frames but its last ``leave``: the body leaving the ground comes down
    where it does (stfire2dead's DI slaves' toes, pushing off); the hands reaching for the ground at the
    hover's end are left as they were (lowered with the body, they touched down early and slid 4.29 cm)."""
    out = np.zeros_like(need)
    for a, b in true_runs(need > 0):
        out[a : max(a, b - leave)] = need[a : max(a, b - leave)]
    return out


def pelvis_down(heights: dict[str, np.ndarray]) -> int:
    """The first frame the pelvis' lowest node (of segment ``heights``, :func:`postures.segment_heights`)
    comes within the check's PELVIS_NEAR_CM of where it finally lies (``legs_rise_cm``'s start)."""
    return near_from(heights[PELVIS], PELVIS_NEAR_CM)


def _drop(
    kin: FigureKinematics, poses: np.ndarray, roots: np.ndarray, until_down: bool, leave: int = 0
) -> np.ndarray:
    """:func:`drop` of a body in ``poses`` at ``roots``, only before its pelvis is down if ``until_down``."""
    h = segment_heights(kin, poses, roots)
    parts = np.stack(list(h.values()))
    return drop(parts.min(axis=0), pelvis_down(h) if until_down else None, leave, parts)


def grounded_frames(frames: ClipFrames, body: Figure, release: int, until_down: bool = False) -> ClipFrames:
    """A recorded fall lowered where it hovers (:func:`drop`, only before the pelvis is down if
    ``until_down``); the rifle with it until ``release``."""
    down = _drop(FigureKinematics(body), frames.poses, frames.roots, until_down)
    roots, rifles = frames.roots.copy(), frames.rifles.copy()
    roots[:, 1, 3] -= down
    rifles[:release, 1, 3] -= down[:release]
    return ClipFrames(frames.poses, roots, rifles, frames.fps)


def ground_channelset(chset: Channelset, body: Figure, until_down: bool = False, leave: int = 0) -> None:
    """A slave's channelset lowered where its ``body`` hovers (:func:`drop`, only before the pelvis is down
    if ``until_down``), every figure channel until its release frame, the body's after it too. In place."""
    bf = bind_channelset(chset, [body]).figures[0]
    poses = np.tile(bf.neutral.astype(np.float64), (chset.nframes, 1))
    poses[:, bf.dst] = chset.joint_data[:, bf.src]
    chan = next(c for c in chset.figure_channels() if c.column == bf.figure_channel)
    kin = FigureKinematics(body)
    loc = chset.transforms(chan)  # of the channel's root site in each frame: the figure's root's, as played
    roots = chset.roots(chan)
    if any(r != kin.root_name for r in roots):
        g = kin.site_globals(poses, np.broadcast_to(np.eye(4), (chset.nframes, 4, 4)))
        at = g[np.arange(chset.nframes), [kin.site_names.index(r) for r in roots]]
        loc = loc @ np.linalg.inv(at) @ g[:, kin.site_names.index(kin.root_name)]
    down = _drop(kin, poses, loc, until_down, leave)
    if not down.any():
        return
    held = np.arange(chset.nframes) < (chset.release_frame if chset.release_frame is not None else 0)
    moved = np.where(held[:, None], down[:, None], 0.0).repeat(chset.fig_pos.shape[1], axis=1)
    moved[:, chan.column] = down
    chset.fig_pos[:, :, 1] -= moved.astype(np.float32)
