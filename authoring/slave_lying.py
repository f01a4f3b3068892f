"""A prone dying slave's forearms lie still where the master's do (issue 14).

The slave stages lay a DI forearm at the master's height only while the hands hold the rifle
(:mod:`authoring.slave_contacts`) and pin it (:mod:`authoring.slave_arms`) only where the slave's own forearm
is below the contact height: where the master's lies still after the release, prstow2dead's DI left forearm
hovered 1.5-2.3 cm up and drifted 7 cm, dragging 3.3 cm along the ground as it came down and lifted off
(M16 4.3). Where the death asks (:attr:`~authoring.death_specs.DeathSpec.slave_forearms_lying`), in the frames
the master's forearm is on the ground as the check judges it (down to the contact height, on it until it
rises past ``LIFT_OFF_CM``) and after the release, each slave forearm keeps the place and turn it had when
that began, moved and turned only as his moves and turns since (he lies still: so does it), and is aimed
at his forearm's height; a stance to the clip's end keeps the last frame (the DEAD rest). The hold eases in
and out over :data:`EASE_FRAMES` either side, the arm with its clavicle carrying it. DI's shoulders sit
higher prone than soldier.fig's, so its arm alone does not always reach down: prstow2dead's DI left forearm
lies still but 1.6-2.9 cm up over frames 14-23 where his lies on the ground (it hovered as high before).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from authoring import ik
from authoring.body_parts import contact_runs
from authoring.death_specs import spec_of
from authoring.quality import CONTACT_HEIGHT_CM, LIFT_OFF_CM
from authoring.quality_frames import FigureSet
from authoring.slave_body import played_body
from authoring.slave_contacts import SIDES
from authoring.slave_feet import merged_runs, part_points
from authoring.transitions import track_solve
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

SITE = "{side}_lower_arm.distal"  # the held site (its wrist end), its frame held too
JOINTS = ("{side}_clavicle", "{side}_shoulder", "{side}_elbow")
ABOVE_CM = 0.2  # a held forearm's lowest node lies this far above the ground (never into it)
EASE_FRAMES = 6  # the hold eases in and out over this many frames (0.1 s)
TURN_CM = 40.0  # a radian of the forearm's turn weighs this much: held as firmly as its place
ITERATIONS = 20  # per frame of the tracking ...
DOF_STEP = 0.004  # ... in steps of at most this (rad): the shoulder's three together leapt otherwise
PASSES = 2  # the forearm's lowest node changes as it turns: measure and solve again


def on_ground(points: np.ndarray) -> np.ndarray:
    """Per frame whether a part (its nodes ``points`` ``(n, k, 3)``) is on the ground as the check judges
    it: a node down to the contact height stays on it until it rises past ``LIFT_OFF_CM``."""
    runs = contact_runs(points, CONTACT_HEIGHT_CM, LIFT_OFF_CM)
    down = np.zeros(len(points), dtype=bool)
    for a, b in zip(runs.first, runs.last, strict=True):
        down[a : b + 1] = True
    return down


def hold_weights(down: np.ndarray, held_from: int) -> tuple[np.ndarray, np.ndarray]:
    """Per frame how far a slave forearm is held (smoothstep over :data:`EASE_FRAMES` either side of each
    run of ``down`` from ``held_from`` on; eased in after ``held_from`` where a run starts before it: the
    hands held the rifle) and the frame each hold takes its place from (the run's first held frame, or the
    last frame for a run to the end: the DEAD rest is kept)."""
    n = len(down)
    frames = np.arange(n)
    weight, anchor = np.zeros(n), np.full(n, -1)
    for a, b in merged_runs(down):
        a = max(a, held_from)
        if b - a < 2:
            continue
        early = a == held_from and a > 0
        u_in = (frames - a) / EASE_FRAMES if early else 1.0 - (a - frames) / EASE_FRAMES
        u = np.clip(np.minimum(u_in, 1.0 - (frames - b) / EASE_FRAMES), 0.0, 1.0)
        u[:held_from] = 0.0
        u = u * u * (3.0 - 2.0 * u)
        near = u > weight
        weight[near], anchor[near] = u[near], b if b == n - 1 else a  # to the end: where it lies there
    return weight, anchor


def lay_slave_forearms(master: Channelset, slave: Channelset, figures: FigureSet) -> float:
    """Hold the dying ``slave``'s forearms still on the ground where ``master``'s lie (its joint channels,
    in place; see the module docstring); returns the largest move of a held site (cm), 0 where the death
    does not ask for it."""
    spec = spec_of(master.name)
    release = getattr(slave, "release_frame", None)
    if spec is None or not spec.slave_forearms_lying or release is None:
        return 0.0
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    kin = figures.kin[stype]
    downs = {s: on_ground(part_points(mq, mloc, figures, mtype, (f"{s}_forearm",))) for s in SIDES}
    m_sites = figures.kin[mtype].site_globals(mq, mloc)
    pose, worst = q, 0.0
    lift = {side: np.zeros(len(q)) for side in SIDES}
    held = {side: hold_weights(downs[side], release) for side in SIDES}
    for _ in range(PASSES):
        sites = kin.site_globals(pose, loc)
        goals: list[ik.Goal] = []
        for side in SIDES:
            name = SITE.format(side=side)
            site, his = (
                sites[:, kin.site_names.index(name)],
                m_sites[:, figures.kin[mtype].site_names.index(name)],
            )
            weight, anchor = held[side]
            if not weight.any():
                continue
            # his forearm's place and turn, carried to where the slave's was as the hold began
            at = np.maximum(anchor, 0)
            target = his[:, :3, 3] + site[at, :3, 3] - his[at, :3, 3]
            target[:, 1] += np.where(anchor == len(q) - 1, 0.0, lift[side])  # the end's rest kept
            pos = site[:, :3, 3] + weight[:, None] * (target - site[:, :3, 3])
            # his turn since then, from the slave's turn then
            turned = his[:, :3, :3] @ his[at, :3, :3].transpose(0, 2, 1) @ site[at, :3, :3]
            mine = Rotation.from_matrix(site[:, :3, :3])
            towards = (mine.inv() * Rotation.from_matrix(turned)).as_rotvec()
            rot = mine * Rotation.from_rotvec(weight[:, None] * towards)
            worst = max(worst, float(np.linalg.norm(pos - site[:, :3, 3], axis=1).max()))
            joints = tuple(j.format(side=side) for j in JOINTS)
            goals.append(ik.Goal(name, pos, rot.as_matrix(), 1.0, 0, joints, TURN_CM))
        if not goals:
            return 0.0
        pose = track_solve(kin, pose, goals, loc, iterations=ITERATIONS, max_dof_step=DOF_STEP)
        for side in SIDES:  # its lowest node as high as his (ABOVE_CM at least): measured, then again
            s_low = part_points(pose, loc, figures, stype, (f"{side}_forearm",))[..., 1].min(axis=1)
            m_low = part_points(mq, mloc, figures, mtype, (f"{side}_forearm",))[..., 1].min(axis=1)
            lift[side] += np.maximum(m_low, ABOVE_CM) - s_low
    bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return worst
