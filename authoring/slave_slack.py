"""A dead slave's feet go slack as the master's do: its ankles and toes take his angles (issue 14).

A crawling death's feet go slack after he lands (:attr:`authoring.deaths.DeathSpec.slack_feet`): his ankles
end pointed 60 degrees and everted 30, the toes a little up, the heels 14.9 cm up. The DI slave's feet were
solved to his foot's points instead (:mod:`authoring.slave_feet`' lying leg, the foot held where the knee is
down): its ankles ended pointed as far but everted the other way (-16 to -20 degrees), its toes curled to
their 70 degree limit, and it lay on its toes, heels 19.3 cm up (crawl2dead_low).

So for a death that asks it (:attr:`~authoring.deaths.DeathSpec.slave_feet_slack`), once the master lies
still and his feet then go slack (:func:`slack_progress`), the slave's ankles and toes go from where they
lay when he came to rest to his angles (mapped by joint name), as far along as his feet have gone: they
move only while his do, and end as his (DEAD@crawl's DI heels 19.3 -> 14.4 cm). Its legs lie otherwise
than his, so where his ankles turn a slave's foot into the ground its knee bends the least that lifts it
out (:func:`_knee_out_of_ground`; else the build lifted the whole body off the ground by it).
"""

from __future__ import annotations

import numpy as np

from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smooth_above
from authoring.slave_body import played_body
from authoring.slave_contacts import SIDES
from authoring.slave_feet import part_points
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

JOINTS = ("ankle", "toes")  # a foot's joints that go slack (the knee and hip are the legs' own settle's)
STILL_DEG = 0.05  # the master's feet' angles changing less than this a frame (summed) are still ...
STILL_FRAMES = 10  # ... and this many frames of it before his last move: he had come to rest (landed)
KNEE_STEPS_DEG = np.arange(0.0, 41.0, 1.0)  # a foot turned into the ground: the knee bent this much more ...
KNEE_SIGMA_FRAMES = 3.0  # ... the least that lifts it out, smoothed over the clip (at or above the need)


def slack_progress(angles: np.ndarray) -> np.ndarray:
    """Per frame how far ``(n,)`` the master's feet (``angles`` ``(n, k)``, radians) have gone slack: 0 up to
    the end of his last still spell (``STILL_FRAMES`` or more) before his feet's last move, then the share of
    that move's angle change (summed over the joints) done, 1 from its end. All 0 where his feet never rest
    and then move."""
    n = len(angles)
    change = np.degrees(np.abs(np.diff(angles, axis=0))).sum(axis=1)  # change[i]: into frame i + 1
    moving = np.flatnonzero(change >= STILL_DEG)
    out = np.zeros(n)
    if not len(moving):
        return out
    last = int(moving[-1])
    still = 0
    for i in range(last, -1, -1):  # back from his last move to a still spell long enough
        still = still + 1 if change[i] < STILL_DEG else 0
        if still >= STILL_FRAMES:
            start = i + STILL_FRAMES  # the first change of the slack is into frame start + 1
            break
    else:
        return out
    done = np.concatenate([[0.0], np.cumsum(change[start:])])
    out[start:] = done / done[-1]
    return out


def follow_slack(own: np.ndarray, master: np.ndarray) -> np.ndarray:
    """The slave's foot angles ``own`` ``(n, k)`` going from where they lay when the master came to rest to
    his (``master``, same joints) as his feet go slack (:func:`slack_progress`); unchanged before."""
    w = slack_progress(master)
    if not w.any():
        return own.copy()
    start = int(np.flatnonzero(w > 0.0)[0]) - 1
    out = own.copy()
    out[start:] = (1.0 - w[start:, None]) * own[start] + w[start:, None] * master[start:]
    return out


def _knee_out_of_ground(pose: np.ndarray, loc: np.ndarray, figures: FigureSet, stype: str, side: str) -> None:
    """Bend the ``side`` knee of ``pose`` ``(n, ndof)`` (in place) the least (:data:`KNEE_STEPS_DEG`,
    smoothed over the clip) that keeps its foot out of the ground: the DI's legs lie otherwise than his, and
    with his ankle angles its left foot went 3.7 cm into the ground (the build lifted the whole body off
    it, the chest 3.7 cm up). Lying face down, the knee bending lifts the foot."""
    kin = figures.kin[stype]
    knee = kin.dof_slices[f"{side}_knee"].start
    low = np.empty((len(KNEE_STEPS_DEG), len(pose)))
    for i, step in enumerate(np.radians(KNEE_STEPS_DEG)):
        bent = pose.copy()
        bent[:, knee] += step
        low[i] = part_points(bent, loc, figures, stype, (f"{side}_foot",))[..., 1].min(axis=1)
    ok = low >= 0.0
    need = np.where(ok.any(axis=0), KNEE_STEPS_DEG[ok.argmax(axis=0)], KNEE_STEPS_DEG[-1])
    if need.any():
        bend = np.radians(smooth_above(need, KNEE_SIGMA_FRAMES))
        pose[:, knee] = np.minimum(pose[:, knee] + bend, kin.upper[knee])


def slack_slave_feet(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """The slave's ankles and toes follow the master's as his feet go slack (``slave``'s joint channels, in
    place, :func:`follow_slack`); returns the largest change of a foot angle per frame (degrees)."""
    mq, _, mtype = played_body(master, figures)
    q, loc, stype = played_body(slave, figures)
    mkin, kin = figures.kin[mtype], figures.kin[stype]
    names = [f"{side}_{j}" for side in SIDES for j in JOINTS]
    src = np.concatenate([np.arange(mkin.ndof)[mkin.dof_slices[j]] for j in names])
    dst = np.concatenate([np.arange(kin.ndof)[kin.dof_slices[j]] for j in names])
    pose = q.copy()
    pose[:, dst] = np.clip(follow_slack(q[:, dst], mq[:, src]), kin.lower[dst], kin.upper[dst])
    for side in SIDES:
        _knee_out_of_ground(pose, loc, figures, stype, side)
    change = np.degrees(np.abs(pose - q)).max(axis=1)
    if change.any():
        bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
        slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return change
