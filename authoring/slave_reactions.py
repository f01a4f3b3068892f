"""A reaction's slave as its posture plus the master's change (issue 14: prone recoil and flinch on DI).

A reaction (:mod:`authoring.reactions`) leaves its posture and comes back within 0.3-0.65 s, a few degrees
of spine and neck. Slaved frame by frame like any clip (:mod:`authoring.slaving`, then the prone forearms
laid, the rifle slid under them, the ends snapped to the posture node and faded in over 12 frames), the
prone reactions came out larger and other than the master's: made visible (5 degrees of lateral bend,
the neck at its limit), DI's prone flinch dragged a forearm 3.7-6.6 cm, left its palms 3-4.8 cm off the
rifle and its first frames moved at 1.2-2.5 m/s; the prone recoil's shoulders went 8.5 cm where the
master's go 3.0. DI's posture itself is sound (every clip meeting it passes), so a reaction that asks
(:attr:`authoring.reactions.Reaction.slave_follows`) is the slave's snapped first frame plus the master's
change (:meth:`~authoring.slaving.MasterSlavePair.copy_pose`, the body's placement moved as the master's);
its arms are solved once, at the peak, with the elbows pinned where they lie (a prone rifleman's elbows are
planted: above the palms) and the rifle slid to where the palms can hold it, then eased there and back with
the trunk (:func:`hold_arms`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from authoring import ik
from authoring.quality_frames import FigureSet
from authoring.slave_body import played_body
from authoring.slaving import SLAVE_CONSTRAINTS, MasterSlavePair
from peabody import quaternion
from peabody.fk import FigureKinematics
from server.motion.binding import bind_channelset, protofiletype
from server.motion.channelset import Channelset

TRACK_DOF_STEP = 0.05  # rad per iteration: a tracked frame stays on its neighbour's branch
PINNED = 4  # priority of an elbow or wrist on the ground: above the palms' 3 (the rifle gives, not the elbow)
FIT_ROUNDS = 4  # solve the arms, move the rifle to the palms, again
SHOULDER_KEPT = PINNED  # an acromion kept as firmly as the elbows (at 2, under the palms, it swung as free)
GROUND_CM = 6.0  # an elbow or wrist site this low lies on the ground (its centre sits ~4 cm up)


def follow_master(
    master: Channelset,
    slave: Channelset,
    pair: MasterSlavePair,
    figures: FigureSet,
    turned: bool = False,
    shoulders_kept: bool = False,
) -> None:
    """``slave`` (in place) as its first frame plus ``master``'s change from its first frame, its palms
    then held on the rifle and its elbows and wrists on the ground where they lie (:func:`hold_arms`)."""
    mq, mloc, mtype = played_body(master, figures)
    copied = pair.copy_pose(mq, figures.kin[mtype].segment_globals(mq, mloc))
    bound = bind_channelset(slave, [pair.slave]).figures[0]
    q = slave.joint_data[0, bound.src].astype(np.float64) + (copied - copied[0])[:, bound.dst]
    # the master's body and rifle: each placement's move from its first, in the world
    moves: dict[str, np.ndarray] = {}
    for chan in master.figure_channels():
        t = master.transforms(chan)
        moves["body" if chan.protofiletype == mtype else "rifle"] = t @ np.linalg.inv(t[0])
    placed: dict[str, np.ndarray] = {}
    for chan in slave.figure_channels():
        what = "body" if chan.protofiletype == protofiletype(pair.slave) else "rifle"
        placed[what] = moves[what] @ slave.transforms(chan)[0]
        pos, quat = quaternion.from_transform(placed[what])
        slave.fig_pos[:, chan.column] = pos.astype(slave.fig_pos.dtype)
        slave.fig_quat[:, chan.column] = quaternion.make_continuous(quat).astype(slave.fig_quat.dtype)
    pose = np.tile(pair.slave_kin.neutral_pose(), (len(q), 1))
    pose[:, bound.dst] = q
    pose, placed["rifle"] = hold_arms(
        pair.slave_kin, pose, placed["body"], placed["rifle"], turned, shoulders_kept
    )
    slave.joint_data[:, bound.src] = pose[:, bound.dst].astype(slave.joint_data.dtype)
    for chan in slave.figure_channels():
        if chan.protofiletype != protofiletype(pair.slave):
            pos, quat = quaternion.from_transform(placed["rifle"])
            slave.fig_pos[:, chan.column] = pos.astype(slave.fig_pos.dtype)
            slave.fig_quat[:, chan.column] = quaternion.make_continuous(quat).astype(slave.fig_quat.dtype)


def hold_arms(
    kin: FigureKinematics,
    poses: np.ndarray,
    roots: np.ndarray,
    rifles: np.ndarray,
    turned: bool = False,
    shoulders_kept: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """``poses`` ``(n, ndof)`` with the arms eased to their solve at the peak and back, and the rifle's
    placements ``(n, 4, 4)`` moved with them from ``rifles`` (the master's): each elbow (and a wrist within
    ``GROUND_CM``) pinned where it lies; tracked frame after frame instead, DI's clavicles jumped 16-23
    degrees in a frame, and held on the master's rifle its left palm stayed 2.6-4.4 cm short of it."""
    g0 = kin.site_globals(poses[0], roots[0])
    change = np.linalg.norm(poses - poses[0], axis=1)
    peak = int(np.argmax(change))
    if change[peak] == 0.0:
        return poses.copy(), rifles.copy()
    palms = [c for c in SLAVE_CONSTRAINTS if c.group == "palm"]
    arms = np.concatenate([_dofs(kin, j) for c in palms for j in c.joints])
    pinned = []
    for c in SLAVE_CONSTRAINTS:  # a prone rifleman's elbows are planted: pinned where they lie
        if c.group == "elbow":
            side = c.slave_site.split("_")[0]
            for site in (c.slave_site, f"{side}_lower_arm.distal"):
                at = g0[kin.site_names.index(site), :3, 3]
                if site == c.slave_site or at[1] <= GROUND_CM:
                    pinned.append(ik.Goal(site, at, None, 1.0, PINNED, c.joints))
    if shoulders_kept:  # each acromion where the trunk took it (the palms' clavicles swung DI's 8.6 cm)
        gp = kin.site_globals(poses[peak], roots[peak])
        for side in ("left", "right"):
            at = gp[kin.site_names.index(f"{side}_clavicle.acromion"), :3, 3]
            pinned.append(
                ik.Goal(f"{side}_clavicle.acromion", at, None, 1.0, SHOULDER_KEPT, (f"{side}_clavicle",))
            )
    # the arms solved once, at the reaction's peak, from the posture (tracked frame by frame with the elbows
    # pinned, DI's clavicles jumped 16-23 degrees in a frame); the rifle then goes where the held palms
    # can take it (held where the master's goes, DI's left palm stayed 2.6-4.4 cm short of it)
    rifle = rifles[peak]
    key = poses[peak : peak + 1].copy()
    key[:, arms] = poses[0, arms]
    for _ in range(FIT_ROUNDS):
        hold = [rifle @ np.linalg.inv(rifles[0]) @ g0[kin.site_names.index(c.slave_site)] for c in palms]
        goals = list(pinned)
        for c, t in zip(palms, hold, strict=True):
            goals.append(ik.Goal(c.slave_site, t[:3, 3], None, 1.0, 3, c.joints))
            goals.append(ik.Goal(c.slave_site, None, t[:3, :3], 1.0, 1, c.joints, 8.0))
        key, _ = ik.solve(
            kin, key, goals, roots[peak : peak + 1], iterations=200, rest_pose=poses[peak : peak + 1],
            rest_gain=0.5, max_dof_step=TRACK_DOF_STEP,
        )  # fmt: skip
        g = kin.site_globals(key[0], roots[peak])
        got = [g[kin.site_names.index(c.slave_site), :3, 3] for c in palms]
        if turned:
            rifle = _turned_to(rifle, got, [t[:3, 3] for t in hold])
            continue
        moved = np.eye(
            4
        )  # the rifle slid (not turned: a palm's turn is held loosely) to the palms' mean miss
        moved[:3, 3] = np.mean([a - t[:3, 3] for a, t in zip(got, hold, strict=True)], axis=0)
        rifle = moved @ rifle
    # how far along to the peak the trunk is (the head lags it: measured with it, the arms lagged the trunk
    # and the palms were 2.7 cm off the rifle on the way)
    sight = [j for c in SLAVE_CONSTRAINTS if c.group == "sight" for j in c.joints]
    trunk = np.setdiff1d(np.arange(poses.shape[1]), np.concatenate([arms, *(_dofs(kin, j) for j in sight)]))
    d = poses[peak, trunk] - poses[0, trunk]
    share = np.clip((poses[:, trunk] - poses[0, trunk]) @ d / float(d @ d), 0.0, None)
    q = poses.copy()
    q[:, arms] = poses[0, arms] + share[:, None] * (key[0, arms] - poses[0, arms])
    return q, _blend(rifles[0], rifle, share)


def _turned_to(rifle: np.ndarray, got: list[np.ndarray], want: list[np.ndarray]) -> np.ndarray:
    """``rifle`` turned about the right palm's hold (the grip, by the butt in the shoulder) so that the left
    palm's hold comes to where the left palm got (``got``/``want``: left, right)."""
    about = np.eye(4)
    about[:3, 3] = got[1]
    turn = np.eye(4)
    turn[:3, :3] = Rotation.align_vectors([got[0] - got[1]], [want[0] - want[1]])[0].as_matrix()
    shift = np.eye(4)
    shift[:3, 3] = got[1] - want[1]
    return about @ turn @ np.linalg.inv(about) @ shift @ rifle


def _dofs(kin: FigureKinematics, joint: str) -> np.ndarray:
    return np.arange(kin.dof_slices[joint].start, kin.dof_slices[joint].stop)


def _blend(a: np.ndarray, b: np.ndarray, share: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)``: rigid ``a`` moved ``share`` of the way to ``b`` (1 at ``b``; beyond it further)."""
    step = np.linalg.inv(a) @ b  # in the rifle's own frame: turned about itself, not the world's origin
    rot = Rotation.from_matrix(step[:3, :3]).as_rotvec()
    out = np.tile(np.eye(4), (len(share), 1, 1))
    out[:, :3, :3] = Rotation.from_rotvec(share[:, None] * rot).as_matrix()
    out[:, :3, 3] = share[:, None] * step[:3, 3]
    return a @ out
