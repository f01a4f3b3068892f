"""A dying slave rests where its master rests: after the hands let go (a death's ``release_frame``), every
part of the DI.fig slave lies on the ground where the master's lies there, nothing goes into the ground, and
the dropped rifle lies clear of the slave's body.

After the release the slaving copies the master's angles (:func:`authoring.slaving._let_go`), and DI.fig's
shoulders, neck and torso are shaped differently from soldier.fig's: with the same angles a DI hand or
forearm that the master lays on the ground went up to 10 cm into it, and lifting the whole body out of it
(:func:`authoring.build.lift_off_ground`) left the DI hovering 10-12 cm over the ground, heels 30 cm up.
So the parts are solved instead (:func:`rest_limbs`), frame by frame, following the master's contacts
whatever the death: each part's sites move up or down by how far the slave's part is from the master's (his
part on the ground: to his height; up in the air: only out of the ground). A limb part in contact moves
horizontally as the master's site of the same name does (:func:`_plants`: it slides no more than his).
Once the master lies still (:func:`_settled`) the trunk settles: the body goes down (:func:`_trunk_drop`)
and rolls or pitches (root ``ty rx rz``) onto the trunk parts the master rests on. A last unplanted pass
takes out of the ground what a plant held there. :func:`clear_rifle` then pushes the dropped rifle out of
the slave's segment hulls and the ground.
"""

from __future__ import annotations

import numpy as np

from authoring import ik
from authoring.death_specs import spec_of
from authoring.quality_frames import FigureSet, play
from authoring.quality_rest import down_from
from authoring.signal_shaping import hann_smooth
from authoring.slave_body import heights_of, joint_chain, played_body, write_pose
from authoring.slave_contacts import SMOOTH_FRAMES, ground_fade
from peabody import quaternion
from peabody.fk import FigureKinematics
from server.motion.channelset import Channelset

SIDES = ("left", "right")
# a body part (as the quality check names it) -> the slave sites that carry it up or down
PART_SITES: dict[str, tuple[str, ...]] = {
    **{f"{s}_hand": (f"{s}_lower_arm.distal", f"{s}_palm.distal") for s in SIDES},
    **{f"{s}_forearm": (f"{s}_lower_arm.proximal", f"{s}_lower_arm.distal") for s in SIDES},
    **{f"{s}_foot": (f"{s}_foot.heel", f"{s}_toes.distal") for s in SIDES},
    **{f"{s}_knee": (f"{s}_lower_leg.knee",) for s in SIDES},
    **{f"{s}_thigh": (f"{s}_upper_leg.trochanter", f"{s}_upper_leg.distal") for s in SIDES},
    **{f"{s}_upper_arm": (f"{s}_upper_arm.deltoid", f"{s}_lower_arm.proximal") for s in SIDES},
    "head": ("bottom_head.proximal", "bottom_head.distal"),
    "pelvis": ("lower_torso.front", "lower_torso.back", "lower_torso.left_hip", "lower_torso.right_hip"),
    "belly": ("middle_torso.navel", "middle_torso.vl2"),
    "chest": (
        "upper_torso.sternum",
        "upper_torso.back",
        "upper_torso.left_clavicle",
        "upper_torso.right_clavicle",
    ),
}
TRUNK = ("pelvis", "belly", "chest")
HIPS = ("left_thigh", "right_thigh")  # turn with the pelvis: the body is not lowered through them either
LIMB_PASSES = 4  # a part's lowest node moves along it as the limb turns: solve again for what is left
ARM_PARTS = ("_hand", "_forearm", "_upper_arm")  # held where the master's go (DeathSpec.slave_arms_follow)
CHEST = "upper_torso.sternum"  # an arm goes out sideways away from this (_sideways)
ROOT = "lower_torso.proximal"  # a slave site without a master site of its name moves as this one does
CONTACT_CM = 1.3  # the master's part this low is on the ground (the quality check's 1.25 cm)
MARGIN_CM = 0.3  # a part the master holds up is kept this far above the ground at least
AIR_SHARE = 0.5  # ... and at least this share of the master's height
ROOT_DOFS = ("tx", "ty", "tz", "rx", "rz")  # the body may go down and roll or pitch onto what it rests on
SETTLE_SPEED_CM_S = 5.0  # the master lies still: his root moves slower than this for the rest of the clip
SETTLE_FRAMES = 15  # ... the trunk is lowered onto the ground over this many frames from then
ARMS_STILL_CM_S = 10.0  # ... and, where a death asks, his arm and head sites slower than this
IN_PLACE_CM = 0.01  # a pelvis node moving less than this a frame: the body turns about it, in place
FADE_FRAMES = 12  # after the release the goals fade in over this many frames (the slaving's own fade)
# where a death asks (DeathSpec.slave_settle_down) the trunk settles once the master's pelvis and chest lie
# within DOWN_CM of where they end, over DOWN_SETTLE_FRAMES (over 15, kfire2dead's DI upper arm, on the
# ground under it while he still rolled, slid 3.07 cm and its chest rose 2.02 cm after it lay)
DOWN_CM = 3.0
DOWN_SETTLE_FRAMES = 30


def _need(master: np.ndarray, slave: np.ndarray) -> np.ndarray:
    """How far (cm, up positive) a slave part should move: to the master's height where his part lies on
    the ground, fading to just out of the ground (``MARGIN_CM``) where it is up in the air, and at least
    :data:`AIR_SHARE` of the master's height there (a dead leg lifted clear to turn, ``dead_legs``: lowered
    onto the ground with the slave's thigh, DI's foot skidded 9.7 cm as it turned)."""
    on = ground_fade(master)
    rest = np.maximum(master, 0.0) - slave
    clear = np.maximum(0.0, np.maximum(MARGIN_CM, AIR_SHARE * master) - slave)
    return on * rest + (1.0 - on) * clear


def fade_in(n: int, release: int, frames: int = FADE_FRAMES) -> np.ndarray:
    """Per frame, 0 until ``release``, easing to 1 over ``frames``."""
    u = np.clip((np.arange(n) - release) / frames, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def rest_limbs(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Lay the slave's limbs, head and trunk where the master's are after the release (``slave``'s joint and
    body channels, in place); returns the largest remaining distance from the wanted height per frame (cm)."""
    release = getattr(slave, "release_frame", None)
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    n = len(q)
    if release is None or release >= n - 1:
        return np.zeros(n)
    kin = figures.kin[stype]
    parts = tuple(PART_SITES)
    m_h = heights_of(mq, mloc, figures, mtype, parts)
    w = fade_in(n, release)
    q_loc, loc = loc, loc.copy()
    pose = q.copy()
    frames = w > 0
    sub = np.flatnonzero(frames)

    def needs(pose: np.ndarray, loc: np.ndarray) -> dict[str, np.ndarray]:
        s_h = heights_of(pose, loc, figures, stype, parts)
        return {p: w * _need(m_h[p], s_h[p]) for p in parts if p in s_h and p in m_h}

    limbs = tuple(p for p in parts if p not in TRUNK)
    unsolved, m_at = _positions(kin, q, loc), _positions(figures.kin[mtype], mq, mloc)
    in_place = _rolling_in_place(mq, mloc, figures, mtype) if _rolls(master) else None
    settle = w * _settled(mloc, float(master.fps), in_place)
    if _settles_arms_still(master):
        settle = np.minimum(settle, fade_in(n, _arms_still(m_at, float(master.fps)), SETTLE_FRAMES))
    arm_out, rigid = _arm_out(master), _trunk_rigid(master)
    follow = _arms_follow(master)
    planted = _plants(unsolved, m_at, m_h, release, follow=follow)
    if _settles_down(master):  # from his trunk down, however his root still turns (slave_settle_down)
        settle = w * fade_in(n, _trunk_down(m_h), DOWN_SETTLE_FRAMES)
    if _spine_laid(master):  # its trunk lies as his already (slave_spine): nothing to turn it onto
        settle = np.zeros(n)
    # once the master lies still, the trunk (the body rolls or pitches onto what the master rests on); the
    # limbs throughout; last, the limbs again unplanted: a part that its plant kept in the ground comes out
    stages = [(TRUNK, ROOT_DOFS, True), (limbs, (), True)] * LIMB_PASSES + [(limbs, (), False)]
    for k, (group, root_dofs, planting) in enumerate(stages):
        if k % 2 == 0 and k < len(stages) - 1:
            loc[:, 1, 3] += settle * _trunk_drop(m_h, heights_of(pose, loc, figures, stype, TRUNK + HIPS))
        plants = planted if planting else {}
        if arm_out and planting and group is limbs:  # a part landing as the trunk settles: from the solve
            plants = _plants(unsolved, m_at, m_h, release, (_positions(kin, pose, loc), settle > 0), follow)
        scale = settle if group is TRUNK else 1.0
        need = {p: v * scale for p, v in needs(pose, loc).items() if p in group}
        goals = part_goals(kin, pose[sub], loc[sub], need, sub, plants, arm_out, rigid)
        solved, report = ik.solve(
            kin, pose[sub], goals, loc[sub], iterations=40,
            damping=2.0, rest_pose=pose[sub], rest_gain=0.05, tolerance=0.05, max_dof_step=0.05,
            root_dofs=root_dofs,
        )  # fmt: skip
        pose[sub] = solved
        if report.root_location is not None:
            loc[sub] = report.root_location
    # frames solved alone can land on different branches of a redundant arm: smooth the change over the clip
    pose = q + hann_smooth(pose - q, SMOOTH_FRAMES) * frames[:, None]
    loc = _smooth_moves(q_loc, loc, frames)
    write_pose(slave, figures, stype, pose, loc @ np.linalg.inv(q_loc))
    left = needs(pose, loc)
    return np.max(np.abs(np.stack(list(left.values()))), axis=0)


def _arm_out(master: Channelset) -> bool:
    """Whether this death's slave moves its arms out of the ground sideways (``DeathSpec.slave_arm_out``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_arm_out


def _trunk_rigid(master: Channelset) -> bool:
    """Whether this death's slave trunk is laid by its root alone (``DeathSpec.slave_trunk_rigid``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_trunk_rigid


def _arms_follow(master: Channelset) -> bool:
    """Whether this death's slave arms go where the master's go after the release, on the ground or not
    (``DeathSpec.slave_arms_follow``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_arms_follow


def _settles_arms_still(master: Channelset) -> bool:
    """Whether this death's slave trunk settles only once the master's arms and head lie still too
    (``DeathSpec.slave_settle_arms_still``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_settle_arms_still


def _spine_laid(master: Channelset) -> bool:
    """Whether this death's slave trunk was laid by its spine (``DeathSpec.slave_spine_laid``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_spine_laid


def _arms_still(at: dict[str, np.ndarray], fps: float) -> int:
    """The frame from which every arm and head site of ``at`` (the master's positions) moves slower than
    :data:`ARMS_STILL_CM_S` for the rest of the clip."""
    parts = [p for p in PART_SITES if p.endswith(("arm", "hand")) or p == "head"]
    sites = [at[s] for p in parts for s in PART_SITES[p] if s in at]
    speed = np.linalg.norm(np.diff(np.stack(sites), axis=1), axis=2).max(axis=0) * fps
    moving = np.flatnonzero(speed > ARMS_STILL_CM_S)
    return int(moving[-1]) + 1 if len(moving) else 0


def _rolls(master: Channelset) -> bool:
    """Whether this death's master rolls his pelvis with each leg (``DeathSpec.prone_legs_roll``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.prone_legs_roll


def _rolling_in_place(q: np.ndarray, loc: np.ndarray, figures: FigureSet, ptype: str) -> np.ndarray:
    """``(n - 1,)``: whether the master's body moves from each frame to the next only by turning about one
    of its pelvis's nodes, which stays where it was (to :data:`IN_PLACE_CM`): a prone death's pelvis
    rolling with a leg moves his root 10 cm/s, yet he lies still."""
    kin = figures.kin[ptype]
    nodes, segs = figures.nodes(ptype)
    pelvis = figures.node_parts(ptype) == "pelvis"
    g = kin.segment_globals(q, loc)
    pts = np.einsum("nkij,kj->nki", g[:, segs[pelvis], :3, :], nodes[pelvis])
    return np.linalg.norm(np.diff(pts, axis=0), axis=2).min(axis=1) < IN_PLACE_CM


def _settled(root: np.ndarray, fps: float, in_place: np.ndarray | None = None) -> np.ndarray:
    """Per frame, 0 while the master's body still moves (its root faster than ``SETTLE_SPEED_CM_S``, but not
    where it only turns ``in_place``, :func:`_rolling_in_place`), easing to 1 over ``SETTLE_FRAMES`` once it
    lies still for the rest of the clip: lowering a falling or sliding slave onto the ground kept its trunk
    on the ground while the master's body moved on (it skated)."""
    speed = np.linalg.norm(np.diff(root[:, :3, 3], axis=0), axis=1) * fps
    if in_place is not None:
        speed[in_place] = 0.0
    moving = np.flatnonzero(speed > SETTLE_SPEED_CM_S)
    still = int(moving[-1]) + 1 if len(moving) else 0
    return fade_in(len(root), still, SETTLE_FRAMES)


def _settles_down(master: Channelset) -> bool:
    """Whether this death's slave trunk settles once the master's trunk is down
    (``DeathSpec.slave_settle_down``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_settle_down


def _trunk_down(heights: dict[str, np.ndarray]) -> int:
    """The frame from which the master's pelvis and chest (their lowest nodes' ``heights``) stay within
    :data:`DOWN_CM` of where they finally lie."""
    return max(down_from(heights[part], DOWN_CM) for part in ("pelvis", "chest"))


def _smooth_moves(before: np.ndarray, after: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Root placements ``after`` ``(n, 4, 4)`` whose move from ``before`` (in the root's frame: a drop and a
    small roll or pitch, solved frame by frame) is smoothed over the clip like the joints' change (only
    in ``frames``), so the body does not tremble as it lies."""
    local = np.linalg.inv(before) @ after
    quat = quaternion.from_matrix(local[:, :3, :3])  # (w, x, y, z), w >= 0: small turns, no sign flips
    parts = np.concatenate([local[:, :3, 3], quat], axis=1)
    ident = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    parts = ident + hann_smooth(parts - ident, SMOOTH_FRAMES) * frames[:, None]
    moved = quaternion.to_transform(
        parts[:, :3], parts[:, 3:] / np.linalg.norm(parts[:, 3:], axis=1)[:, None]
    )
    return before @ moved


def _trunk_drop(master: dict[str, np.ndarray], slave: dict[str, np.ndarray]) -> np.ndarray:
    """Per frame, how far (cm, negative: down) to lower the body so that its trunk rests as low as the
    master's: as far as the trunk part the master rests on that floats the most asks, but no trunk part into
    the ground (the limbs are solved again after it); never a rise (lifting is the build's last step)."""
    trunk = [p for p in TRUNK if p in master and p in slave]
    if not trunk:
        return np.zeros(len(next(iter(slave.values()))))
    want = np.min([ground_fade(master[p]) * (np.maximum(master[p], 0.0) - slave[p]) for p in trunk], axis=0)
    floor = -np.min([slave[p] for p in (*trunk, *HIPS) if p in slave], axis=0)
    return np.minimum(0.0, np.maximum(want, floor))


def _plants(
    slave: dict[str, np.ndarray],
    master: dict[str, np.ndarray],
    heights: dict[str, np.ndarray],
    release: int,
    solved: tuple[dict[str, np.ndarray], np.ndarray] | None = None,
    follow: bool = False,
) -> dict[str, np.ndarray]:
    """Per site of :data:`PART_SITES`, where it goes (x, z; NaN where free) while the master's part is on
    the ground (``CONTACT_CM``): from where it was as the contact began (or at the release) it moves as
    the master's site of the same name moves (his root where he has none), so the slave's contacts slide
    no more than his. ``slave``/``master``: ``(n, 3)`` positions per site name. ``solved``: the positions
    the solve so far has and the frames the trunk settles in; a contact beginning there starts from the
    solve (from the unsolved slave, 3-5 cm off once the trunk went down, the solve jumped there as the part
    landed and the smoothing made the jump a slide: DI crawl2dead right hand 6.3 cm). ``follow``: an arm's
    sites are held so from the release to the end, the arm down or lifted."""
    out: dict[str, np.ndarray] = {}
    n = len(heights[next(iter(heights))])
    for part, names in PART_SITES.items():
        if part not in heights or part in TRUNK:  # the trunk follows the root: it rolls, it is not planted
            continue
        down = np.concatenate([[False], heights[part] <= CONTACT_CM, [False]])
        if follow and part.endswith(ARM_PARTS):
            down[1:-1] = np.arange(n) >= release
        edges = np.flatnonzero(np.diff(down.astype(np.int8)))
        for site in names:
            track = np.full((n, 3), np.nan)
            ref = master.get(site, master[ROOT])
            for a, b in zip(edges[::2], edges[1::2], strict=True):
                a = max(int(a), release)
                if a < b:
                    at = solved[0] if solved is not None and solved[1][a] else slave
                    track[a:b] = at[site][a] + ref[a:b] - ref[a]
            out[site] = track
    return out


def _positions(kin: FigureKinematics, pose: np.ndarray, loc: np.ndarray) -> dict[str, np.ndarray]:
    """Site name -> world positions ``(n, 3)`` of the sites of :data:`PART_SITES` (and the root) ``kin``
    has."""
    g = kin.site_globals(pose, loc)[..., :3, 3]
    wanted = {s for names in PART_SITES.values() for s in names} | {ROOT}
    return {s: g[:, kin.site_names.index(s)] for s in wanted if s in kin.site_names}


def part_goals(
    kin: FigureKinematics,
    pose: np.ndarray,
    loc: np.ndarray,
    need: dict[str, np.ndarray],
    rows: np.ndarray,
    planted: dict[str, np.ndarray],
    arm_out: bool = False,
    rigid: bool = False,
) -> list[ik.Goal]:
    """One goal per site of :data:`PART_SITES` of the parts in ``need``: where it is in ``pose`` (the frames
    ``rows`` of the clip), moved up or down by the largest need of the parts it carries (so a wrist lifts
    both forearm and hand out of the ground). ``arm_out``: an arm site going up also goes as far out
    sideways, away from the chest (:func:`_sideways`). ``rigid``: the torso sites' goals move the root alone,
    not the spine."""
    sites = kin.site_globals(pose, loc)
    moves: dict[str, np.ndarray] = {}
    for part, move in need.items():
        for site in PART_SITES[part]:
            moves[site] = move[rows] if site not in moves else np.maximum(moves[site], move[rows])
    goals = []
    for site, move in moves.items():
        at = sites[:, kin.site_names.index(site), :3, 3].copy()
        at[:, 1] += move
        hold = planted[site][rows] if site in planted else np.full((len(rows), 3), np.nan)
        keep = ~np.isnan(hold[:, 0])
        at[keep, 0], at[keep, 2] = hold[keep, 0], hold[keep, 2]
        if arm_out and site.split("_", 1)[-1].startswith(("upper_arm", "lower_arm")):
            at += _sideways(at, sites[:, kin.site_names.index(CHEST), :3, 3], move)
        chain = () if rigid and site.split(".")[0].endswith("_torso") else joint_chain(site)
        goals.append(ik.Goal(site, at, None, 1.0, 1, chain))
    return goals


def _sideways(at: np.ndarray, chest: np.ndarray, up: np.ndarray) -> np.ndarray:
    """How far ``(n, 3)`` to move arm sites ``at`` out of the ground sideways: horizontally away from the
    ``chest`` as far as they go ``up``. A DI forearm or upper arm lying in the ground under its chest (the
    crawler's, 2-7 cm) cannot come up by the arm alone, its shoulder is on the chest: out beside it, it
    lies on the ground, the chest lands on the ground and not on it."""
    out = at - chest
    out[:, 1] = 0.0
    out /= np.maximum(np.linalg.norm(out, axis=1), 1e-9)[:, None]
    return out * np.maximum(up, 0.0)[:, None]


RIFLE_MARGIN_CM = 0.3  # a dropped rifle is put this far clear of the body's hulls and the ground
RIFLE_PASSES = 12  # a push out of one hull can go into another: push again
RIFLE_SIGMA_FRAMES = 3.0  # the push is smoothed over the clip (at least as far as it has to go)
RIFLE_FADE_FRAMES = 6  # ... and fades in over this many frames from the release


def clear_rifle(slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Move the dropped rifle (every figure channel but the body's, from the release on) out of the slave's
    body and the ground: it lies where the master's rifle lies, but the DI's body is shaped differently
    and may lie where the master's did not. Each frame is pushed out of the segment hull it is deepest in
    through that hull's nearest face, and up out of the ground; the push is smoothed over the clip (rising
    ahead of the need) and fades in from the release. In place; returns the push per frame (cm)."""
    release = getattr(slave, "release_frame", None)
    f = play(slave, figures)
    stype = max(f.poses, key=lambda k: figures.kin[k].ndof)
    n = slave.nframes
    if release is None or release >= n - 1:
        return np.zeros(n)
    seg_globals = figures.kin[stype].segment_globals(f.poses[stype], f.locations[stype])
    hulls = figures.hulls(stype)
    total = np.zeros(n)
    after = np.arange(n) >= release
    fade = fade_in(n, release - 1, RIFLE_FADE_FRAMES)  # nothing while the hands hold it
    for chan in slave.figure_channels():
        if chan.protofiletype == stype:
            continue
        nodes, _ = figures.nodes(chan.protofiletype)
        locs = f.locations[chan.protofiletype]
        push = np.zeros((n, 3))
        for _ in range(RIFLE_PASSES):
            moved = locs.copy()
            moved[:, :3, 3] += push
            pts = np.einsum("fij,kj->fki", moved[:, :3, :], nodes)
            depth, out = hulls.exits(pts, seg_globals)
            out[:, 1] = np.maximum(out[:, 1], 0.0)  # never down, into the ground: round the body instead
            away = pts.mean(axis=1) - f.locations[stype][:, :3, 3]  # under a limb: out away from the body
            away[:, 1] = 0.0
            flat = np.linalg.norm(out, axis=1) < 0.3
            out[flat] = away[flat]
            out /= np.maximum(np.linalg.norm(out, axis=1), 1e-9)[:, None]
            step = out * np.where(depth > 0, depth + RIFLE_MARGIN_CM, 0.0)[:, None]
            step[:, 1] = np.maximum(step[:, 1], RIFLE_MARGIN_CM - pts[..., 1].min(axis=1))
            step[~after] = 0.0
            if not (np.abs(step) > 1e-3).any():
                break
            push = _smooth_push(push + step) * fade[:, None]
        slave.fig_pos[:, chan.column] += push.astype(slave.fig_pos.dtype)
        total = np.maximum(total, np.linalg.norm(push, axis=1))
    return total


def _smooth_push(push: np.ndarray) -> np.ndarray:
    """Each component of ``push`` ``(n, 3)`` smoothed over the clip, never shorter than where it points (a
    running maximum of its positive and of its negative part, then Gaussian). Unlike the held rifle's pitch
    (:func:`authoring.signal_shaping.smooth_above`) the ends are not pinned to the frame's own need: a dropped
    rifle's last frame belongs to no other clip, and pinned it moved at 1.5 m/s over the last frames."""
    half = int(np.ceil(3.0 * RIFLE_SIGMA_FRAMES))
    k = np.arange(-half, half + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (k / RIFLE_SIGMA_FRAMES) ** 2)
    kernel /= kernel.sum()

    def above(c: np.ndarray) -> np.ndarray:
        runmax = np.lib.stride_tricks.sliding_window_view(np.pad(c, half, mode="edge"), 2 * half + 1).max(-1)
        return np.maximum(c, np.convolve(np.pad(runmax, half, mode="edge"), kernel, mode="valid"))

    return np.stack([above(np.maximum(c, 0.0)) - above(np.maximum(-c, 0.0)) for c in push.T], axis=1)
