"""A dying slave's arms do not rise once its master is down (issue 14).

The slave copies the master's arm angles after the release, and DI.fig's torso is shaped otherwise than
soldier.fig's: kfire2dead's top arm, let go before he is down (``DeathSpec.arms_fall_early_s``), sweeps its
hand over his chest about 15 cm up as the elbow drops to the ground; the DI's, with the same angles over its
own chest and its trunk rolled onto the ground under it (:func:`authoring.slave_ground.rest_limbs`), rose
14.3 cm after its body lay (the check's ``rest_rise_cm``, limit 3; the master's 2.6). Where a death asks
(:attr:`~authoring.death_specs.DeathSpec.slave_arms_down`), last, each arm site of the slave (shoulder to
palm, :data:`authoring.slave_ground.PART_SITES`) is brought down by its arm alone, from the frame the
master's pelvis, chest and head are down (the check's :func:`~authoring.quality_rest.rest_frame`: the
slave's trunk may settle later), to at most :data:`RISE_CM` above the lowest it and each arm part it carries
have been since (the parts' lowest nodes, the check's measure). An arm part at the ground is neither brought
down nor moved across it (:data:`CONTACT_CM`), and none is turned into it (:data:`CLEAR_CM`). The change is
smoothed over the clip as :func:`~authoring.slave_ground.rest_limbs`' is.
"""

from __future__ import annotations

import numpy as np

from authoring import ik
from authoring.death_specs import spec_of
from authoring.quality_frames import FigureSet
from authoring.quality_rest import TORSO_PARTS, rest_frame
from authoring.signal_shaping import hann_smooth
from authoring.slave_body import heights_of, joint_chain, played_body
from authoring.slave_contacts import SMOOTH_FRAMES
from authoring.slave_ground import PART_SITES
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

ARMS = tuple(f"{s}_{p}" for s in ("left", "right") for p in ("upper_arm", "forearm", "hand"))
RISE_CM = 0.5  # cm: an arm site rises at most this above its lowest since the body is down (check: 3)
PASSES = 4  # the arm turns as it comes down: bring down again what still rises
# cm: an arm part this low is at the ground (the check's contact: 1.25; its nodes dip lower): its sites keep
# their height and their place across it from where it came there (brought down onto the ground, DI
# kfire2dead's left upper arm slid 5.4 cm)
CONTACT_CM = 3.0
# cm: an arm part turned down is kept this far out of the ground (its nodes; the mesh reaches lower, and
# the build lifts the whole body out of the ground where it goes in: DI kfire2dead's pelvis rested 2.95 cm up)
CLEAR_CM = 1.0


def arms_kept_down(master: Channelset) -> bool:
    """Whether this death's slave keeps its arms from rising once down (``DeathSpec.slave_arms_down``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_arms_down


def _rises(y: np.ndarray, start: int) -> np.ndarray:
    """``(n, k)``: how far (cm, <= 0) each column of heights ``y`` must come down so that from ``start``
    on it is at most :data:`RISE_CM` above its lowest since."""
    cap = np.full_like(y, np.inf)
    cap[start:] = np.minimum.accumulate(y[start:], axis=0) + RISE_CM
    return np.minimum(0.0, cap - y)


def _held(at: np.ndarray, touching: np.ndarray) -> np.ndarray:
    """Sites ``at`` ``(n, k, 3)`` with their x and z held, while ``touching`` ``(n, k)``, where each run of
    touching frames began."""
    out = at.copy()
    for k in range(at.shape[1]):
        for i in range(1, len(at)):
            if touching[i, k] and touching[i - 1, k]:
                out[i, k, [0, 2]] = out[i - 1, k, [0, 2]]
    return out


def _parts_down(
    lows: dict[str, np.ndarray], names: list[str], down: np.ndarray, start: int
) -> tuple[np.ndarray, np.ndarray]:
    """``down`` (per site of ``names``) brought further down where an arm part it carries rises (``lows``,
    each part's lowest node), not where one is at the ground (:data:`CONTACT_CM`; those sites are returned,
    ``touching``), and up where one is under :data:`CLEAR_CM`."""
    down = down.copy()
    touching = np.zeros(down.shape, bool)
    clear = np.full(down.shape, -np.inf)
    for part, y in lows.items():
        part_down = _rises(y[:, None], start)[:, 0]
        for site in PART_SITES[part]:
            if site in names:
                k = names.index(site)
                down[:, k] = np.minimum(down[:, k], part_down)
                touching[:, k] |= y < CONTACT_CM
                clear[:, k] = np.maximum(clear[:, k], CLEAR_CM - y)
    down[touching] = 0.0
    return np.maximum(down, clear), touching


def keep_slave_arms_down(master: Channelset, slave: Channelset, figures: FigureSet) -> float:
    """Bring the dying ``slave``'s arm sites down where they rise once its master is down (its joint channels,
    in place; see the module docstring); returns the largest rise of a site left (cm), 0 where the death
    does not ask."""
    if not arms_kept_down(master):
        return 0.0
    q, loc, stype = played_body(slave, figures)
    kin = figures.kin[stype]
    mq, mloc, mtype = played_body(master, figures)
    start = rest_frame(heights_of(mq, mloc, figures, mtype, TORSO_PARTS))
    names = sorted({s for p in ARMS for s in PART_SITES[p] if s in kin.site_names})
    if start is None or not names:
        return 0.0
    cols = [kin.site_names.index(s) for s in names]
    rows = np.arange(start, len(q))
    pose = q.copy()
    for _ in range(PASSES):
        at = kin.site_globals(pose, loc)[:, cols][..., :3, 3]
        down = _rises(at[..., 1], start)
        lows = heights_of(pose, loc, figures, stype, ARMS)  # a part's lowest node, the check's measure
        down, touching = _parts_down(lows, names, down, start)
        held = _held(at, touching)
        if not (down < 0.0).any():
            break
        goals = []
        for k, site in enumerate(names):
            goal = held[rows, k].copy()
            goal[:, 1] = at[rows, k, 1] + down[rows, k]
            goals.append(ik.Goal(site, goal, None, 1.0, 1, joint_chain(site)))
        pose[rows], _ = ik.solve(
            kin, pose[rows], goals, loc[rows], iterations=40,
            damping=2.0, rest_pose=pose[rows], rest_gain=0.05, tolerance=0.05, max_dof_step=0.05,
        )  # fmt: skip
    pose = q + hann_smooth(pose - q, SMOOTH_FRAMES)
    bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    left = _rises(kin.site_globals(pose, loc)[:, cols][..., 1, 3], start)
    return float(-left.min())
