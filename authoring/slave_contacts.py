"""Kneeling, prone and crawling contacts carried over to the slave: where the master's kneecap or forearm
rests on the ground, so does the slave's.

Slaving copies the legs' joint angles, and DI.fig and soldier.fig share the leg skeleton, but DI.fig's
kneecap mesh sits about 1.4 cm higher on its knee site than soldier.fig's (and its toes 0.7 cm): a DI
soldier kneeling with the master's angles floats on his knee and toes. A kneeling thigh hangs straight down
from the hip, so the knee cannot go lower by the leg alone: in the frames where the master's kneecap (the
lower-leg mesh nodes near the ``knee`` site, as the quality check counts them) is on or near the ground, the
slave figure and its rifle are lowered by how far the slave's kneecap is above the master's (never taking the
rest of the body below the ground), and the legs are solved so that every foot stays where it was (a
kneeling leg's toes come down to where the master's are) and a kneeling knee goes down with the body. The
lowering fades in as the master's kneecap comes down (from ``REACH_CM`` to ``REST_CM`` above the ground),
so a knee going down or coming up does not jump. The build's ``lift_off_ground`` then raises any frame
where something else would sink.

Prone, the slave's forearms are laid on the ground (:func:`rest_slave_forearms`); crawling on forearms and
knees they are put at the master's height (a DI forearm that sank set the whole body on it, lifted off its
knees), planted elbows held in place, and where DI's arm cannot lift a forearm that far (the master holds
the rifle with his arm at its joint limits) the rifle rises with the hands. Lowering the body onto the
knees would then sink the forearms, so :func:`tilt_onto_knees` turns the slave about the ground below its
elbows instead.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from authoring import ik
from authoring.death_specs import spec_of
from authoring.postures import leg, segment_heights
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import hann_smooth, smooth_above, smoothstep
from authoring.slave_body import part_heights, played_body
from authoring.slave_rifle import held_rifle, rifle_slide, slide_rifle
from peabody import quaternion
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

REST_CM = 2.0  # the master's kneecap this close to the ground: the slave's goes as low (full weight)
REACH_CM = 6.0  # ... this far up: no goal
DROP_FADE_CM = 0.3  # the legs' solve fades in as the body's lowering grows to this
SIDES = ("left", "right")
LEG_SEGMENTS = ("upper_leg", "lower_leg", "foot", "toes")


def rest_slave_knees(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Lower the slave onto its kneeling knees where the master rests on them (``slave``'s figure and joint
    channels, in place); returns the lowering per frame (cm)."""
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    kin = figures.kin[stype]
    m_h = part_heights(mq, mloc, figures, mtype)
    s_h = part_heights(q, loc, figures, stype)
    m_foot = part_heights(mq, mloc, figures, mtype, "foot")
    s_foot = part_heights(q, loc, figures, stype, "foot")
    weight: dict[str, np.ndarray] = {}
    drop = np.zeros(len(q))
    for side in SIDES:
        if side not in m_h or side not in s_h:
            continue
        w = np.clip((REACH_CM - m_h[side]) / (REACH_CM - REST_CM), 0.0, 1.0)
        weight[side] = w * w * (3.0 - 2.0 * w)
        drop = np.maximum(drop, weight[side] * np.maximum(0.0, s_h[side] - np.maximum(m_h[side], 0.0)))
    # never lower the rest of the body into the ground (lying on the forearms, the knees are not what the
    # slave rests on); the legs are solved again, so they do not count
    rest = [h for seg, h in segment_heights(kin, q, loc).items() if not seg.endswith(LEG_SEGMENTS)]
    drop = np.minimum(drop, np.maximum(0.0, np.min(rest, axis=0)))
    if not drop.any():
        return drop
    lowered = loc.copy()
    lowered[:, 1, 3] -= drop
    sites = kin.site_globals(q, loc)
    goals: list[ik.Goal] = []
    for side in SIDES:  # every foot stays where it is; a kneeling knee goes down with the body
        heel = sites[:, kin.site_names.index(f"{side}_foot.heel")].copy()
        if side in weight:  # and a kneeling leg's toes, if they float above the master's, go down to them
            heel[:, 1, 3] -= weight[side] * np.maximum(0.0, s_foot[side] - np.maximum(m_foot[side], 0.0))
        goals.append(ik.Goal(f"{side}_foot.heel", heel[:, :3, 3], heel[:, :3, :3], 1.0, 2, leg(side)))
        if side in weight:
            knee = sites[:, kin.site_names.index(f"{side}_lower_leg.knee"), :3, 3].copy()
            knee[:, 1] -= drop
            goals.append(ik.Goal(f"{side}_lower_leg.knee", knee, None, weight[side], 1, leg(side)))
    # heavily damped small steps: a kneeling front thigh is near its hip's gimbal (flexion ~90 degrees), where
    # an undamped solve swaps abduction for twist and the hip's angles jump by tens of degrees between frames
    pose, _ = ik.solve(
        kin, q, goals, lowered, iterations=60, damping=6.0, rest_pose=q, rest_gain=0.05, tolerance=0.02,
        max_dof_step=0.02,
    )  # fmt: skip
    # frames not lowered keep their legs (so every clip through a posture where the body cannot go lower,
    # CRAWL on its forearms, has the same legs there), the solve faded in as the lowering grows
    pose = q + np.clip(drop / DROP_FADE_CM, 0.0, 1.0)[:, None] * (pose - q)
    bound = bind_channelset(slave, [figures.figures[stype]])
    bf = bound.figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    slave.fig_pos[:, :, 1] -= drop[:, None].astype(slave.fig_pos.dtype)  # the figure and its rifle
    return drop


ARM_CHAIN = ("clavicle", "shoulder", "elbow", "wrist")
SPINE = ("upper_spine",)  # DI's shoulders sit higher prone than soldier.fig's: the chest turns to lower them
HEAD = ("neck",)  # the head is at its limits prone: turning it there jumps between them
FOREARM_PASSES = 6  # the forearm's lowest node is near, not at, the elbow: solve again for what is left
AIM_BELOW_CM = 0.5  # the solve stops short of its goal: aim this much below the master's forearm ...
CONTACT_CM = 1.3  # ... but not into contact (the quality check's 1.25 cm) where the master's is not
RIFLE_PASSES = 3  # prone: the rifle settled, the arms solved after it, and again for what is left
FOREARM_REST_CM = 1.0  # a prone slave forearm higher than this brings the rifle down (see _forearm_aim)
RIFLE_ABOVE_GROUND_CM = 0.3  # ... but the rifle stays this far above the ground
EYE_BALL_CM = 2.0  # the eye stays this close to where the slaving put it (a ball: GOAL_RADIUS is 0.9)


def rest_slave_forearms(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Lay the slave's forearms on the ground where the master's lie there (prone).

    DI.fig's shoulders sit about 5 cm higher than soldier.fig's when prone, and with the palms on the rifle
    its elbow is already as low as the arm alone can take it, so its forearms float. The upper spine and
    both arms are solved together to bring each elbow down by how far the slave's forearm is above the
    master's (faded in as the master's forearm comes down) while the palms stay where they are on the rifle
    and the eye where it is (higher-priority goals over the spine, the arms and the neck; the
    gaze turns a little, the head and neck being at their limits prone). Planted elbows are held in one
    place (:func:`_planted_tracks`).

    On forearms and knees (crawling: the master's trunk off the ground, a knee on it) each forearm is put
    at the master's height instead, up or down, and where the arm cannot lift it there the rifle and the
    palms on it rise by what is missing (smoothed, at least that much), and the arms are solved again.
    ``slave``'s joint channels (and, crawling, its rifle's channel) change in place. Returns the worst
    remaining lift per frame (cm)."""
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    kin = figures.kin[stype]
    m_h = part_heights(mq, mloc, figures, mtype, "forearm")
    # lying on the belly (or chest), or on forearms and knees
    trunk = [h for p in ("belly", "chest") for h in part_heights(mq, mloc, figures, mtype, p, ("",)).values()]
    if not trunk:
        return np.zeros(len(q))
    prone = ground_fade(np.min(trunk, axis=0))
    # on forearms and knees (the crawl), the forearms carry the body: the slave's as high as the master's
    knees = part_heights(mq, mloc, figures, mtype)
    kneeling = ground_fade(np.min(list(knees.values()), axis=0)) if knees else np.zeros(len(q))
    # on his forearms alone, knees up (FOREARMS_FOLLOW): they carry him as crawling, the elbows planted
    follows = _follow_share(master)
    kneeling = follows + (1.0 - follows) * kneeling
    held_rifle = _holding(slave)
    spec = spec_of(master.name)  # the held rifle's slide out of the body, past the release where asked
    slid = _holding(slave, spec.slave_rifle_slid_past if spec else 0)
    crawling = {
        side: ground_fade(m_h[side]) * (1.0 - prone) * kneeling * held_rifle for side in SIDES if side in m_h
    }
    weight = {side: ground_fade(m_h[side]) * prone + crawling[side] for side in SIDES if side in m_h}
    if not weight or not any(w.any() for w in weight.values()):
        return np.zeros(len(q))
    # put at the master's height, up or down: crawling, and prone where a forearm comes down for good in a
    # clip that ends lying with the rifle in his hands (crawl2prstow; not a death, which lets go of it)
    settles = bool(prone[-1] > 0.5 and held_rifle[-1] > 0.5)
    follow = {
        side: crawling[side] + settles * _landing(m_h[side]) * ground_fade(m_h[side]) * prone
        for side in weight
    }
    # FOREARMS_FOLLOW: at the master's height, up or down, until it fades out
    follow = {side: follows * weight[side] + (1.0 - follows) * follow[side] for side in weight}
    sites = kin.site_globals(q, loc)
    elbows = {side: sites[:, kin.site_names.index(f"{side}_upper_arm.distal"), :3, 3] for side in weight}
    planted = {
        side: _planted_tracks(elbows[side], m_h[side] <= CONTACT_CM, crawling[side] > 0, settles)
        for side in weight
    }
    held = {s: sites[:, kin.site_names.index(s)] for s in [f"{side}_palm.palmcenter" for side in weight]}
    held["bottom_head.sight"] = sites[:, kin.site_names.index("bottom_head.sight")]

    def passes(pose: np.ndarray) -> tuple[np.ndarray, list[ik.Goal]]:
        for _ in range(FOREARM_PASSES):
            s_h = part_heights(pose, loc, figures, stype, "forearm")
            now = kin.site_globals(pose, loc)
            goals: list[ik.Goal] = []
            for site, at in held.items():  # the palms on the rifle, the eye where it was (the gaze kept by
                side = site.split("_", 1)[0]  # the pull towards the slaved pose: the head is at its limits)
                chain = SPINE + (HEAD if side == "bottom" else tuple(f"{side}_{j}" for j in ARM_CHAIN))
                gaze = None if side == "bottom" else at[:, :3, :3]
                ball = EYE_BALL_CM if side == "bottom" else 0.0
                goals.append(ik.Goal(site, at[:, :3, 3], gaze, 1.0, 2, chain, radius=ball))
            for side, w in weight.items():
                aim = m_h[side] - AIM_BELOW_CM
                aim = np.where(m_h[side] <= CONTACT_CM, aim, np.maximum(aim, CONTACT_CM))
                need = (w - follow[side]) * np.maximum(0.0, s_h[side] - np.maximum(aim, 0.0))
                need += follow[side] * (s_h[side] - np.maximum(m_h[side], 0.0))  # up or down
                elbow = now[:, kin.site_names.index(f"{side}_upper_arm.distal"), :3, 3].copy()
                elbow[:, 1] -= need
                track, down = planted[side]
                elbow[down, 0], elbow[down, 2] = track[down, 0], track[down, 2]  # planted: it does not slide
                chain = SPINE + tuple(f"{side}_{j}" for j in ARM_CHAIN)
                goals.append(ik.Goal(f"{side}_upper_arm.distal", elbow, None, w, 1, chain))  # or held there
            pose, _ = ik.solve(
                kin, pose, goals, loc, iterations=100, damping=2.0, rest_pose=pose, rest_gain=0.05,
                tolerance=0.02, max_dof_step=0.03,
            )  # fmt: skip
        return pose, goals

    pose, goals = passes(q)
    if any(w.any() for w in crawling.values()):
        # crawling, a DI forearm that its arm cannot lift to the master's height (his arm holds the rifle at
        # its joint limits) is lifted by the rifle: rifle and palms rise by what is missing, and again
        s_h = part_heights(pose, loc, figures, stype, "forearm")
        short = np.max([w * np.maximum(0.0, np.maximum(m_h[s], 0.0) - s_h[s]) for s, w in crawling.items()],
                       axis=0)  # fmt: skip
        lift = smooth_above(short, RIFLE_LIFT_SIGMA_FRAMES)
        for chan in slave.figure_channels():
            if chan.protofiletype != stype:
                slave.fig_pos[:, chan.column, 1] += lift.astype(slave.fig_pos.dtype)
        for site in held:
            if site.endswith("palmcenter"):
                held[site] = held[site].copy()
                held[site][:, 1, 3] += lift
        pose, goals = passes(pose)  # (every clip alike, so clips meeting at a posture agree there)
    for _ in range(RIFLE_PASSES):  # prone: the rifle out of the body, and down where a forearm cannot go
        s_h = part_heights(pose, loc, figures, stype, "forearm")
        high = np.max(
            [(weight[s] - crawling[s]) * (s_h[s] - _forearm_aim(m_h[s])) for s in weight],
            axis=0,
        )
        if not _settle_rifle(slave, figures, (pose, loc, stype), prone * slid, high, held):
            break
        pose, goals = passes(pose)  # the palms after the rifle, the forearms kept down
    # frames solved alone land a few degrees apart where the neck is at its limit: smooth the change over
    # the clip (its ends kept), then put the palms and the eye back exactly (a small, smooth correction)
    change = pose - q
    smooth = hann_smooth(change, SMOOTH_FRAMES)
    for end in (0, -1):  # the ends as solved (so clips meeting at a posture agree), the smoothing faded in
        pin_end(smooth, end, change[end], SMOOTH_FRAMES * 2)
    pose = q + smooth
    pose, _ = ik.solve(
        kin, pose, [g for g in goals if g.priority == 2], loc, iterations=60, damping=2.0, rest_pose=pose,
        rest_gain=0.05, tolerance=0.02, max_dof_step=0.03,
    )  # fmt: skip
    s_h = part_heights(pose, loc, figures, stype, "forearm")
    bound = bind_channelset(slave, [figures.figures[stype]])
    bf = bound.figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return np.max([w * np.maximum(0.0, s_h[s] - m_h[s]) for s, w in weight.items()], axis=0)


def _landing(master: np.ndarray) -> np.ndarray:
    """Per frame, 1 where the master's forearm (heights ``master``) is down for the rest of the clip after
    coming down in it (crawl2prstow), easing in over the ``LAND_FRAMES`` before. The slave's follows the
    master's height there, up or down: DI's forearm, only lowered, landed 4 frames before the master's while
    the arms still swung the elbow towards its place, and slid 6 cm on the ground."""
    down = master <= CONTACT_CM
    n = len(master)
    up = np.flatnonzero(~down)
    if not down[-1] or not len(up):
        return np.zeros(n)
    u = np.clip(1.0 - (up[-1] + 1 - np.arange(n)) / LAND_FRAMES, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


LAND_FRAMES = 12  # a forearm coming down for good follows the master's height from this many frames before


def _forearm_aim(master: np.ndarray) -> np.ndarray:
    """How high a prone slave forearm may stay before the rifle comes down for it: ``FOREARM_REST_CM``
    where the master's forearm rests (the check's 2 cm, ``REST_CM``), else as high as the master's."""
    return np.where(master <= REST_CM, FOREARM_REST_CM, master)


def _settle_rifle(
    slave: Channelset,
    figures: FigureSet,
    body: tuple[np.ndarray, np.ndarray, str],
    weight: np.ndarray,
    high: np.ndarray,
    held: dict[str, np.ndarray],
) -> bool:
    """Prone (``weight``), slide the held rifle out of the body (:mod:`authoring.slave_rifle`) and lower it
    by ``high`` (cm per frame: how far a forearm that the arm could not lay down is still up; smoothed, at
    least that much, never into the ground), the palm goals in ``held`` going with it (in place). Whether it
    moved: then the arms are to be solved again."""
    pose, loc, stype = body
    rifle = held_rifle(slave, figures, stype)
    if rifle is None or not weight.any():
        return False
    slide = rifle_slide(figures, stype, pose, loc, rifle[1:], weight)
    room = np.maximum(0.0, rifle[2][..., 1].min(axis=1) - RIFLE_ABOVE_GROUND_CM)
    slide[:, 1] -= np.minimum(smooth_above(weight * np.maximum(0.0, high), RIFLE_LIFT_SIGMA_FRAMES), room)
    if np.abs(slide).max() < 0.01:
        return False
    slide_rifle(slave, rifle[0], slide)
    for site in [s for s in held if s.endswith("palmcenter")]:
        held[site] = held[site].copy()
        held[site][:, :3, 3] += slide
    return True


def _planted_tracks(
    points: np.ndarray, down: np.ndarray, crawling: np.ndarray, settles: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, where a planted site should stay (``points`` ``(n, 3)``) and the frames that holds in.

    Prone, over each run of ``down`` frames its mean position. Crawling (``crawling``, per frame), one place
    per run too — where it is at the clip's first (last) frame for a run that starts (ends) the clip, so the
    posture there is kept — eased in and out over ``PLANT_FADE_FRAMES`` either side, so the goal does not jump
    as the contact starts or ends. With ``settles`` (the clip ends lying, rifle in hand), a prone elbow that
    comes down and stays down to the clip's end (crawl2prstow) is held like that too, where the clip ends,
    eased in over ``LAND_FRAMES``: held at the run's mean, its goal jumped there at touchdown and the end
    frame, solved onto it, slid the forearm 3.9 cm after landing."""
    n = len(points)
    track, eased, hold = points.copy(), points.copy(), np.zeros(n)
    frames = np.arange(n)
    landing = np.zeros(n, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], down.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        track[a:b] = points[a:b].mean(axis=0)
        place = points[0] if a == 0 else points[-1] if b == n else track[a]
        gap = np.maximum(a - frames, frames - (b - 1)).clip(0)
        lands = settles and a > 0 and b == n
        u = np.clip(1.0 - gap / (LAND_FRAMES if lands else PLANT_FADE_FRAMES), 0.0, 1.0)
        u = u * u * (3.0 - 2.0 * u)
        near = u > hold
        eased[near] = points[near] + u[near, None] * (place - points[near])
        hold[near] = u[near]
        if lands:
            landing |= u > 0
    eased_here = (crawling > 0) | landing
    return np.where(eased_here[:, None], eased, track), np.where(eased_here, hold > 0, down)


def _holding(slave: Channelset, past: int = 0) -> np.ndarray:
    """Per frame, 1 while the hands hold the rifle, easing to 0 over the ``HOLD_FADE_FRAMES`` before the
    clip's ``release_frame`` (a death lets go of it: the rifle is a free body from there), or ``past``
    frames later."""
    n = slave.nframes
    release = getattr(slave, "release_frame", None)
    if release is None:
        return np.ones(n)
    u = np.clip((release + past - np.arange(n)) / HOLD_FADE_FRAMES, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


# clips whose master's forearms carry him with the knees up (crawl2prstow lowering onto the belly): planted
# as crawling, and put at the master's height, up or down, wherever they are near the ground (pressed down
# to it, the slave's stayed there while the master's rose for the turn on the belly: dragged 15 cm round);
# faded out over the (start, end) s given, so the clip ends as the plain solve ends, in the pose its posture
# node's other clips start from (followed to the end, DI's shoulders ended 14 degrees off it)
FOREARMS_FOLLOW = {"crawl2prstow": (1.4, 1.6)}


def _follow_share(master: Channelset) -> np.ndarray:
    """Per frame, how far ``master``'s slave forearms follow his (:data:`FOREARMS_FOLLOW`; 0 elsewhere)."""
    t = np.arange(master.nframes) / master.fps
    fade = FOREARMS_FOLLOW.get(master.name.split(".")[0])
    return np.zeros(len(t)) if fade is None else 1.0 - smoothstep((t - fade[0]) / (fade[1] - fade[0]))


HOLD_FADE_FRAMES = 12  # the crawl's contact handling fades out over this many frames before a release
RIFLE_LIFT_SIGMA_FRAMES = 4.0  # the crawling rifle's lift is smoothed over the clip (at or above the need)
PLANT_FADE_FRAMES = 6  # a planted site's held place eases in and out over this many frames (0.1 s)


def ground_fade(height: np.ndarray) -> np.ndarray:
    """1 for a master's part resting on the ground (``REST_CM``), easing to 0 at ``REACH_CM`` up."""
    w = np.clip((REACH_CM - height) / (REACH_CM - REST_CM), 0.0, 1.0)
    return w * w * (3.0 - 2.0 * w)


SMOOTH_FRAMES = 6  # half-width of the window smoothing the forearm solve's change over a clip (0.1 s)


def pin_end(data: np.ndarray, frame: int, value: np.ndarray, frames: int) -> None:
    """Set ``data[frame]`` (0 or -1) to ``value`` and carry the change into the clip over ``frames`` frames,
    fading out smoothly (in place), so the end does not jump away from its neighbours."""
    n = min(frames, len(data) // 2)
    delta = value - data[frame]
    t = np.arange(n) / n
    fade = 1.0 - t * t * (3.0 - 2.0 * t)  # 1 at the end, easing to 0
    rows = np.arange(n) if frame == 0 else len(data) - 1 - np.arange(n)
    data[rows] += (fade[:, None] * delta[None, :]).astype(data.dtype)
    data[frame] = value


def tilt_onto_knees(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Put the slave's kneeling knees down where the master's rest on them while something in front of
    them carries the body too (on forearms and knees: the crawl), where :func:`rest_slave_knees` could not
    lower the body without sinking that part.

    DI.fig's kneecap sits about 1.1 cm higher above its elbows, forearms lying on the ground, than
    soldier.fig's. The slave figure and its rifle are tilted together (feet down, head up) about a level
    axis through the ground below the elbows, by the angle that brings the kneecaps down to the master's,
    or less where anything else (the toes) would reach the ground first; the forearms stay where they lie.
    ``slave``'s figure channels change in place. Returns the tilt per frame (rad)."""
    (mq, mloc, mtype), (q, loc, stype) = played_body(master, figures), played_body(slave, figures)
    kin = figures.kin[stype]
    m_h = part_heights(mq, mloc, figures, mtype)
    s_h = part_heights(q, loc, figures, stype)
    m_fore = part_heights(mq, mloc, figures, mtype, "forearm")
    sides = [s for s in SIDES if s in m_h and s in s_h]
    if not sides or not m_fore:
        return np.zeros(len(q))
    trunk = [h for p in ("belly", "chest") for h in part_heights(mq, mloc, figures, mtype, p, ("",)).values()]
    off_trunk = 1.0 - ground_fade(np.min(trunk, axis=0)) if trunk else np.ones(len(q))
    on_forearms = ground_fade(np.min(list(m_fore.values()), axis=0)) * off_trunk * _holding(slave)
    extra = np.max(
        [ground_fade(m_h[s]) * np.maximum(0.0, s_h[s] - np.maximum(m_h[s], 0.0)) for s in sides], axis=0
    )
    extra *= on_forearms
    if not (extra > TILT_MIN_CM).any():
        return np.zeros(len(q))
    sites = kin.site_globals(q, loc)[..., :3, 3]
    pivot = np.mean([sites[:, kin.site_names.index(f"{s}_upper_arm.distal")] for s in SIDES], axis=0)
    knee = np.mean([sites[:, kin.site_names.index(f"{s}_lower_leg.knee")] for s in sides], axis=0)
    pivot[:, 1] = 0.0
    back = knee - pivot
    back[:, 1] = 0.0
    reach = np.linalg.norm(back, axis=1)
    u = back / reach[:, None]
    nodes, segs = figures.nodes(stype)
    pts = np.einsum("fkij,kj->fki", kin.segment_globals(q, loc)[:, segs, :3, :], nodes)
    behind = np.einsum("fki,fi->fk", pts - pivot[:, None, :], u)  # how far behind the pivot each node lies
    room = np.where(behind > 1.0, np.maximum(pts[..., 1], 0.0) / np.maximum(behind, 1.0), np.inf).min(axis=1)
    angle = np.minimum(extra / reach, room)
    turn = Rotation.from_rotvec(np.cross(np.array([0.0, 1.0, 0.0]), u) * angle[:, None]).as_matrix()
    tilt = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    tilt[:, :3, :3] = turn
    tilt[:, :3, 3] = pivot - np.einsum("fij,fj->fi", turn, pivot)
    for chan in slave.figure_channels():
        moved = tilt @ slave.transforms(chan)
        slave.fig_pos[:, chan.column] = moved[:, :3, 3].astype(slave.fig_pos.dtype)
        slave.fig_quat[:, chan.column] = quaternion.from_matrix(moved[:, :3, :3]).astype(slave.fig_quat.dtype)
    return angle


TILT_MIN_CM = 0.05  # knees floating less than this above the master's are left as they are
