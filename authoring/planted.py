"""Parts on the ground stay put: a simulated clip's drift along the ground is taken out of its root.

The ragdoll of :mod:`authoring.deaths` skids: while a soldier's knees buckle and he pitches forward, the parts
he rests on slide 5-12 cm over the ground (MuJoCo's soft contacts under the muscles that shape the fall;
more friction, ``noslip``, ``impratio``, and pinning loaded parts with ``connect`` constraints did not stop
it). So the recorded frames are moved back horizontally, frame by frame, by how far the parts on the ground
moved: per part the mean motion of its mesh nodes that touched the ground (the check's contact height) in
this frame and the one before, averaged over those parts, accumulated from the first frame (which stays
where it is). The whole figure moves as one (root and rifle), so no pose changes: where the body skids as a
whole the skid is gone, where one part drags against the others it is only shared out.
"""

from __future__ import annotations

import numpy as np

from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.model import Figure


def ground_drift(points: np.ndarray, touching: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """``(n, 3)`` how far (cm, horizontal) the parts on the ground moved into each frame: ``points``
    ``(n, k, 3)`` mesh nodes per frame, ``touching`` ``(n, k)`` on the ground, ``parts`` ``(k,)`` their body
    parts; per part the mean motion of its nodes touching in both frames, averaged over the parts (0 with
    none)."""
    drift = np.zeros((len(points), 3))
    for f in range(1, len(points)):
        both = touching[f] & touching[f - 1]
        step = points[f] - points[f - 1]
        moves = [step[both & (parts == p)].mean(axis=0) for p in np.unique(parts[both])]
        if moves:
            drift[f] = np.mean(moves, axis=0)
    drift[:, 1] = 0.0
    return drift


def plant(frames: ClipFrames, soldier: Figure) -> ClipFrames:
    """``frames`` with the drift of the parts on the ground taken out (see the module docstring)."""
    figs = FigureSet({"body": soldier})
    nodes, segs = figs.nodes("body")
    g = figs.kin["body"].segment_globals(frames.poses, frames.roots)
    points = np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes)
    touching = points[..., 1] <= CONTACT_HEIGHT_CM
    shift = -np.cumsum(ground_drift(points, touching, figs.node_parts("body")), axis=0)
    roots, rifles = np.array(frames.roots), np.array(frames.rifles)
    roots[:, :3, 3] += shift
    rifles[:, :3, 3] += shift
    return ClipFrames(frames.poses, roots, rifles, frames.fps)


# The kneeling deaths (issue 14, kneelskid14): as he lands on his side, the ragdoll's thigh skids in the
# physics itself (kfire2dead 6.6 cm before planting): its ground contact flickers (in contact in 5-20 % of
# the 1/1200 s steps, the whole body without any ground contact in 13 % of the steps after landing) and the
# elliptic friction cone is spent on its torsional and rolling terms; friction x2, sliding-only contacts,
# softer or harder contacts, a 1/2400 s step, 30 no-slip iterations each left it 4-9 cm and changed the
# fall. The mean drift of :func:`plant` shares one part's skid out to the others (kstow2dead's thigh
# 3.1 -> 4.5 cm).
WORST_DIRECTIONS = 8  # the slide is measured along this many horizontal directions (the check: 16)
WORST_STEP_CM = 0.5  # the correction moves the body at most this far per frame and axis (30 cm/s at 60 fps)
WORST_MOTION = 0.02  # per cm the correction moves the body: of two equally good, the stiller
WORST_RUNS = 8  # per part, the runs that slide most enter the first solve; more join while they slide further
WORST_ROUNDS = 4
# kfire2dead (kneelrest14): shifts alone left the trunk's skid on landing at 3.3-3.7 cm; a turn of the whole
# body about the vertical of up to 5 degrees over the fall takes it under 3 (offline on the finished clip)
WORST_TURN_STEP = np.radians(0.5)  # the turn changes at most this much a frame
WORST_TURN_COST = 2.0  # per radian of that change: as a cm of shift (WORST_MOTION) at a 1 m lever
# a foot's or knee's slide weighs this little: the legs' lift takes those off the ground (leg_lift)
LEG_WEIGHT = 0.1
PART_WEIGHT = 0.2  # each other part's own worst slide (besides the worst of them all, weighing 1)
LEG_PARTS = ("left_foot", "right_foot", "left_knee", "right_knee")


def least_worst_shift(
    points: np.ndarray, parts: np.ndarray, pivot: np.ndarray | None = None, directions: int = WORST_DIRECTIONS
) -> np.ndarray:
    """``(n, 3)`` horizontal shifts (cm; the first frame's 0) of a body whose mesh nodes are ``points``
    ``(n, k, 3)`` (of body ``parts`` ``(k,)``) that bring each part's largest slide on the ground (the
    check's measure, along ``directions``: :data:`WORST_DIRECTIONS`) down, their sum least: a linear
    programme (HiGHS) in the shifts, each part's worst slide and, per contact run and direction, its extent;
    the correction moves at most :data:`WORST_STEP_CM` a frame and costs :data:`WORST_MOTION` a cm. With a
    ``pivot`` (x, z) the body may also turn about the vertical through it (linearised:
    :data:`WORST_TURN_STEP` a frame at most, costing :data:`WORST_TURN_COST` a radian); the turns are the
    returned array's y column (radians)."""
    from authoring.body_parts import contact_runs

    n = len(points)
    runs = contact_runs(points, CONTACT_HEIGHT_CM)
    long = np.flatnonzero(runs.last > runs.first)
    if not len(long) or n < 2:
        return np.zeros((n, 3))
    names = np.char.replace(parts.astype(str), "_kneecap", "_knee")
    run_part = names[runs.node[long]]
    chosen = np.concatenate([long[run_part == p][np.argsort(-runs.slide[long[run_part == p]])[:WORST_RUNS]]
                             for p in np.unique(run_part)])  # fmt: skip
    shift = np.zeros((n, 3))
    for _ in range(WORST_ROUNDS):
        shift = _solve_shift(points, runs, chosen, names, pivot, directions)
        extent = _run_extents(_turned(points, shift, pivot), runs, long, np.zeros((n, 2)), directions)
        worst = {p: extent[run_part == p].max() for p in np.unique(run_part)}
        late = long[(extent > np.array([worst[p] for p in run_part]) - 1e-6) & ~np.isin(long, chosen)]
        if not len(late):
            break
        chosen = np.concatenate([chosen, late])
    return shift


def _turned(points: np.ndarray, shift: np.ndarray, pivot: np.ndarray | None) -> np.ndarray:
    """``points`` ``(n, k, 3)`` turned per frame by ``shift[:, 1]`` (radians) about the vertical through
    ``pivot`` (x, z; none: not turned), then moved by ``shift``'s x and z."""
    out = points.copy()
    if pivot is not None:
        c, s = np.cos(shift[:, 1])[:, None], np.sin(shift[:, 1])[:, None]
        rx, rz = points[..., 0] - pivot[0], points[..., 2] - pivot[1]
        out[..., 0], out[..., 2] = pivot[0] + c * rx + s * rz, pivot[1] - s * rx + c * rz
    out[..., 0] += shift[:, None, 0]
    out[..., 2] += shift[:, None, 2]
    return out


def _directions(count: int = WORST_DIRECTIONS) -> np.ndarray:
    ang = np.arange(count) * np.pi / count
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


def _run_extents(
    points: np.ndarray, runs, which: np.ndarray, shift: np.ndarray, directions: int = WORST_DIRECTIONS
) -> np.ndarray:
    """Each run's slide (along :func:`_directions`) with the body shifted by ``shift`` ``(n, 2)``."""
    dirs = _directions(directions)
    out = np.zeros(len(which))
    for j, r in enumerate(which):
        a, b = runs.first[r], runs.last[r] + 1
        proj = (points[a:b, runs.node[r]][:, [0, 2]] + shift[a:b]) @ dirs.T
        out[j] = np.ptp(proj, axis=0).max()
    return out


def _solve_shift(
    points: np.ndarray,
    runs,
    chosen: np.ndarray,
    names: np.ndarray,
    pivot: np.ndarray | None = None,
    directions: int = WORST_DIRECTIONS,
) -> np.ndarray:
    """The linear programme of :func:`least_worst_shift` over the runs ``chosen``: ``(n, 3)`` shifts (x, the
    turn about the vertical through ``pivot`` or 0, z)."""
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix

    n, dirs = len(points), _directions(directions)
    nd = len(dirs)
    groups = sorted(set(names[runs.node[chosen]]))
    # variables: shifts (2n) | per run and direction, the highest and lowest projection | per part its
    # worst slide | per frame and axis, how far the correction moves
    s0, e0 = 0, 2 * n
    w0 = e0 + 2 * len(chosen) * nd
    m0 = w0 + len(groups)
    t0 = m0 + 2 * (n - 1)  # the worst slide of the parts not legs
    r0 = nv = t0 + 1  # with a pivot: per frame the turn, and how far it changes into the frame
    if pivot is not None:
        nv += 2 * n - 1
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    rhs: list[np.ndarray] = []
    count = 0

    def add(c: np.ndarray, v: np.ndarray, b: np.ndarray) -> None:  # rows of c/v (m, w): sum v x <= b
        nonlocal count
        m = len(b)
        rows.append(np.repeat(np.arange(count, count + m), c.shape[1]))
        cols.append(c.ravel())
        vals.append(v.ravel())
        rhs.append(b)
        count += m

    for j, r in enumerate(chosen):
        a, b = int(runs.first[r]), int(runs.last[r]) + 1
        f = np.arange(a, b)
        proj = points[a:b, runs.node[r]][:, [0, 2]] @ dirs.T  # (frames, nd)
        part = groups.index(names[runs.node[r]])
        for d in range(nd):
            hi, lo = e0 + 2 * (j * nd + d), e0 + 2 * (j * nd + d) + 1
            ones = np.ones(len(f))
            sx, sz = s0 + 2 * f, s0 + 2 * f + 1
            along = np.stack([dirs[d, 0] * ones, dirs[d, 1] * ones, -ones], 1)
            at = [sx, sz]
            if pivot is not None:  # a turn by t moves a point at (x, z) by t (z - pz, px - x)
                rel = points[a:b, runs.node[r]][:, [0, 2]] - pivot
                along = np.insert(along, 2, rel[:, 1] * dirs[d, 0] - rel[:, 0] * dirs[d, 1], axis=1)
                at.append(r0 + f)
            add(np.stack([*at, hi + 0 * f], 1), along, -proj[:, d])  # projection <= highest
            add(np.stack([*at, lo + 0 * f], 1), -along, proj[:, d])  # lowest <= projection
            add(np.array([[hi, lo, w0 + part]]), np.array([[1.0, -1.0, -1.0]]), np.zeros(1))
    for part, name in enumerate(groups):
        if name not in LEG_PARTS:
            add(np.array([[w0 + part, t0]]), np.array([[1.0, -1.0]]), np.zeros(1))
    f = np.arange(1, n)
    for ax in range(2):
        m = m0 + 2 * (f - 1) + ax
        now, before = s0 + 2 * f + ax, s0 + 2 * (f - 1) + ax
        ones = np.ones(len(f))
        add(np.stack([now, before, m], 1), np.stack([ones, -ones, -ones], 1), np.zeros(len(f)))
        add(np.stack([now, before, m], 1), np.stack([-ones, ones, -ones], 1), np.zeros(len(f)))
    if pivot is not None:
        m = r0 + n + f - 1
        add(np.stack([r0 + f, r0 + f - 1, m], 1), np.stack([ones, -ones, -ones], 1), np.zeros(len(f)))
        add(np.stack([r0 + f, r0 + f - 1, m], 1), np.stack([-ones, ones, -ones], 1), np.zeros(len(f)))
    a_ub = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(count, nv))
    cost = np.zeros(nv)
    cost[w0:m0] = [LEG_WEIGHT if g in LEG_PARTS else PART_WEIGHT for g in groups]
    cost[m0:t0] = WORST_MOTION
    cost[t0] = 1.0
    bounds = [(0.0, 0.0)] * 2 + [(None, None)] * (w0 - 2) + [(0.0, None)] * len(groups)
    bounds += [(0.0, WORST_STEP_CM)] * (2 * (n - 1)) + [(0.0, None)]
    if pivot is not None:
        cost[r0 + n :] = WORST_TURN_COST
        bounds += [(0.0, 0.0)] + [(None, None)] * (n - 1) + [(0.0, WORST_TURN_STEP)] * (n - 1)
    res = linprog(cost, A_ub=a_ub.tocsr(), b_ub=np.concatenate(rhs), bounds=bounds, method="highs")
    if res.status != 0:
        return np.zeros((n, 3))
    xz = np.asarray(res.x[: 2 * n]).reshape(n, 2)
    turn = np.asarray(res.x[r0 : r0 + n]) if pivot is not None else np.zeros(n)
    return np.stack([xz[:, 0], turn, xz[:, 1]], axis=1)


def _mesh_points(frames: ClipFrames, soldier: Figure) -> tuple[np.ndarray, np.ndarray]:
    """The soldier's mesh nodes per frame ``(n, k, 3)`` and their body parts ``(k,)``."""
    figs = FigureSet({"body": soldier})
    nodes, segs = figs.nodes("body")
    g = figs.kin["body"].segment_globals(frames.poses, frames.roots)
    return np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes), figs.node_parts("body")


def plant_least_worst(frames: ClipFrames, soldier: Figure) -> ClipFrames:
    """``frames`` planted (:func:`plant`), then shifted along the ground so that each part's worst slide is
    least (:func:`least_worst_shift`) rather than the mean drift gone."""
    frames = plant(frames, soldier)
    points, parts = _mesh_points(frames, soldier)
    shift = least_worst_shift(points, parts)
    roots, rifles = np.array(frames.roots), np.array(frames.rifles)
    roots[:, :3, 3] += shift
    rifles[:, :3, 3] += shift
    return ClipFrames(frames.poses, roots, rifles, frames.fps)


def least_worst_turned(frames: ClipFrames, soldier: Figure, directions: int = WORST_DIRECTIONS) -> ClipFrames:
    """``frames`` shifted along the ground and turned about the vertical (through the middle of what he
    finally lies on) so that each part's worst slide is least (:func:`least_worst_shift`, measured along
    ``directions``); their poses unchanged, the first frame where it was."""
    points, parts = _mesh_points(frames, soldier)
    last = points[-1]
    pivot = last[last[:, 1] <= CONTACT_HEIGHT_CM][:, [0, 2]].mean(axis=0)
    shift = least_worst_shift(points, parts, pivot, directions)
    c, s = np.cos(shift[:, 1]), np.sin(shift[:, 1])
    move = np.tile(np.eye(4), (len(shift), 1, 1))
    move[:, 0, 0], move[:, 0, 2], move[:, 2, 0], move[:, 2, 2] = c, s, -s, c
    at = np.array([pivot[0], 0.0, pivot[1]])
    move[:, :3, 3] = at - np.einsum("fij,j->fi", move[:, :3, :3], at) + shift * [1.0, 0.0, 1.0]
    return ClipFrames(frames.poses, move @ frames.roots, move @ frames.rifles, frames.fps)
