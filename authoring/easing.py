"""Ease a recorded clip in and out of its static postures by retiming it.

A clip that starts or ends in a static posture must leave and reach it at rest: every site of the body and
the rifle moves at most :data:`END_SPEED` over the first and last :data:`END_FRAMES` frames (played
backwards, the arrival is a departure). Primitive motions with ease-in/ease-out progress still leave a
posture briskly when they are short, a foot's lift arc leaves the ground at speed, and the IK solution of
frame 1 may sit a little off the exact key posture of frame 0. Rather than tune every step, the finished
clip is *retimed*: played through a time warp ``tau`` whose rate rises smoothly from 0 over a short ramp at
each end (and runs a little faster in between, so the clip keeps its duration and its graph arc time). The
path of every site is unchanged (feet stay planted, palms stay on the rifle), only the timing near the ends
changes; the first and last frames stay the key postures exactly. Each ramp is the shortest of
:data:`RAMPS` that brings its end under the limit (none if it already is), so clips that already ease are
left alone.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Protocol, TypeVar

import numpy as np

from authoring.signal_shaping import smoothstep
from peabody import quaternion
from peabody.fk import FigureKinematics

END_SPEED = 0.4  # m/s: the target at the ends (the check's limit is 0.5; margin for the slaved DI clip)
END_FRAMES = 3  # frame steps measured at each end
RAMPS = (0.0, 0.05, 0.08, 0.11, 0.14, 0.17, 0.2, 0.25, 0.3, 0.35)  # s, candidate ramp lengths, shortest first
RAMP_SHARE = 0.5  # a ramp takes at most half the clip (the two never overlap)
SUBSTEPS = 64  # integration steps per frame of the warp's rate


class Frames(Protocol):
    """A recorded clip (``transitions.ClipFrames``): poses, root and rifle placements per frame."""

    poses: np.ndarray
    roots: np.ndarray
    rifles: np.ndarray
    fps: float


F = TypeVar("F", bound=Frames)  # the clip type passes through: a ClipFrames comes back as one


def site_speeds(kin: FigureKinematics, rkin: FigureKinematics, clip: Frames) -> np.ndarray:
    """``(n - 1,)`` the fastest site (body or rifle) between consecutive frames, m/s."""
    body = kin.site_globals(clip.poses, clip.roots)[..., :3, 3]
    gun = rkin.site_globals(np.zeros((len(clip.poses), 0)), clip.rifles)[..., :3, 3]
    pts = np.concatenate([body, gun], axis=1)
    return np.linalg.norm(np.diff(pts, axis=0), axis=-1).max(axis=1) * clip.fps / 100.0


def end_speeds(kin: FigureKinematics, rkin: FigureKinematics, clip: Frames) -> tuple[float, float]:
    """The fastest site over the first and over the last :data:`END_FRAMES` frame steps, m/s."""
    v = site_speeds(kin, rkin, clip)
    return float(v[:END_FRAMES].max(initial=0.0)), float(v[-END_FRAMES:].max(initial=0.0))


def warp(n: int, fps: float, ramp_in: float, ramp_out: float) -> np.ndarray:
    """``(n,)`` source times (s) for the frames of a retimed clip of ``n`` frames: the rate ramps up from 0
    over ``ramp_in`` s and down to 0 over the last ``ramp_out`` s (smoothstep), constant in between, and the
    warp maps the clip's first and last times onto themselves."""
    total = (n - 1) / fps
    t = np.linspace(0.0, total, (n - 1) * SUBSTEPS + 1)
    rate = np.ones_like(t)
    if ramp_in > 0:
        rate *= smoothstep(t / ramp_in)
    if ramp_out > 0:
        rate *= smoothstep((total - t) / ramp_out)
    area = np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2.0)])
    tau = total * area / area[-1]
    return tau[::SUBSTEPS]


def _blend_frames(m: np.ndarray, i: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rigid frames ``m[i]`` to ``m[i + 1]`` at ``w`` (lerp positions, slerp rotations)."""
    q = quaternion.make_continuous(quaternion.from_matrix(m[:, :3, :3]))
    rot = quaternion.slerp(q[i], q[i + 1], w)
    pos = m[i, :3, 3] + w[:, None] * (m[i + 1, :3, 3] - m[i, :3, 3])
    return quaternion.to_transform(pos, rot)


def retime(clip: F, times: np.ndarray) -> F:
    """The clip sampled at ``times`` (s, within the clip): joint angles interpolated linearly between the
    two nearest recorded frames, placements blended; exact recorded frames stay exact."""
    n = len(clip.poses)
    f = np.clip(np.asarray(times, np.float64) * clip.fps, 0.0, n - 1)
    i = np.minimum(np.floor(f).astype(int), n - 2)
    w = f - i
    poses = clip.poses[i] + w[:, None] * (clip.poses[i + 1] - clip.poses[i])
    return replace(  # type: ignore[type-var]
        clip, poses=poses, roots=_blend_frames(clip.roots, i, w), rifles=_blend_frames(clip.rifles, i, w)
    )


def eased_in(clip: F, ramp: float) -> tuple[F, np.ndarray]:
    """``clip`` leaving its first frame from rest: played through a warp whose rate rises from 0 over
    ``ramp`` s (smoothstep) and is 1 after it, the clip lengthened by the time the ramp loses (``ramp / 2``),
    so nothing after it plays faster (a recorded fall: :func:`ease_ends` speeds up its middle); and the
    source times (s) of its frames."""
    n = len(clip.poses)
    extra = round(ramp * clip.fps / 2.0)
    times = warp(n + extra, clip.fps, ramp, 0.0) * ((n - 1) / (n + extra - 1))
    return retime(clip, times), times


def ease_ends(
    kin: FigureKinematics,
    rkin: FigureKinematics,
    clip: F,
    start: bool = True,
    end: bool = True,
    limit: float = END_SPEED,
) -> F:
    """``clip`` retimed so that it leaves its first frame (``start``) and reaches its last (``end``) at no
    more than ``limit`` m/s: each end gets the shortest ramp of :data:`RAMPS` that does it (the longest
    within :data:`RAMP_SHARE` of the clip if none does); unchanged if both ends already do."""
    n = len(clip.poses)
    if n < 2 * END_FRAMES + 2:
        return clip
    ramps = [r for r in RAMPS if r <= RAMP_SHARE * (n - 1) / clip.fps]
    pick = [0.0, 0.0]
    for _ in range(2):  # each ramp slightly speeds up the clip between them: settle both
        for k, want in enumerate((start, end)):
            if not want:
                continue
            for r in ramps:
                trial = list(pick)
                trial[k] = r
                eased = retime(clip, warp(n, clip.fps, *trial))
                pick = trial
                if end_speeds(kin, rkin, eased)[k] <= limit:
                    break
    if pick == [0.0, 0.0]:
        return clip
    return retime(clip, warp(n, clip.fps, *pick))
