"""A dead slave's trunk comes to rest on the ground: pelvis and chest or belly both down, as a body lies.

DI.fig's trunk is shaped differently from soldier.fig's (its belly stands further out of the line from
pelvis to chest), so with the master's angles and the limbs laid down (:mod:`authoring.slave_ground`) a dead
DI lay on its belly with the pelvis 3-5 cm up, or on its pelvis with the chest up. Once the master lies
still, :func:`rest_slave_trunk` looks for the smallest change of the last frame that brings the pelvis and
the chest or belly down together (to ``AIM_CM``): the body turned about the ground under its trunk (root
pitch and roll), the spine bent (waist, belly, upper spine), the hips and knees (the trunk pivots about the
thighs), each candidate lowered onto the ground, while every part resting on the ground stays on it and no
foot, heel or the head rises past the check's bound (SLSQP); then the change is eased in over the half
second before the clip's last frames, where the body lies still (eased in from where the master's root
stops, the last frame's turn about the last frame's ground point met a body still falling: it sank, was
lifted 3 cm and its chest slid 9 cm). The build's ``lift_off_ground`` runs after it.

With ``feet_held`` (a death's :attr:`~authoring.deaths.DeathSpec.slave_feet_held`) a foot near the ground
whose knee is up is held where it was through the change, its leg solved to carry it (:func:`_hold_feet`),
instead of only bounding its slide at the last frame: kfire2dead's DI, its right foot hovering 1.2-1.9 cm
over the ground, was lowered onto it by the trunk's turn while still moving and skated 4.1 cm.

A death may let the resting parts slide further than ``SLIDE_CM``
(:attr:`~authoring.deaths.DeathSpec.slave_rest_slide_cm`): kfire2dead's DI pelvis lies bridged between its
belly and left thigh, and with its hands, knee, thigh and foot held to 0.8 cm the search brought it down
only to 2.34 cm (1.54 at 1.5 cm).

With ``arms_held`` (:attr:`~authoring.deaths.DeathSpec.slave_arms_held`) an upper arm or forearm lying on
the ground at the end is held where it lands there (:func:`_hold_arms`): prfire2dead's DI and M16, the
trunk lowered under a right arm still swinging in beside the body (the master's settle lays it anew, and
the slave's spine still turns), touched down 0.2 s before the end and swept 3.8-4.2 cm along the ground.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import minimize

from authoring import ik
from authoring.postures import leg
from authoring.quality_frames import FigureSet
from authoring.slave_body import joint_chain, played_body, write_pose
from authoring.slave_contacts import SIDES
from authoring.slave_feet import KNEE_DOWN_CM, NEAR_CM, part_points
from authoring.slave_ground import PART_SITES
from authoring.transitions import track_solve
from peabody.fk import FigureKinematics
from server.motion.channelset import Channelset

REST_CM = 2.0  # a part this low at the end rests on the ground: it stays this low (the check's rest limit)
SLIDE_CM = 0.8  # ... and its sites move along the ground no further than this (the check's slide: 2-3 cm)
TRUNK_PARTS = ("pelvis", "chest|belly")  # a dead body's trunk parts, both on the ground
# may not rise above max(now, their check limit): the feet (heel sites too) and the head
RISE_LIMIT_CM = {"left_foot": 15.0, "right_foot": 15.0, "left_heel": 15.0, "right_heel": 15.0, "head": 10.0}
HEELS = ("left_heel", "right_heel")
AIM_CM = 1.0  # the trunk is brought this low (not lower: the smallest change that rests it)
MOVE_WEIGHT = 0.002  # the search's cost per square degree of change (of two equal rests, the smaller change)
MAX_TURN_DEG = 20.0  # no parameter turns further than this
SEARCH_ITERATIONS = 200  # the search's SLSQP iterations at most ...
SEARCH_STARTS = 3  # ... per start, started again from where it stopped while that lowers the trunk
JAC_STEP_DEG = 0.01  # the forward-difference step of the heights' derivatives
# a solution may pass a part's bound by this much (the heights are not smooth: SLSQP ends near, not at, them)
BOUND_SLACK_CM = 0.25
KEPT_SHARES = 20  # a search ending past a bound keeps the largest share (1/20 steps) of its move within them
EASE_FRAMES = 30  # the change eases in over this many frames (0.5 s) near the clip's end, where the body lies
END_HOLD_FRAMES = 4  # still, and is in full this many frames before the end (a death ends at rest)
HOLD_ITERATIONS = 20  # a held foot's leg is tracked frame after frame (slave_feet's tracking) ...
HOLD_DOF_STEP = 0.01  # ... in steps of at most this (rad)
HOLD_TURN_CM = 40.0  # a radian of a held foot's turn weighs this much move: held firmly
ARM_PARTS = tuple(f"{s}_{p}" for s in SIDES for p in ("upper_arm", "forearm"))  # held where they land ...
ARM_DOWN_CM = 1.25  # ... lying this low (the check's contact height) from then to the last frame ...
ARM_HELD_SITES = ("lower_arm.proximal", "lower_arm.distal")  # ... by the elbow and the wrist
# the searched parameters: a root turn about world x or z through the ground under the trunk, or a DOF
PARAMS = (
    ("root", 0),
    ("root", 2),
    ("waist", 1),
    ("waist", 0),
    ("waist", 2),
    ("belly", 1),
    ("belly", 0),
    ("upper_spine", 1),
    ("left_hip", 1),
    ("right_hip", 1),
    ("left_hip", 0),
    ("right_hip", 0),
    ("knees", 0),
)


def part_lows(figures: FigureSet, ptype: str, poses: np.ndarray, locs: np.ndarray) -> dict[str, np.ndarray]:
    """Per body part (and ``chest|belly``, ``lowest``), its lowest mesh node's height ``(m,)`` (cm)."""
    kin = figures.kin[ptype]
    nodes, segs = figures.nodes(ptype)
    parts = figures.node_parts(ptype)
    g = kin.segment_globals(poses, locs)[..., 1, :]
    y = np.einsum("fkj,kj->fk", g[:, segs], nodes)
    out = {str(p): y[:, parts == p].min(axis=1) for p in np.unique(parts)}
    out["lowest"] = y.min(axis=1)
    out["chest|belly"] = np.minimum(out.get("chest", np.inf), out.get("belly", np.inf))
    sites = kin.site_globals(poses, locs)[..., 1, 3]
    for side in ("left", "right"):
        if f"{side}_foot.heel" in kin.site_names:
            out[f"{side}_heel"] = sites[:, kin.site_names.index(f"{side}_foot.heel")]
    return out


def _turn(axis: int, deg: np.ndarray) -> np.ndarray:
    """Rotations ``(m, 4, 4)`` by ``deg`` about world axis ``axis`` (0 = x, 2 = z)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    m = np.tile(np.eye(4), (len(deg), 1, 1))
    i, j = (1, 2) if axis == 0 else (0, 1)
    m[:, i, i], m[:, i, j], m[:, j, i], m[:, j, j] = c, -s, s, c
    return m


class _Rest:
    """The last frame of a dead slave and the candidates of the search around it."""

    def __init__(
        self,
        figures: FigureSet,
        ptype: str,
        pose: np.ndarray,
        loc: np.ndarray,
        slide_cm: float = SLIDE_CM,
        heels_cm: float | None = None,
    ) -> None:
        self.figures, self.ptype, self.pose, self.loc = figures, ptype, pose, loc
        kin = figures.kin[ptype]
        self.dofs = [[kin.dof_slices[j].start + k for j in _joints(kin, name)] for name, k in PARAMS]
        self.lower, self.upper = kin.lower, kin.upper
        lows = part_lows(figures, ptype, pose[None], loc[None])
        trunk = min(TRUNK_PARTS, key=lambda p: float(lows[p][0]))
        y = self._node_heights(pose[None], loc[None])[0]
        parts = figures.node_parts(ptype)
        low = np.flatnonzero(_part_mask(parts, trunk))[np.argmin(y[_part_mask(parts, trunk)])]
        nodes, segs = figures.nodes(ptype)
        at = kin.segment_globals(pose[None], loc[None])[0, segs[low]] @ nodes[low]
        self.pivot = np.array([at[0], 0.0, at[2]])  # the ground under the trunk's lowest point
        base = {p: float(v[0] - lows["lowest"][0]) for p, v in lows.items()}
        not_limbs = (*TRUNK_PARTS, "lowest", "chest", "belly")
        resting = [p for p, h in base.items() if h <= REST_CM and p not in not_limbs]
        self.ceiling = {p: max(base[p], REST_CM) for p in resting}
        self.ceiling |= {p: max(base[p], cm) for p, cm in RISE_LIMIT_CM.items() if p in base}
        if heels_cm is not None:  # the heels brought down to this, however high they lay
            self.ceiling |= {p: heels_cm for p in HEELS if p in base}
        # a resting limb's sites do not slide either (the turn about the trunk moved feet 3-4 cm)
        self.slides = {p: [kin.site_names.index(s) for s in PART_SITES[p] if s in kin.site_names]
                       for p in resting if p in PART_SITES}  # fmt: skip
        self.slides = {p: idx for p, idx in self.slides.items() if idx}
        self.site_at = kin.site_globals(pose[None], loc[None])[0, :, :3, 3]
        self.ceiling |= {f"{p}:slide": slide_cm for p in self.slides}

    def _node_heights(self, poses: np.ndarray, locs: np.ndarray) -> np.ndarray:
        kin = self.figures.kin[self.ptype]
        nodes, segs = self.figures.nodes(self.ptype)
        g = kin.segment_globals(poses, locs)[..., 1, :]
        return np.einsum("fkj,kj->fk", g[:, segs], nodes)

    def placed(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Candidates ``x`` ``(m, len(PARAMS))`` (degrees) applied: poses, root globals (not yet lowered onto
        the ground) and the drop that lowers each onto it (cm, negative down)."""
        poses = np.repeat(self.pose[None], len(x), 0)
        locs = np.repeat(self.loc[None], len(x), 0)
        to, back = np.eye(4), np.eye(4)
        to[:3, 3], back[:3, 3] = self.pivot, -self.pivot
        for k, dofs in enumerate(self.dofs):
            for dof in dofs:
                turned = poses[:, dof] + np.radians(x[:, k])
                poses[:, dof] = np.clip(turned, self.lower[dof], self.upper[dof])
            if not dofs:
                locs = to @ _turn(PARAMS[k][1], x[:, k]) @ back @ locs
        drop = -part_lows(self.figures, self.ptype, poses, locs)["lowest"]
        return poses, locs, drop

    def lows_on_ground(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Per part, its height ``(m,)`` in each candidate lowered onto the ground."""
        poses, locs, drop = self.placed(x)
        out = {p: v + drop for p, v in part_lows(self.figures, self.ptype, poses, locs).items()}
        if self.slides:  # ... and, as ``PART:slide``, how far a resting part's sites move along the ground
            at = self.figures.kin[self.ptype].site_globals(poses, locs)[..., :3, 3]
            for p, idx in self.slides.items():
                moved = (at[:, idx] - self.site_at[idx])[..., [0, 2]]
                out[f"{p}:slide"] = np.linalg.norm(moved, axis=-1).max(axis=1)
        return out


def _joints(kin: FigureKinematics, name: str) -> list[str]:
    """The joints a parameter turns: none for the root, both hips for ``hips``, else the joint itself."""
    if name == "root":
        return []
    if name == "knees":
        return [j for j in (f"left_{name[:-1]}", f"right_{name[:-1]}") if j in kin.dof_slices]
    return [name] if name in kin.dof_slices else []


def _part_mask(parts: np.ndarray, part: str) -> np.ndarray:
    return np.isin(parts, part.split("|"))


def search(rest: _Rest) -> np.ndarray:
    """The smallest change (degrees, :data:`PARAMS`) that brings the trunk down to ``AIM_CM`` or as near as
    it gets with no bounded part past its bound: SLSQP on ``(x, t)``, ``t`` the highest trunk part, started
    again where it stopped while that lowers the trunk. Zero if nothing rests it better."""
    n, names = len(PARAMS), list(rest.ceiling)
    rows = [*TRUNK_PARTS, *names]
    bound = np.array([0.0] * len(TRUNK_PARTS) + [rest.ceiling[p] for p in names])
    is_trunk = np.array([1.0] * len(TRUNK_PARTS) + [0.0] * len(names))

    def heights(x: np.ndarray) -> np.ndarray:
        """The bounded parts' heights ``(m, rows)`` for candidates ``x`` ``(m, n)``."""
        lows = rest.lows_on_ground(x)
        return np.stack([lows[p] for p in rows], axis=1)

    def margins(v: np.ndarray) -> np.ndarray:  # >= 0: every trunk part under t, every other under its bound
        return bound + is_trunk * v[-1] - heights(v[None, :-1])[0]

    def margins_jac(v: np.ndarray) -> np.ndarray:  # forward differences, every step in one batch
        x = np.repeat(v[None, :-1], n + 1, 0)
        x[1:] += np.eye(n) * JAC_STEP_DEG
        h = heights(x)
        return np.c_[-(h[1:] - h[0]).T / JAC_STEP_DEG, is_trunk]

    def top(x: np.ndarray) -> float:
        return float(heights(x[None])[0, : len(TRUNK_PARTS)].max())

    bounds = [(-MAX_TURN_DEG, MAX_TURN_DEG)] * n + [(AIM_CM, None)]
    best = np.zeros(n)
    for _ in range(SEARCH_STARTS):
        res = minimize(
            lambda v: v[-1] + MOVE_WEIGHT * (v[:-1] ** 2).sum(),
            np.r_[best, max(AIM_CM, top(best))],
            jac=lambda v: np.r_[2.0 * MOVE_WEIGHT * v[:-1], 1.0],
            method="SLSQP",
            bounds=bounds,
            constraints=[{"type": "ineq", "fun": margins, "jac": margins_jac}],
            options={"maxiter": SEARCH_ITERATIONS},
        )
        x = _kept_share(best, np.asarray(res.x[:-1], dtype=np.float64), heights, bound[len(TRUNK_PARTS) :])
        if top(x) >= top(best) - 0.01:
            break
        best = x
    return best


def _kept_share(best: np.ndarray, x: np.ndarray, heights: Any, bound: np.ndarray) -> np.ndarray:
    """``x``, or where it passes a bound by more than :data:`BOUND_SLACK_CM` the largest share of the move
    from ``best`` towards it that does not (in :data:`KEPT_SHARES` steps; ``best`` if none): SLSQP stopped
    on its line search past the kneeling death's hand bounds threw away a move that had brought the
    pelvis from 3.3 to 2.4 cm on the way."""
    shares = np.linspace(1.0, 0.0, KEPT_SHARES + 1)[:-1]
    cand = best[None] + shares[:, None] * (x - best)[None]
    ok = (heights(cand)[:, len(TRUNK_PARTS) :] - bound < BOUND_SLACK_CM).all(axis=1)
    return cand[int(np.argmax(ok))] if ok.any() else best


def _ease(n: int, start: int) -> np.ndarray:
    """Per frame, 0 until ``start``, easing (smoothstep) to 1 over :data:`EASE_FRAMES`."""
    u = np.clip((np.arange(n) - start) / EASE_FRAMES, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _held_feet(
    q: np.ndarray, loc: np.ndarray, figures: FigureSet, ptype: str, frames: np.ndarray
) -> tuple[str, ...]:
    """The feet (``left_foot``, ...) that come within ``NEAR_CM`` of the ground in ``frames`` while their
    knee stays off it (above ``KNEE_DOWN_CM``: a knee on the ground carries the leg, and holding its foot
    slid the knee)."""
    out = []
    for side in SIDES:
        foot = part_points(q[frames], loc[frames], figures, ptype, (f"{side}_foot",))[..., 1].min(axis=1)
        parts = tuple(f"{side}_{p}" for p in ("knee", "kneecap", "thigh"))
        knee = part_points(q[frames], loc[frames], figures, ptype, parts)[..., 1].min(axis=1)
        if foot.min() <= NEAR_CM and knee.min() > KNEE_DOWN_CM:
            out.append(f"{side}_foot")
    return tuple(out)


def _hold_feet(
    figures: FigureSet,
    ptype: str,
    before: tuple[np.ndarray, np.ndarray],
    after: tuple[np.ndarray, np.ndarray],
    feet: tuple[str, ...],
    frames: np.ndarray,
) -> np.ndarray:
    """``after``'s poses with the ``feet``' legs solved (in ``frames``) to put each foot's heel site where
    it is in ``before`` (position and turn; each a ``(poses, root globals)`` pair)."""
    kin = figures.kin[ptype]
    sites = kin.site_globals(before[0][frames], before[1][frames])
    goals = []
    for foot in feet:
        side = foot.removesuffix("_foot")
        heel = sites[:, kin.site_names.index(f"{side}_foot.heel")]
        goals.append(
            ik.Goal(f"{side}_foot.heel", heel[:, :3, 3], heel[:, :3, :3], 1.0, 2, leg(side), HOLD_TURN_CM)
        )
    poses = after[0].copy()
    poses[frames] = track_solve(
        kin, after[0][frames], goals, after[1][frames], iterations=HOLD_ITERATIONS, max_dof_step=HOLD_DOF_STEP
    )
    return poses


def _landed_arms(
    q: np.ndarray, loc: np.ndarray, figures: FigureSet, ptype: str, frames: np.ndarray
) -> dict[str, int]:
    """Per side (``left``, ``right``) whose upper arm or forearm (:data:`ARM_PARTS`) lands on the ground
    (``ARM_DOWN_CM``) within ``frames`` and lies there to the last of them: the frame it lands (the
    earlier of the two). A part already lying there at the first of ``frames`` is left to the search's
    bounds."""
    lows = part_lows(figures, ptype, q[frames], loc[frames])
    out: dict[str, int] = {}
    for part in ARM_PARTS:
        down = lows.get(part, np.full(len(frames), np.inf)) <= ARM_DOWN_CM
        up = np.flatnonzero(~down)
        if not down[-1] or not len(up):
            continue
        side = part.split("_", 1)[0]
        out[side] = min(out.get(side, len(q)), int(frames[up[-1] + 1]))
    return out


def _hold_arms(
    kin: FigureKinematics, poses: np.ndarray, locs: np.ndarray, landed: dict[str, int]
) -> np.ndarray:
    """``poses`` with each ``landed`` side's arm (clavicle to wrist) keeping from the frame it lands on
    (:func:`_landed_arms`) the angles it lands with, and its clavicle, shoulder and elbow solved to keep its
    elbow and wrist where they are as it lands, within about a centimetre (prfire2dead's DI/M16 upper arm
    still slides 1.4 cm): the slave's spine still turns there (its trunk laid onto the ground) and carried
    the shoulder 3 cm. Held only along the ground (their heights as the kept angles
    put them), the elbow went into it and the build's lift raised the whole body 0.7-0.9 cm; solved from the
    slaved pose with the elbow alone held, tracked frame after frame, the redundant arm swung its hand
    17 cm."""
    out = poses.copy()
    rows = np.arange(min(landed.values()), len(poses))
    goals = []
    for side, f in landed.items():
        chain = joint_chain(f"{side}_upper_arm.deltoid")
        for joint in chain:
            out[f:, kin.dof_slices[joint]] = poses[f, kin.dof_slices[joint]]
        sites = kin.site_globals(out[rows], locs[rows])[..., :3, 3]
        for site in (f"{side}_{s}" for s in ARM_HELD_SITES):
            at = sites[:, kin.site_names.index(site)]
            at[rows > f] = at[rows == f]
            goals.append(ik.Goal(site, at, None, (rows >= f).astype(np.float64), 1, chain[:-1]))
    out[rows], _ = ik.solve(
        kin, out[rows], goals, locs[rows], iterations=40,
        damping=2.0, rest_pose=out[rows], rest_gain=0.05, tolerance=0.05, max_dof_step=0.05,
    )  # fmt: skip
    return out


def rest_slave_trunk(
    master: Channelset,
    slave: Channelset,
    figures: FigureSet,
    feet_held: bool = False,
    slide_cm: float | None = None,
    arms_held: bool = False,
    heels_cm: float | None = None,
) -> np.ndarray:
    """Turn a dead slave's body and lumbar so its pelvis and chest or belly rest on the ground at the end
    (``slave``'s joint and body channels, in place; a clip without a ``release_frame`` is left alone); with
    ``feet_held`` a foot near the ground whose knee is up stays where it was (:func:`_hold_feet`);
    ``slide_cm``: how far a resting part's sites may move along the ground (None: :data:`SLIDE_CM`); with
    ``arms_held`` an arm part lying on the ground at the end stays where it lands (:func:`_hold_arms`).
    Returns the parameters found (degrees, in :data:`PARAMS` order)."""
    release = getattr(slave, "release_frame", None)
    if release is None:
        return np.zeros(len(PARAMS))
    q, loc, stype = played_body(slave, figures)
    n = len(q)
    rest = _Rest(figures, stype, q[-1], loc[-1], SLIDE_CM if slide_cm is None else slide_cm, heels_cm)
    w = _ease(n, max(release, n - 1 - EASE_FRAMES - END_HOLD_FRAMES))
    held = _held_feet(q, loc, figures, stype, np.flatnonzero(w > 0)) if feet_held else ()
    x = search(rest)
    if not np.any(x):
        return x
    poses, moved = q.copy(), np.tile(np.eye(4), (n, 1, 1))
    drop0 = float(rest.placed(np.zeros((1, len(PARAMS))))[2][0])  # the last frame lies on the ground: ~0
    for f in np.flatnonzero(w > 0):
        pose, at, drop = rest.placed(x[None] * w[f])
        poses[f] = q[f] + (pose[0] - q[-1])
        moved[f] = at[0] @ np.linalg.inv(loc[-1])  # the root's turn about the pivot (world) ...
        moved[f, 1, 3] += drop[0] - (1.0 - w[f]) * drop0  # ... and the drop onto the ground, eased in
    if held:
        poses = _hold_feet(figures, stype, (q, loc), (poses, moved @ loc), held, np.flatnonzero(w > 0))
    landed = _landed_arms(poses, moved @ loc, figures, stype, np.flatnonzero(w > 0)) if arms_held else {}
    if landed:
        poses = _hold_arms(figures.kin[stype], poses, moved @ loc, landed)
    write_pose(slave, figures, stype, poses, moved)
    return x
