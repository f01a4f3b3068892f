"""Planted feet carried over to the slave: a DI foot on the ground stays where it touched down.

Slaving copies the leg angles and puts the slave's root where the master's is, so the slave's feet follow the
master's to about a centimetre, but not its contacts: DI.fig's hips sit a little elsewhere on its pelvis and
its foot mesh reaches lower with the foot pitched (crawl2prstow: the DI's toes on the ground through frames
33-53 while the master's skim 1.1-1.6 cm above it and drag 8 cm), and the death slaves' pelvis is moved
onto the ground where the master's lies (:mod:`~authoring.slave_ground`). Where the pelvis moves over a foot
on the ground, the foot slid along with it (8.5 cm).

So while the master's foot is on the ground (a node below the quality check's contact height), the slave's
is held there: the mean ground velocity of the slave's foot nodes in contact in both of two frames is
cancelled by moving the foot the other way (:func:`plant_offsets`), and the legs are solved to carry the foot
there, its orientation kept loosely (heel-toe rolling is kept: a node the foot rolls about does not move),
tracked frame after frame in small steps. A node that touches down stays there; between stances the offset
eases back to none, and it is none at a clip's first and last frames (every clip meeting at a posture node
agrees there). A leg whose knee or thigh is on the ground is left as slaved (holding its foot too slid the
knee), except in a death on the foot he falls onto and lies on to the end (:func:`_last_rest`): kstow2dead's
DI, its left knee down, slid that foot 3.0 cm under his at rest while its trunk was lowered onto the
ground (1.1 cm held, its knee 1.4 -> 0.6). Where the master's foot is near the
ground but not on it, the slave's is kept at least as high (:func:`lift_to_master`), so it does not touch
down where the master's does not. Stances whose offset stays under ``MIN_PLANT_CM`` are left alone (the
foot slides less than that), and so are locomotion clips (recorded in place: a planted foot there moves
with the ground, and their slaves' feet do not slide).

A death's slave (from a stand) has its feet turned after the release by
:func:`~authoring.slave_ground.rest_limbs`, which lays every part at the master's height: a foot rolling onto
its side under the falling body turned 11 degrees further than his and its toes bent, and the loosely held
orientation let the nodes straddling the turn slide 3 cm apart (ststow2dead, frames 47-59). So there the
foot and toes turn as the master's do while his foot is planted (their turn relative to his taken once, at
touchdown), and the foot's own nodes are then held by the offsets above. A slave that starts kneeling or
prone keeps the loose hold (its legs were posed otherwise than his by
:func:`~authoring.slave_contacts.rest_slave_knees`; turned as his, a kneeling hip jumped 25-30 degrees),
and where its knee or thigh is on the ground, its knee and ankle alone hold the foot from the slave's own
touchdown (:func:`_lying_leg`; the thigh, and so the knee on the ground, held as slaved): left as slaved
there, rest_limbs' leg stage swung a prone DI's toes 2-3 cm along the ground and back. The hold's change to
those knees and ankles is smoothed over the clip (:func:`_smoothed_lower_legs`): its targets step where the
foot touches down, and the tracking turned an ankle 11 degrees in one frame there (a flick).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import gaussian_filter1d

from authoring import ik
from authoring.death_specs import spec_of
from authoring.postures import leg
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smooth_above
from authoring.slave_body import played_body
from authoring.slave_contacts import SIDES
from authoring.transitions import track_solve
from peabody import quaternion
from peabody.fk import FigureKinematics
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset
from server.soldier.blend import smoothstep

MERGE_GAP_FRAMES = 3  # a foot off the ground this briefly is still in its stance (a flickering contact)
MIN_SHIFT_CM = 0.05  # a foot moved less than this is left as it is
LANDING_EASE_FRAMES = 6  # a foot held where it lands (_held_from_landing): its offset before eases out
MIN_PLANT_CM = 1.0  # a stance whose offset stays below this is left as slaved (it slides less than that)
NEAR_CM = 6.0  # the master's foot this near the ground: the slave's is kept at least as high
LIFT_SIGMA_FRAMES = 2.0  # the lift is smoothed over the clip (at or above the need)
KNEE_DOWN_CM = 3.0  # a knee or thigh this near the ground carries the leg: its foot is left as slaved ...
KNEE_FREE_CM = 10.0  # ... and planted from this height up (eased in between)
TRACK_ITERATIONS = 20  # per frame of the legs' tracking ...
TRACK_DOF_STEP = 0.01  # ... in steps of at most this (rad): a joint turns at most 11 degrees a frame
FOOT_TURN_CM = 5.0  # a radian of the foot's turn weighs as much as this much move (held loosely: a
# kneeling leg's ankle at its limits cannot keep the foot's exact orientation as the foot moves)
FOOT_HOLD_TURN_CM = 40.0  # a dying slave's planted foot turns as the master's: held firmly
TURN_RAMP_FRAMES = 10  # ... easing out over this many frames once his foot is off the ground
KNEE_SIGMA_FRAMES = 4.0  # ... and out as the knee comes down, smoothed over the clip (at least as far)
START_FRAMES = 6  # ... that turn fades in over a clip's first frames (its first is a shared posture node)
LYING_ROOT_CM = 45.0  # a dying slave whose pelvis starts lower lies (prone 14.5 cm, crawling 39; kneeling 53)
LYING_SITES = ("toe", "ball", "heel", "lateral", "medial")  # a lying leg's foot held by the one it rests on
LYING_SIGMA_FRAMES = 2.0  # a lying leg's knee and ankle change from the hold smoothed over the clip: its
# targets jump where the foot touches down and the tracker turned the ankle 11 degrees in one frame (a flick)
FOOT_PASSES = 2  # the contact nodes change a little as the foot moves: measure and solve again


def merged_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` of every run of True in ``mask``, runs closer than ``MERGE_GAP_FRAMES`` merged."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    runs: list[tuple[int, int]] = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if runs and a - runs[-1][1] <= MERGE_GAP_FRAMES:
            runs[-1] = (runs[-1][0], b - 1)
        else:
            runs.append((a, b - 1))
    return runs


def plant_offsets(
    points: np.ndarray,
    planted: np.ndarray | None = None,
    contact_cm: float = CONTACT_HEIGHT_CM,
    at_lift_off: bool = False,
    spread_end: bool = False,
) -> np.ndarray:
    """Per frame the ground offset ``(n, 3)`` (y = 0) that holds a foot's contacts where they touched down.

    ``points`` ``(n, k, 3)`` are one foot's nodes over a clip; ``planted`` ``(n,)`` the frames it may be held
    in (the master's foot on the ground; default: wherever a node is below ``contact_cm``). In a stance, the
    offset changes by minus the
    mean ground move of the nodes below ``contact_cm`` in both frames, starting from none at touchdown (or,
    for a stance that reaches the clip's last frame, ending at none there; a stance over the whole clip
    spreads what is left evenly; ``at_lift_off``: every stance after the first frame ends at none, so the
    part is held where it lifts off, where the rest of the fall put it; ``spread_end``: a stance reaching
    the clip's last frame starts from none too, what is left there spread evenly over it, so a foot that
    touches down in a clip's first frames is not pulled there at once). Between stances it eases
    (smoothstep) from one stance's last value to the next one's first; it is none at the first and last
    frames."""
    n = len(points)
    below = points[..., 1] <= contact_cm
    stance = np.asarray(below.any(axis=1) if planted is None else planted, dtype=bool)
    both = below[1:] & below[:-1] & stance[1:, None] & stance[:-1, None]
    step = np.where(both[..., None], points[1:] - points[:-1], 0.0).sum(axis=1)
    step /= np.maximum(both.sum(axis=1), 1)[:, None]
    step[:, 1] = 0.0
    move = np.zeros((n, 3))
    move[1:] = -step  # the offset's change into frame i
    out = np.zeros((n, 3))
    runs = merged_runs(stance)
    for a, b in runs:
        track = np.cumsum(move[a : b + 1], axis=0) - move[a]  # none at touchdown
        if b == n - 1 or (at_lift_off and a > 0):
            whole = a > 0 and not (spread_end and b == n - 1)
            track -= track[-1] * (1.0 if whole else np.linspace(0.0, 1.0, b - a + 1)[:, None])
        if np.linalg.norm(track, axis=1).max() >= MIN_PLANT_CM:
            out[a : b + 1] = track
    _ease_gaps(out, runs)
    out[[0, -1]] = 0.0
    return out


def _ease_gaps(values: np.ndarray, runs: list[tuple[int, int]]) -> None:
    """Between the ``runs`` (and before the first, after the last), ease ``values`` ``(n, ...)`` in place
    (smoothstep) from one run's last value to the next one's first (none beyond the clip's ends)."""
    n = len(values)
    gaps = [(-1, runs[0][0] if runs else n)] + [
        (b, runs[i + 1][0] if i + 1 < len(runs) else n) for i, (_, b) in enumerate(runs)
    ]
    for last, nxt in gaps:
        if nxt - last < 2:
            continue
        lo = values[last] if last >= 0 else np.zeros_like(values[0])
        hi = values[nxt] if nxt < n else np.zeros_like(values[0])
        u = (np.arange(last + 1, nxt) - last) / (nxt - last)
        values[last + 1 : nxt] = lo + (u * u * (3.0 - 2.0 * u)).reshape(-1, *[1] * (values.ndim - 1)) * (
            hi - lo
        )


def part_points(
    pose: np.ndarray, loc: np.ndarray, figures: FigureSet, ptype: str, parts: tuple[str, ...]
) -> np.ndarray:
    """The nodes of the body ``parts`` (as the quality check names them: ``left_foot`` is foot and toes)
    per frame ``(n, k, 3)``."""
    nodes, segs = figures.nodes(ptype)
    sel = np.isin(figures.node_parts(ptype), parts)
    g = figures.kin[ptype].segment_globals(pose, loc)
    return np.einsum("fkij,kj->fki", g[:, segs[sel], :3, :], nodes[sel])


def lift_to_master(slave_low: np.ndarray, master_low: np.ndarray) -> np.ndarray:
    """Per frame how far ``(n,)`` to raise a slave's foot whose lowest node is at ``slave_low`` so that it
    is not below the master's (``master_low``) while that is near the ground but not on it."""
    off = (master_low > CONTACT_HEIGHT_CM) & (master_low < NEAR_CM)
    need = np.where(off, np.maximum(0.0, np.minimum(master_low, NEAR_CM) - slave_low), 0.0)
    return smooth_above(need, LIFT_SIGMA_FRAMES) if need.any() else need


def _stance_weight(stance: np.ndarray) -> np.ndarray:
    """Per frame how much of the master's foot turn a dying slave's foot takes: all of it in his stances,
    easing out over ``TURN_RAMP_FRAMES`` off the ground, none at the clip's first frame (a posture node every
    clip there agrees on)."""
    n = len(stance)
    down = np.flatnonzero(stance)
    if not len(down):
        return np.zeros(n)
    gap = np.abs(np.arange(n)[:, None] - down[None, :]).min(axis=1)
    w = np.clip(1.0 - gap / TURN_RAMP_FRAMES, 0.0, 1.0)
    u = np.clip(np.arange(n) / START_FRAMES, 0.0, 1.0)
    return np.minimum(w * w * (3.0 - 2.0 * w), u * u * (3.0 - 2.0 * u))


def _last_rest(stance: np.ndarray) -> np.ndarray:
    """Per frame 1 over the master's last stance if it lasts to the clip's end and starts after its first
    frame (the foot he dies lying on), easing in (smoothstep) from the end of the stance before it."""
    n = len(stance)
    runs = merged_runs(stance)
    out = np.zeros(n)
    if not runs or runs[-1][1] != n - 1 or runs[-1][0] == 0:
        return out
    a = runs[-1][0]
    lo = runs[-2][1] if len(runs) > 1 else 0
    out[a:] = 1.0
    out[lo + 1 : a] = smoothstep((np.arange(lo + 1, a) - lo) / max(a - lo, 1))
    return out


def _anchored(master: np.ndarray, slave: np.ndarray, stance: np.ndarray) -> np.ndarray:
    """Per frame the orientation ``(n, 3, 3)`` a slave segment should have to turn as the master's does
    (``master``, ``slave``: ``(n, 4, 4)`` globals): its turn relative to his is taken once, at the
    touchdown of each stance (the nearest stance's off the ground), and kept through the stance, so a foot
    that the slaving put a little otherwise than his is not turned to his at once. (Nearest by the stance's
    middle, a long stance's first frames took a short one's turn before it: stfire2dead's DI toes jumped 32
    degrees in a frame.)"""
    m, sl = master[:, :3, :3], slave[:, :3, :3]
    runs = merged_runs(stance)
    if not runs:
        return sl.copy()
    starts = np.array([a for a, _ in runs])
    ends = np.array([b for _, b in runs])
    i = np.arange(len(m))[:, None]  # a frame takes its own stance's turn, off the ground the nearest one's
    near = np.maximum(np.maximum(starts[None, :] - i, i - ends[None, :]), 0).argmin(axis=1)
    rel = m[starts].transpose(0, 2, 1) @ sl[starts]
    return m @ rel[near]


def _turns(foot: np.ndarray, target: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per frame the world turn ``(n, 3, 3)`` that brings the slave's segment ``foot`` ``(n, 4, 4)`` ``w``
    of the way to the orientation ``target`` ``(n, 3, 3)``."""
    full = quaternion.from_matrix(target @ foot[:, :3, :3].transpose(0, 2, 1))
    ident = np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), full.shape)
    return quaternion.to_matrix(quaternion.slerp(ident, full, w))


def _ground_to_master(
    low: np.ndarray, master_low: np.ndarray, stance: np.ndarray, w: np.ndarray
) -> np.ndarray:
    """Per frame how far ``(n,)`` to raise a dying slave's foot so that its lowest node is not below the
    master's while his is on the ground (eased between stances) or near it (:func:`lift_to_master`). Never
    lowered: pushing a DI foot that floats 2.6 cm down to his height jumped the hip 30 degrees in a frame
    (kstow2dead)."""
    dy = np.where(stance, np.maximum(np.maximum(master_low, 0.0) - low, 0.0), 0.0)
    _ease_gaps(dy, merged_runs(stance))
    return np.where(stance, dy, np.maximum(dy, lift_to_master(low, master_low))) * w


def _leg_goal(
    pose: np.ndarray,
    loc: np.ndarray,
    figures: FigureSet,
    ptype: str,
    master_foot: np.ndarray,
    side: str,
    master_turn: tuple[np.ndarray, np.ndarray] | None = None,
    death: str = "",
) -> tuple[list[ik.Goal], np.ndarray]:
    """One leg's goals (the foot moved by its planting offset and lift, its orientation kept) and the move
    per frame. A knee or thigh on the ground carries the leg too: the move fades out as it comes down
    (holding the foot where the hip moves over a knee on the ground slid the knee 4-6 cm instead).

    With ``master_turn`` (a death: the master's foot and toes segment globals, each ``(n, 4, 4)``) the
    foot and toes are also turned as the master's while his foot is planted, raised where it sinks below:
    :func:`~authoring.slave_ground.rest_limbs` had turned a DI foot rolling onto its side 11 degrees further
    than his and bent its toes, and kept loosely that turn slid it 3 cm (ststow2dead). Its own nodes then
    roll without slipping (:func:`plant_offsets`). ``death``: ``"dying"``, a death, whose foot he lies on
    is held even with the knee down (:func:`_last_rest`); ``"landed"``, also held where the slave's own foot
    lands in his last stance (:func:`_held_from_landing`)."""
    kin = figures.kin[ptype]
    sites = kin.site_globals(pose, loc)
    foot_pts = part_points(pose, loc, figures, ptype, (f"{side}_foot",))
    master_low = master_foot[..., 1].min(axis=1)
    stance = master_low <= CONTACT_HEIGHT_CM
    u = _knee_free(pose, loc, figures, ptype, side)
    heel = sites[:, kin.site_names.index(f"{side}_foot.heel")]
    at, turn = heel[:, :3, 3], heel[:, :3, :3]
    extra: list[ik.Goal] = []
    if master_turn is None:
        move = plant_offsets(foot_pts, stance)
        move[:, 1] = lift_to_master(foot_pts[..., 1].min(axis=1), master_low)
        if death != "kneeling":  # (a death whose slaves hold every stance: DeathSpec.slave_feet_knelt)
            move *= (np.maximum(u, _last_rest(stance)) if death else u)[:, None]
    else:
        # a knee coming down fast let the toes go in 3 frames (40 degrees in one): eased over more
        u = 1.0 - smooth_above(1.0 - u, KNEE_SIGMA_FRAMES)
        w = _stance_weight(stance) * u
        segs = kin.segment_globals(pose, loc)
        foot, toes = (segs[:, kin.segment_names.index(f"{side}_{seg}")] for seg in ("foot", "toes"))
        rot = _turns(foot, _anchored(master_turn[0], foot, stance), w)
        origin = foot[:, :3, 3]
        foot_pts = np.einsum("fij,fkj->fki", rot, foot_pts - origin[:, None]) + origin[:, None]
        at = np.einsum("fij,fj->fi", rot, at - origin) + origin
        turn = rot @ turn
        dy = _ground_to_master(foot_pts[..., 1].min(axis=1), master_low, stance, w)
        foot_pts[..., 1] += dy[:, None]
        move = plant_offsets(foot_pts, stance) * u[:, None]
        if death == "landed":
            move = _held_from_landing(foot_pts, stance, move)
        move[:, 1] = dy
        toes_turn = _turns(toes, _anchored(master_turn[1], toes, stance), w) @ toes[:, :3, :3]
        extra.append(
            ik.Goal(f"{side}_toes.distal", None, toes_turn, 1.0, 2, (f"{side}_toes",), FOOT_HOLD_TURN_CM)
        )
    target = at + move
    goal = ik.Goal(
        f"{side}_foot.heel",
        target,
        turn,
        1.0,
        2,
        leg(side),
        FOOT_TURN_CM if master_turn is None else FOOT_HOLD_TURN_CM,
    )
    return [goal, *extra], np.linalg.norm(target - heel[:, :3, 3], axis=1)


def _held_from_landing(foot_pts: np.ndarray, stance: np.ndarray, move: np.ndarray) -> np.ndarray:
    """The planting offset ``move`` ``(n, 3)`` of a foot (nodes ``foot_pts`` ``(n, k, 3)``) changed so that
    in the master's last stance (:func:`_last_rest`) it stays where the slave's own foot lands
    (:func:`_from_touchdown`): its nodes on the ground do not move from there on, to the clip's end; the
    offset before eases out over ``LANDING_EASE_FRAMES`` up to the landing. Held from his touchdown and
    brought back to where it lies at the end (:func:`plant_offsets`), the foot's knee on the ground let it
    go: a DI foot laid by its root alone skated 3.1 cm after landing (ststow2dead); held there instead at
    once, it landed on the dropped rifle (2 cm in). Unchanged where the slave's foot never lands."""
    below = foot_pts[..., 1] <= CONTACT_HEIGHT_CM
    down = np.asarray(below.any(axis=1))
    landed = np.flatnonzero(_from_touchdown(stance, down) & (_last_rest(stance) >= 1.0))
    if not len(landed):
        return move
    first = int(landed[0])
    out = move * smoothstep(np.clip((first - np.arange(len(move))) / LANDING_EASE_FRAMES, 0.0, 1.0))[:, None]
    both = below[1:] & below[:-1]
    step = np.where(both[..., None], foot_pts[1:] - foot_pts[:-1], 0.0).sum(axis=1)
    step /= np.maximum(both.sum(axis=1), 1)[:, None]
    out[first + 1 :] = -np.cumsum(step[first:], axis=0)
    out[first, :] = 0.0
    out[:, 1] = 0.0
    return out


def _lying_leg(
    pose: np.ndarray,
    loc: np.ndarray,
    figures: FigureSet,
    ptype: str,
    master_foot: np.ndarray,
    side: str,
    leg_goal: ik.Goal,
    thigh: np.ndarray,
) -> tuple[list[ik.Goal], np.ndarray]:
    """A dying slave's lying leg (prone, crawling or kneeling at the start): where its knee or thigh is on
    the ground, the leg's own hold (``leg_goal``, :func:`_leg_goal`) is off and the knee and ankle alone hold
    the foot (:func:`_lower_leg_goals`), from the slave's own touchdown in each of the master's stances
    (:func:`_from_touchdown`), lifted as there and out of the ground. Left as slaved there,
    :func:`~authoring.slave_ground.rest_limbs`' leg stage swung a prone DI's toes 2.2 cm along the ground and
    back (prfire2dead, frames 19-42) where his stayed. Returns the goals and the move per frame."""
    kin = figures.kin[ptype]
    foot_pts = part_points(pose, loc, figures, ptype, (f"{side}_foot",))
    low = foot_pts[..., 1].min(axis=1)
    master_low = master_foot[..., 1].min(axis=1)
    down = _from_touchdown(master_low <= CONTACT_HEIGHT_CM, low <= CONTACT_HEIGHT_CM)
    move = plant_offsets(foot_pts, down, spread_end=True)
    move[:, 1] = np.maximum(lift_to_master(low, master_low), -low)  # (turned about the ankle: not into it)
    lying = 1.0 - _knee_free(pose, loc, figures, ptype, side)
    sites = kin.site_globals(pose, loc)
    held = _lower_leg_goals(kin, sites, side, foot_pts, down, move, lying)
    # off the ground the foot keeps its turn too (held by its sites' places alone, a DI foot in the air
    # before touchdown swung its ankle 14 degrees a frame): fading out about the stances
    first = np.flatnonzero(down)
    aloft = lying * (1.0 - _stance_weight(down)) * (np.arange(len(down)) < (first[0] if len(first) else 0))
    heel = sites[:, kin.site_names.index(f"{side}_foot.heel")]
    held.append(
        ik.Goal(
            f"{side}_foot.heel",
            None,
            heel[:, :3, :3],
            aloft,
            2,
            (f"{side}_knee", f"{side}_ankle"),
            FOOT_HOLD_TURN_CM,
        )
    )
    # the thigh stays as slaved (``thigh``: its distal site's globals before the hold): with no goal on the
    # hip where the knee is down, the tracking carried a hip turn made where it lifted on through the
    # crawl (M16 crawl2dead: 2-3 degrees, the thigh touched down as the body dragged, 5.1 cm)
    site = f"{side}_upper_leg.distal"
    held.append(
        ik.Goal(site, thigh[:, :3, 3], thigh[:, :3, :3], lying, 2, (f"{side}_hip",), FOOT_HOLD_TURN_CM)
    )
    return [replace(leg_goal, weight=1.0 - lying), *held], np.linalg.norm(move, axis=1) * lying


def _from_touchdown(stance: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Per frame whether a slave's foot is held: in each of the master's stances, from the first frame the
    slave's own foot is ``down`` on. (Held only where it is down, a foot flickering about the contact
    height started a new stance at each touch, each from none: crawl2dead's DI foot slid back 3 cm.)"""
    out = np.zeros_like(stance)
    for a, b in merged_runs(stance):
        touch = np.flatnonzero(down[a : b + 1])
        if len(touch):
            out[a + touch[0] : b + 1] = True
    return out


def _at(kin: FigureKinematics, sites: np.ndarray, site: str) -> np.ndarray:
    return sites[:, kin.site_names.index(site), :3, 3]


def _lower_leg_goals(
    kin: FigureKinematics,
    sites: np.ndarray,
    side: str,
    foot_pts: np.ndarray,
    down: np.ndarray,
    move: np.ndarray,
    weight: np.ndarray,
) -> list[ik.Goal]:
    """A lying leg's foot held by its knee and ankle alone (``weight`` per frame: where the knee or thigh
    is on the ground): the foot sites nearest the nodes it rests on (``foot_pts`` below the contact height
    in the ``down`` frames; a prone foot turned out rests on its edge, one dug in on its toe), each weighted
    by its share of them, moved by the planting offset ``move`` ``(n, 3)``; the knee stays put."""
    names = [f"{side}_foot.{s}" for s in LYING_SITES]
    at = np.stack([_at(kin, sites, name) for name in names], axis=1)  # (n, s, 3)
    on = (foot_pts[..., 1] <= CONTACT_HEIGHT_CM) & down[:, None]
    nearest = np.linalg.norm(foot_pts[:, :, None, :] - at[:, None, :, :], axis=-1).argmin(axis=2)  # (n, k)
    share = (on[..., None] & (nearest[..., None] == np.arange(len(names)))).sum(axis=1).astype(np.float64)
    rows = np.flatnonzero(on.any(axis=1))
    if not len(rows):
        share[:, 0] = 1.0
    else:  # a frame without a node down takes the nearest frame's (the hold eases there anyway)
        near = rows[np.abs(np.arange(len(share))[:, None] - rows[None, :]).argmin(axis=1)]
        share = share[near] / share[near].sum(axis=1, keepdims=True)
    joints = (f"{side}_knee", f"{side}_ankle")
    return [
        ik.Goal(name, at[:, k] + move, None, weight * share[:, k], 2, joints)
        for k, name in enumerate(names)
        if share[:, k].max() > 0.0
    ]


def _knee_free(pose: np.ndarray, loc: np.ndarray, figures: FigureSet, ptype: str, side: str) -> np.ndarray:
    """Per frame 0 where the leg's knee or thigh is on the ground (it carries the leg), easing to 1 where
    it is ``KNEE_FREE_CM`` up."""
    leg_pts = part_points(
        pose, loc, figures, ptype, tuple(f"{side}_{p}" for p in ("knee", "kneecap", "thigh"))
    )
    if not leg_pts.shape[1]:
        return np.ones(len(pose))
    u = np.clip((leg_pts[..., 1].min(axis=1) - KNEE_DOWN_CM) / (KNEE_FREE_CM - KNEE_DOWN_CM), 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _smoothed_lower_legs(kin: FigureKinematics, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """``after`` with each knee's and ankle's change from ``before`` (poses ``(n, ndof)``) smoothed over the
    clip (Gaussian, ``LYING_SIGMA_FRAMES``), none at its first frame (a posture node every clip there
    agrees on): a step of the hold's targets becomes a turn over a few frames, not a one-frame flick."""
    out = after.copy()
    for side in SIDES:
        for joint in (f"{side}_knee", f"{side}_ankle"):
            sl = kin.dof_slices[joint]
            change = gaussian_filter1d(
                after[:, sl] - before[:, sl], LYING_SIGMA_FRAMES, axis=0, mode="nearest"
            )
            change *= smoothstep(np.clip(np.arange(len(out)) / START_FRAMES, 0.0, 1.0))[:, None]
            out[:, sl] = before[:, sl] + change
    return out


def plant_slave_feet(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Hold the slave's feet planted where the master's are on the ground, and off it where his are not
    (``slave``'s joint channels, in place); returns the largest move of a foot in each frame (cm)."""
    q, loc, stype = played_body(slave, figures)
    if getattr(slave, "ground_speed", None) is not None:  # locomotion: recorded in place
        return np.zeros(len(q))
    mq, mloc, mtype = played_body(master, figures)
    master_feet = {side: part_points(mq, mloc, figures, mtype, (f"{side}_foot",)) for side in SIDES}
    turns: dict[str, tuple[np.ndarray, np.ndarray] | None] = dict.fromkeys(SIDES)
    knelt = any(_knee_free(q[:1], loc[:1], figures, stype, side)[0] < 1.0 for side in SIDES)
    # a death from a stand or a kneel; lying at the start (prone, crawl) the held foot pushed the DI's prone
    # start to 1.13 m/s and the rifle 1.9 cm into its upper arm
    dying = getattr(slave, "release_frame", None) is not None and float(loc[0, 1, 3]) >= LYING_ROOT_CM
    if getattr(slave, "release_frame", None) is not None and not knelt:
        # a death from a stand: rest_limbs turned the feet on the ground. Kneeling or prone at the start, the
        # slave's legs are posed otherwise than his (rest_slave_knees): turned as his, a kneeling DI's hip
        # jumped 25-30 degrees in a frame (kstow2dead), so those keep the loose hold
        mkin = figures.kin[mtype]
        mseg = mkin.segment_globals(mq, mloc)

        def seg(name: str) -> np.ndarray:
            return mseg[:, mkin.segment_names.index(name)]

        turns = {side: (seg(f"{side}_foot"), seg(f"{side}_toes")) for side in SIDES}
    lying = getattr(slave, "release_frame", None) is not None and knelt and loc[0, 1, 3] < LYING_ROOT_CM
    spec = spec_of(master.name)
    landed = turns["left"] is not None and spec is not None and spec.slave_feet_landed
    death = ("landed" if landed else "dying") if dying else ""
    if dying and spec is not None and spec.slave_feet_knelt:
        death = "kneeling"
    kin = figures.kin[stype]
    thighs = kin.site_globals(q, loc)  # the thighs as slaved (a lying leg keeps its thigh)
    pose = q
    total = np.zeros(len(q))
    for _ in range(FOOT_PASSES):
        goals: list[ik.Goal] = []
        worst = np.zeros(len(q))
        for side in SIDES:
            leg_goals, moved = _leg_goal(
                pose, loc, figures, stype, master_feet[side], side, turns[side], death
            )
            if lying:
                thigh = thighs[:, kin.site_names.index(f"{side}_upper_leg.distal")]
                leg_goals[:1], held = _lying_leg(
                    pose, loc, figures, stype, master_feet[side], side, leg_goals[0], thigh
                )
                moved = np.maximum(moved, held)
            goals += leg_goals
            worst = np.maximum(worst, moved)
        if not (worst > MIN_SHIFT_CM).any():
            break
        total = np.maximum(total, worst)
        # tracked frame after frame in small steps: solved frame by frame alone, a kneeling leg's hip and
        # ankle swapped between their limits as the foot moved 2 cm (kstow2dead: 50 degrees in one frame)
        pose = track_solve(kin, pose, goals, loc, iterations=TRACK_ITERATIONS, max_dof_step=TRACK_DOF_STEP)
    if lying and total.any():
        pose = _smoothed_lower_legs(kin, q, pose)
    if total.any():
        bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
        slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return total
