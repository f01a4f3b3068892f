"""A prone death's chest comes down: the spine bends, the arms are laid anew, the head rests (issue 14).

The ragdoll of a prone death comes to rest propped on its elbows like a live prone soldier: the chest
inclined, the shoulders up, the head 18-19 cm up even with the neck at its limit (dropping the head alone,
:func:`authoring.dead_settle.dropped_head`). Lowering the spine alone drove the elbows 11-19 cm into the
ground. So a prone death's settle (:func:`lowered`) is solved in three steps:

1. **the torso and head come down** (:func:`lowered_torso`): the spine's forward bend, by groups of
   vertebrae (:data:`SPINE_GROUPS`), and the neck's and head's angles that lay the head lowest and the
   chest flattest, the arms left out (they are laid next), into neither the ground, the trunk nor the
   rifle where it lies, sliding nothing on the ground (crawl2dead's rifle lies by the face: the head is
   turned apart from the spine, from several starts, :data:`NECK_GRID`);
2. **the arms are laid against the lowered torso** (:func:`laid_arm`): each arm's clavicle, shoulder, elbow
   and wrist angles that lay it lowest (its highest part's lowest node, as the check measures, plus a
   little of its nodes' mean height), into neither the ground, the body nor the rifle: the elbows slide out
   and the forearms lie on the ground;
3. **the arms are lifted clear while they move** (:func:`lifted_arm`): shapes straight above where each
   arm lay and will lie, just clear (:data:`CLEAR_CM`, :data:`LIFT_OFF`) and well clear (:data:`LIFT_CM`,
   :data:`AIR_SPAN`), shapes between them (:data:`AIR_KEYS`) and more where the spline between dips
   (:data:`MORE_KEYS`), each into neither the body nor the rifle with the torso where it is then, so an
   elbow never skids over the ground (the check judges contact by height alone: pulled sideways out of a
   propped pose the elbows slid 5-8 cm); the torso comes down while the arms are in the air
   (:data:`TORSO_SPAN`), the arms pass their shapes on a smooth spline (:func:`arm_path`), and a head that
   would pass through the rifle on its way gets shapes clear of it too. Nearest the blend of its shapes,
   an arm's part may rise in mid-air after the chest is down: a death that asks (``low_air``,
   ``DeathSpec.arms_air_low``) holds each shape off the ground as low as its clearance lets
   (:data:`LOW_AIR_WEIGHT`).

The searches are batched pattern searches (:func:`search`): one forward-kinematics call evaluates every
trial step of every start at once, so a settle takes seconds, not minutes; deterministic.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from authoring import dead_settle as ds
from authoring.body_parts import SegmentHulls

SPINE_GROUPS = (
    ("waist",),
    ("vl5", "vl4", "vl3", "vl2", "vl1"),
    ("vt12", "vt11", "vt10", "vt9", "vt8", "vt7"),
    ("vt6", "vt5", "vt4", "vt3", "vt2", "vt1"),
)
FLEX = 1  # a spine joint's second angle bends it forward (face down: the chest comes down)
HAND_EVERY = 3  # of the hand's nodes, every so many are tested against the body (the searches' cost)
REACH_MARGIN_CM = 10.0  # an arm's search tests the body and the rifle this much beyond its reach
MAX_FLEX_DEG = 12.0  # per joint of a group: the most the spine bends forward from where it lies
NECK_DOFS = ("neck", "head")
TWIST = 2  # the neck's third angle turns the head to the side
# degrees: the neck's three angles tried for the head (a grid: its best shapes are starts besides the head's
# own; with a rifle by the face the head had no way out of it one angle at a time)
NECK_GRID = ((-30.0, 0.0, 30.0), (-40.0, 0.0, 40.0), (-70.0, -35.0, 0.0, 35.0, 70.0))
NECK_STARTS = 2
CHEST_WEIGHT = 0.3  # of the chest nodes' mean height (besides the head's lowest node): lie flat
LIFT_CM = 4.0  # an arm node's least height in the air (contact is 1.25 cm)
LIFT_OFF = 0.12  # of the settle: the arm just clear (CLEAR_CM) straight above where it lay (and will lie)
CLEAR_CM = 3.0  # just clear of the ground (contact is 1.25 cm): leaving it and landing, nothing skids
AIR_SPAN = (0.2, 0.8)  # of the settle: the arm well clear (LIFT_CM) above where it lay and will lie
AIR_KEYS = 7  # shapes over AIR_SPAN (both ends too)
RIFLE_SLACK_CM = 0.5  # the head may touch the rifle where it lies this deep on its way down
MORE_KEYS = 6  # at most so many more where the path between them dips
# (DeathSpec.arms_lifted_level) an arm shape lifted straight above its nodes counts the square of their
# height over that lift this much of a miss sideways: only a miss sideways counted, prfire2dead's right arm,
# its elbow held 4 cm up, swung its hand up to 16.9 cm, fingers up by his face, as his head lay down
# (rest_rise 4.39); weighed 1, the arm lay 0.8 cm in the falling rifle and the rifle_settle flung it 2 m up
LEVEL_WEIGHT = 0.2
TORSO_SPAN = (0.2, 0.8)  # of the settle: the torso comes down while the arms are in the air
# per cm: (``low_air``) an arm in the air is held this low too, each part's lowest node as the check's
# rest_rise sees it: nearest the blend of its shapes, crawl2dead's left hand rose 5.0 -> 9.4 cm in mid-air
# after his head was down (0.5: 1.06 cm; each measured held low from the ground on: 0.1, 2.94; 0.3, his hand
# rose 5.2 cm as it landed; 1.0 and 2.0, his elbow swung 13 degrees a frame)
LOW_AIR_WEIGHT = 0.5
ARM_SIDES = ("left", "right")
STEP_DEG = 16.0  # the pattern search's first step
TOL_DEG = 0.25  # and its last
Cost = Callable[[np.ndarray], np.ndarray]


def search(cost: Cost, starts: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The lowest point a compass search finds from each of ``starts`` ``(m, d)`` within the bounds, the
    best of them (the first on ties). ``cost`` maps ``(n, d)`` to ``(n,)``: each round evaluates a step up
    and down every coordinate of every start in one call; a start whose steps all fail halves its step."""
    x = np.clip(starts, lo, hi)
    f = cost(x)
    m, d = x.shape
    step = np.full(m, np.radians(STEP_DEG))
    moves = np.concatenate([np.eye(d), -np.eye(d)])
    while (step > np.radians(TOL_DEG)).any():
        trial = np.clip(x[:, None, :] + step[:, None, None] * moves[None], lo, hi)
        ft = cost(trial.reshape(-1, d)).reshape(m, 2 * d)
        best = np.argmin(ft, axis=1)
        better = ft[np.arange(m), best] < f - 1e-9
        x[better] = trial[better, best[better]]
        f[better] = ft[better, best[better]]
        step[~better] *= 0.5
    return x[int(np.argmin(f))]


class _Batch:
    """The body of a face-down dead soldier, evaluated for many poses at once."""

    def __init__(self, body: ds._Body) -> None:
        self.body, self.kin = body, body.kin
        self.parts = body.parts

    def points(self, q: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment globals ``(n, nseg, 4, 4)`` and the nodes of ``mask`` ``(n, k, 3)`` in poses ``q``."""
        g = self.kin.segment_globals(q, self.body.root)
        b = self.body
        return g, np.einsum("nkij,kj->nki", g[:, b.segs[mask], :3, :], b.nodes[mask])

    def hulls(self, mask: np.ndarray) -> SegmentHulls:
        b = self.body
        return SegmentHulls.build(b.nodes, b.segs, np.unique(b.segs[mask]))


def _spine_poses(q0: np.ndarray, kin, x: np.ndarray) -> np.ndarray:
    """Poses ``(n, ndof)``: ``q0`` with each :data:`SPINE_GROUPS` group's joints bent forward by ``x[:, g]``
    (rad, each, clipped to the joints' limits) and the neck and head at ``x[:, len(SPINE_GROUPS):]``."""
    q = np.repeat(q0[None], len(x), axis=0)
    for g, group in enumerate(SPINE_GROUPS):
        i = np.array([kin.dof_slices[j].start + FLEX for j in group])
        q[:, i] = np.clip(q0[i] + x[:, g : g + 1], kin.lower[i], kin.upper[i])
    q[:, ds._dofs(kin, NECK_DOFS)] = x[:, len(SPINE_GROUPS) :]
    return q


def lowered_torso(body: ds._Body) -> np.ndarray:
    """The pose with the spine bent and the neck and head turned so that the head lies lowest and the chest
    flattest, into neither the ground, the trunk nor the rifle where it lies, sliding nothing on the ground
    (the arms as they were: they are laid next). The spine is bent with and without the rifle kept out of
    the head, the head then turned alone (out of the rifle), and the better taken: the compass search moves
    one angle at a time, and with a rifle by the face the spine could not bend without the neck lifting
    the head at once, nor the head leave the rifle with the spine bent over it."""
    torso = _Torso(body)
    kin, n = body.kin, len(SPINE_GROUPS)
    neck = ds._dofs(kin, NECK_DOFS)
    x0 = np.r_[np.zeros(n), body.q[neck]]
    lo = np.r_[np.zeros(n), kin.lower[neck]]
    hi = np.r_[np.full(n, np.radians(MAX_FLEX_DEG)), kin.upper[neck]]

    bent = np.r_[np.radians([0.0, 3.0, 3.0, 3.0]), x0[n:]]
    shapes = []
    for rifle_head in (False, True):  # the rifle by the face may keep the spine from bending, or not

        def bend(x: np.ndarray, rifle_head: bool = rifle_head) -> np.ndarray:
            return torso.cost(x, x0, rifle_head)

        spine = search(bend, np.array([x0, bent]), lo, hi)[:n]
        shapes.append(np.r_[spine, _turned_head(torso, spine, x0, lo[n:], hi[n:])])
    x = np.array(shapes)
    return _spine_poses(body.q, kin, x[int(np.argmin(torso.cost(x, x0, True)))][None])[0]


def _turned_head(
    torso: _Torso, spine: np.ndarray, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """The neck's and head's angles (the spine bent by ``spine``) that lay the head lowest, out of the
    rifle: from their own, turned to the other side and the best of :data:`NECK_GRID`."""
    n = len(spine)

    def turn(x: np.ndarray) -> np.ndarray:
        return torso.cost(np.c_[np.broadcast_to(spine, (len(x), n)), x], x0, rifle_head=True)

    other = x0[n:].copy()  # the head turned to the other side: the rifle may lie by the face
    other[TWIST] = -other[TWIST]
    grid = np.radians(np.array(np.meshgrid(*NECK_GRID, indexing="ij")).reshape(3, -1).T)
    shapes = np.c_[grid, np.broadcast_to(x0[n + 3 :], (len(grid), len(x0) - n - 3))]  # the head's own as is
    best = shapes[np.argsort(turn(shapes), kind="stable")[:NECK_STARTS]]
    return search(turn, np.array([x0[n:], other, *best]), lo, hi)


class _Torso:
    """The trunk, neck and head of a face-down body (the arms left out), to bring down."""

    def __init__(self, body: ds._Body) -> None:
        self.body, self.bb = body, _Batch(body)
        parts = body.parts
        arm = np.array([str(p).endswith(ds.ARM_PARTS) for p in parts])
        self.rest = ~arm
        self.head, self.chest = (parts == "head")[self.rest], (parts == "chest")[self.rest]
        head_segs = np.isin(body.segs, np.unique(body.segs[parts == "head"]))
        self.trunk = self.bb.hulls(~arm & ~head_segs)
        self.heads = self.bb.hulls(head_segs)
        self.rifle = body.rifle_points[None]
        g0 = body.kin.segment_globals(body.q, body.root)[None]
        self.rifle0 = (self.trunk.exits(self.rifle, g0)[0][0], self.heads.exits(self.rifle, g0)[0][0])
        self.still = (body.planted & self.rest)[self.rest]
        self.still0 = body.points[body.planted & self.rest]
        self.base = min(0.0, float(body.points[self.rest, 1].min()))

    def cost(self, x: np.ndarray, x0: np.ndarray, rifle_head: bool) -> np.ndarray:
        """How low the head and how flat the chest lie in shapes ``x`` (and how far wrong); the rifle into
        the head counted only if ``rifle_head``."""
        body = self.body
        g, p = self.bb.points(_spine_poses(body.q, body.kin, x), self.rest)
        rifle = np.broadcast_to(self.rifle, (len(x), *self.rifle.shape[1:]))
        h = p[:, self.head]
        low = h[..., 1].min(axis=1)
        slid = np.hypot(*(p[:, self.still] - self.still0)[..., [0, 2]].transpose(2, 0, 1))
        wrong = np.maximum(0.0, self.base - p[:, ~self.head, 1].min(axis=1))
        wrong += np.maximum(0.0, slid.max(axis=1, initial=0.0) - ds.SLIDE_CM)
        wrong += np.maximum(0.0, self.trunk.exits(rifle, g)[0] - self.rifle0[0])
        wrong += np.maximum(0.0, ds.HEAD_CLEARANCE - low) + self.trunk.exits(h, g)[0]
        if rifle_head:
            wrong += np.maximum(0.0, self.heads.exits(rifle, g)[0] - self.rifle0[1])
        score = low + CHEST_WEIGHT * p[:, self.chest, 1].mean(axis=1)
        move = ds.MOVE_COST * np.degrees(np.abs(x - x0)).sum(axis=1)
        return score + ds.PENALTY * wrong + move


class _LaidArm:
    """One arm of a face-down body (``body.q``: the torso where it is), to lay on or lift off the ground:
    ``shape_cost`` scores shapes ``x`` of its clavicle, shoulder, elbow and wrist angles."""

    def __init__(self, body: ds._Body, side: str) -> None:
        self.bb, self.side = _Batch(body), side
        parts = body.parts
        self.idx = ds._dofs(body.kin, tuple(f"{side}_{j}" for j in ds.ARM_DOFS))
        self.arm = np.array([str(p).startswith(side) and str(p).endswith(ds.ARM_PARTS) for p in parts])
        hand = np.flatnonzero(parts == f"{side}_hand")
        self.lower = parts == f"{side}_forearm"
        self.lower[hand[::HAND_EVERY]] = True  # the fingers' nodes are dense: every few test the body
        # only what the arm can reach from its shoulder is tested (the hull tests are the searches' cost)
        g, p = body.heights(body.q)
        shoulder = g[body.kin.segment_names.index(f"{side}_upper_arm"), :3, 3]
        reach = np.linalg.norm(p[self.arm] - shoulder, axis=1).max() + REACH_MARGIN_CM
        near = np.linalg.norm(p - shoulder, axis=1) < reach
        self.rest = self.bb.hulls(near & ~self.arm & ~np.isin(body.segs, np.unique(body.segs[self.arm])))
        self.hulls = self.bb.hulls(self.arm)
        self.limbs = [parts[self.arm] == f"{side}{part}" for part in ds.ARM_PARTS]
        self.q = body.q.copy()
        self.rifle = body.rifle_points[np.linalg.norm(body.rifle_points - shoulder, axis=1) < reach]

    def measure(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per shape: the arm's nodes ``(n, k, 3)`` and how deep (cm) it goes into the body or the rifle."""
        q = np.repeat(self.q[None], len(x), axis=0)
        q[:, self.idx] = x
        g, arm = self.bb.points(q, self.arm)
        d_body, _ = self.rest.exits(arm[:, self.lower[self.arm]], g)
        d_rifle, _ = self.hulls.exits(np.broadcast_to(self.rifle, (len(x), *self.rifle.shape)), g)
        return arm, d_body + d_rifle

    def laid_cost(self, x: np.ndarray, x0: np.ndarray) -> np.ndarray:
        p, inside = self.measure(x)
        y = p[..., 1]
        high = np.max([y[:, m].min(axis=1) for m in self.limbs], axis=0)
        wrong = np.maximum(0.0, ds.ARM_CLEARANCE - y.min(axis=1)) + inside
        move = ds.MOVE_COST * np.degrees(np.abs(x - x0)).sum(axis=1)
        return high + ds.MEAN_WEIGHT * y.mean(axis=1) + ds.PENALTY * wrong + move

    def lifted_cost(
        self,
        x: np.ndarray,
        near: np.ndarray,
        above: np.ndarray | None,
        lift: float,
        level: float = 0.0,
        low: bool = False,
    ) -> np.ndarray:
        """Lifted ``lift`` cm clear, the nearest to the shape ``near`` or, given ``above``, with its nodes
        the nearest straight above those (world ``(k, 3)``), their height over ``lift`` above them weighed
        ``level`` times as much as a miss sideways; ``low``: each part held low too."""
        p, inside = self.measure(x)
        wrong = np.maximum(0.0, lift - p[..., 1].min(axis=1)) + inside
        far = 1e-3 * (np.degrees(x - near) ** 2).sum(axis=1)
        if above is not None:
            far = far + ((p - above)[..., [0, 2]] ** 2).sum(axis=2).mean(axis=1)
            if level:
                far = far + level * (np.maximum(0.0, p[..., 1] - above[:, 1] - lift) ** 2).mean(axis=1)
        if low:
            y = p[..., 1]
            far = far + LOW_AIR_WEIGHT * np.sum([y[:, m].min(axis=1) - lift for m in self.limbs], axis=0)
        return far + ds.PENALTY * wrong


def laid_arm(body: ds._Body, side: str) -> np.ndarray:
    """The ``side`` arm's shape that lays it lowest against the torso of ``body.q`` (from its own shape and
    the best shapes of :data:`authoring.dead_settle.ARM_GRID`)."""
    arm = _LaidArm(body, side)
    x0 = body.q[arm.idx]

    def cost(x: np.ndarray) -> np.ndarray:
        return arm.laid_cost(x, x0)

    starts = np.array([x0, *_grid_starts(body.kin, side, x0, cost)])
    return search(cost, starts, body.kin.lower[arm.idx], body.kin.upper[arm.idx])


def _grid_starts(kin, side: str, x0: np.ndarray, cost: Cost) -> list[np.ndarray]:
    """The :data:`authoring.dead_settle.ARM_STARTS` lowest shapes of the arm grid, evaluated at once."""
    base = kin.dof_slices[f"{side}_clavicle"].start
    grid = [kin.dof_slices[f"{side}_{j}"].start - base for j in ("clavicle", "shoulder", "elbow")]
    at = np.array([grid[0], grid[0] + 1, grid[1], grid[1] + 1, grid[1] + 2, grid[2]])
    angles = np.radians(np.array(np.meshgrid(*ds.ARM_GRID, indexing="ij")).reshape(len(at), -1).T)
    x = np.repeat(x0[None], len(angles), axis=0)
    x[:, at] = angles
    order = np.argsort(cost(x), kind="stable")
    return list(x[order[: ds.ARM_STARTS]])


def lifted_arm(
    body: ds._Body,
    side: str,
    near: np.ndarray,
    above: np.ndarray | None = None,
    lift: float = LIFT_CM,
    level: float = 0.0,
    low: bool = False,
) -> np.ndarray:
    """The ``side`` arm's shape nearest ``near`` (given ``above``, its nodes' places: straight above them,
    ``level``: no higher, :data:`LEVEL_WEIGHT`) with every arm node ``lift`` cm up (``low``: and no higher
    than it must), into neither the body nor the rifle (``body.q``: the torso where it is then)."""
    arm = _LaidArm(body, side)

    def cost(x: np.ndarray) -> np.ndarray:
        return arm.lifted_cost(x, near, above, lift, level, low)

    return search(cost, near[None], body.kin.lower[arm.idx], body.kin.upper[arm.idx])


def _arm_points(body: ds._Body, side: str, x: np.ndarray) -> np.ndarray:
    """The ``side`` arm's nodes (world) in shape ``x``, the torso of ``body.q``."""
    return _LaidArm(body, side).measure(x[None])[0][0]


def torso_progress(t: np.ndarray) -> np.ndarray:
    """How far down the torso is at ``t`` of the settle (eased over :data:`TORSO_SPAN`)."""
    a, b = TORSO_SPAN
    s = np.clip((np.asarray(t, dtype=np.float64) - a) / (b - a), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def arm_path(keys: dict, t: np.ndarray) -> np.ndarray:
    """Shapes at frames ``t`` through ``keys`` (by frame): a cubic Hermite spline, Catmull-Rom tangents
    inside and at rest at both ends."""
    from scipy.interpolate import CubicHermiteSpline

    k = np.array(sorted(keys), dtype=np.float64)
    x = np.array([keys[f] for f in sorted(keys)])
    tangents = np.zeros_like(x)
    tangents[1:-1] = (x[2:] - x[:-2]) / (k[2:] - k[:-2])[:, None]
    return CubicHermiteSpline(k, x, tangents)(t)


def _within(kin, side: str, x: np.ndarray) -> np.ndarray:
    """Arm shapes clipped to the ``side`` arm's joint limits (the spline overshoots a shape at a limit)."""
    i = _arm_dofs(kin, side)
    return np.clip(x, kin.lower[i], kin.upper[i])


def _air_keys(
    body: ds._Body,
    side: str,
    poses: np.ndarray,
    q0: np.ndarray,
    target: np.ndarray,
    level: float = 0.0,
    held_low: bool = False,
) -> dict:
    """The ``side`` arm's shapes at frames of the settle ``poses`` (the torso coming down): as it lay and as
    it will lie, just clear straight above both (:data:`CLEAR_CM`, :data:`LIFT_OFF`), well clear straight
    above both (:data:`LIFT_CM`, :data:`AIR_SPAN`; ``level``: no higher, :func:`lifted_arm`) and between
    (``held_low``: each after it is well clear of where it lay held low, :data:`LOW_AIR_WEIGHT`)."""
    n, i = len(poses), _arm_dofs(body.kin, side)
    x0, x1 = q0[i], target[i]

    def at(
        frame: int,
        near: np.ndarray,
        above: np.ndarray | None = None,
        lift: float = LIFT_CM,
        low: bool = held_low,
    ) -> np.ndarray:
        body.q = poses[frame].copy()  # the torso (and the other arm) then
        return lifted_arm(body, side, near, above, lift, level if above is not None else 0.0, low)

    body.q = q0.copy()
    start = _arm_points(body, side, x0)
    body.q = target.copy()
    end = _arm_points(body, side, x1)
    frame = [round(f * n) - 1 for f in (LIFT_OFF, AIR_SPAN[0], AIR_SPAN[1], 1.0 - LIFT_OFF)]
    keys = {-1: x0, n - 1: x1}
    # it leaves the ground as without held_low (held low from the start, crawl2dead's M16 slave's right upper
    # arm skidded 3.6-4.9 cm as it left)
    keys[frame[0]] = at(frame[0], x0, start, CLEAR_CM, low=False)
    keys[frame[3]] = at(frame[3], x1, end, CLEAR_CM)
    keys[frame[1]] = a = at(frame[1], x0, start, low=False)
    keys[frame[2]] = b = at(frame[2], x1, end)
    for f in np.linspace(frame[1], frame[2], AIR_KEYS)[1:-1].round().astype(int):
        w = (f - frame[1]) / (frame[2] - frame[1])
        keys[int(f)] = at(int(f), (1.0 - w) * a + w * b)
    for _ in range(MORE_KEYS):  # where the path between the shapes dips, one more shape on it
        low = _heights(body, side, poses, keys)
        air = np.arange(n)
        dip = np.where((air > frame[1]) & (air < frame[2]), low, np.inf)
        worst = int(np.argmin(dip))
        if dip[worst] >= 0.5 * LIFT_CM:
            break
        keys[worst] = at(worst, _within(body.kin, side, arm_path(keys, np.array([worst])))[0])
    return keys


def _arm_dofs(kin, side: str) -> np.ndarray:
    return ds._dofs(kin, tuple(f"{side}_{j}" for j in ds.ARM_DOFS))


def _heights(body: ds._Body, side: str, poses: np.ndarray, keys: dict) -> np.ndarray:
    """Per frame of ``poses``, the ``side`` arm's lowest node on the path through ``keys``."""
    q = poses.copy()
    q[:, _arm_dofs(body.kin, side)] = _within(body.kin, side, arm_path(keys, np.arange(len(poses))))
    arm = _LaidArm(body, side)
    return arm.bb.points(q, arm.arm)[1][..., 1].min(axis=1)


def lowered(body: ds._Body, n: int, level: bool = False, low_air: bool = False) -> np.ndarray:
    """The ``n`` settle poses of a propped face-down ``body`` (its last frame in ``body.q``): the torso and
    head come down, the arms move to their new places through the air (``level``: lifted no higher than
    just clear, :data:`LEVEL_WEIGHT`; ``low_air``: held low in it)."""
    kin, q0 = body.kin, body.q.copy()
    torso = lowered_torso(body)
    body.q = torso.copy()
    for side in ARM_SIDES:
        body.q[_arm_dofs(kin, side)] = laid_arm(body, side)
    target = body.q.copy()
    t = np.arange(1, n + 1) / n
    poses = q0[None] + torso_progress(t)[:, None] * (target - q0)[None]
    for side in ARM_SIDES:
        keys = _air_keys(body, side, poses, q0, target, LEVEL_WEIGHT if level else 0.0, low_air)
        poses[:, _arm_dofs(kin, side)] = _within(kin, side, arm_path(keys, np.arange(n)))
    body.q = q0
    _head_clear_of_rifle(body, poses)
    return poses


def _head_clear_of_rifle(body: ds._Body, poses: np.ndarray) -> None:
    """Where the head on its way down passes through the rifle where it lies (crawl2dead: it lies by the
    face), a shape of the neck and head clear of it, nearest the path there, and the path through it (in
    place)."""
    torso, kin = _Torso(body), body.kin
    i = ds._dofs(kin, NECK_DOFS)
    n = len(poses)
    keys = {-1: body.q[i], n - 1: poses[-1, i]}
    rifle = np.broadcast_to(torso.rifle, (n, *torso.rifle.shape[1:]))
    for _ in range(MORE_KEYS):
        g = kin.segment_globals(poses, body.root)
        depth = torso.heads.exits(rifle, g)[0] - torso.rifle0[1]
        worst = int(np.argmax(depth))
        if depth[worst] <= RIFLE_SLACK_CM:
            return
        q, near = poses[worst], poses[worst, i]

        def cost(x: np.ndarray, q: np.ndarray = q, near: np.ndarray = near) -> np.ndarray:
            qs = np.repeat(q[None], len(x), axis=0)
            qs[:, i] = x
            g, p = torso.bb.points(qs, torso.rest)
            h = p[:, torso.head]
            inside = torso.heads.exits(np.broadcast_to(torso.rifle, (len(x), *torso.rifle.shape[1:])), g)[0]
            wrong = np.maximum(0.0, inside - torso.rifle0[1]) + torso.trunk.exits(h, g)[0]
            wrong += np.maximum(0.0, ds.HEAD_CLEARANCE - h[..., 1].min(axis=1))
            return 1e-3 * (np.degrees(x - near) ** 2).sum(axis=1) + ds.PENALTY * wrong

        keys[worst] = search(cost, near[None], kin.lower[i], kin.upper[i])
        poses[:, i] = np.clip(arm_path(keys, np.arange(n)), kin.lower[i], kin.upper[i])
