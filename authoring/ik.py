"""Inverse kinematics for the authoring pipeline (seed 000, chapter 6: constraints, priorities, joint chains).

:func:`solve` moves a figure's DOFs so that several site goals hold at once, for one pose or a whole batch of
poses (every frame of a clip in one call). It is damped least squares with **priority levels** (Baerlocher &
Boulic 2004): the most important level is solved first and every lower level only acts in the null space of
the levels above it, so a less important goal that conflicts with a more important one cannot disturb it.
As in Jack, a larger ``priority`` number is more important (Jack's arm constraints have priority 1 over the
default 0); equal priorities are solved together as one weighted least-squares task.

* **Jacobian**: analytic. A rotational DOF turning about the world axis ``w`` through ``o`` moves a site at
  ``p`` by ``w x (p - o)`` and turns it by ``w``; a translational DOF moves it along ``w``. Axes and origins
  come from one batched FK call per iteration (the joints' site1 frames times the DOFs before the one wanted).
  A joint walked against the spanning tree (its site1 side further from the root) contributes with the
  opposite sign.
* **Joint chains**: a goal's ``joints`` are the only joints it may move (Jack's starting joint / constraint
  joint list); ``None`` means every joint between the figure root and the site.
* **Joint limits**, per level: a level's step is scaled down until no DOF leaves its range (a uniform scale
  stays in the null space above), the DOFs that reached a limit are frozen for that level and the levels
  below, and the rest of the level's error is solved again without them (Baerlocher & Boulic's clamping
  loop, done level by level so a less important goal cannot steal a DOF by driving it into a limit).
  Poses never leave the limits.
* **Unreachable goals**: damping keeps every step finite, a per-iteration cap on the task error (Jack's
  "step factor") and on each level's DOF change keep far goals from whipping the chain, and below the top
  level the damping grows with the remaining error (Levenberg-Marquardt) so a goal that cannot be met
  settles instead of oscillating. The solver stops at its best effort and reports the residuals.
* **Rest pose**: an optional secondary task pulls the DOFs towards a given pose inside the null space of all
  goals (useful to stay near an animator's key posture or a slave's copied angles).
* **Speed**: FK runs on the figure cut down to the joints between the root and the goal sites (no fingers
  when only palms matter), null spaces are kept as the levels' projected Jacobian rows (small batched
  solves, no ``n x n`` projectors, no batched eigen-solvers), and a pose stops iterating once converged or
  stalled. DOFs that move none of the goal sites are left as they are.

:func:`two_link` is the closed-form solution of a hip-knee-ankle (shoulder-elbow-wrist) chain: the middle
joint's flexion from the law of cosines about its actual axis, then the minimal rotation of the upper joint,
decomposed into its three DOF angles by :func:`decompose_rotation` (general Euler angles about arbitrary
axes, Shuster & Markley 2003).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from peabody.fk import FigureKinematics
from peabody.model import Dof, Figure, Joint, Segment, Site
from peabody.rotations import axis_angle

ROOT_DOFS: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
_CLAMP_PASSES = 6  # clamping-loop passes per step; DOFs still violating afterwards are clipped


@dataclass
class Goal:
    """A site goal: put ``site`` (``"segment.site"``) at ``target_position`` (cm, world) and optionally turn
    its frame to ``target_orientation`` (3x3 or 4x4, world).

    Targets may carry a leading batch axis matching the poses given to :func:`solve` (one target per frame);
    ``weight`` may be a scalar or one weight per pose (0 switches the goal off for that pose).
    ``orientation_weight`` says how many cm of position error one radian of orientation error is worth
    (Jack's position/orientation weight). ``target_position=None`` makes an orientation-only goal.
    ``radius`` (cm, default 0) makes the position goal a ball: a site within ``radius`` of the target counts
    as there and is not pulled further, so a secondary goal does not chase its last millimetres through a
    singular pose or round a saddle (see :mod:`~authoring.slaving`).
    """

    site: str
    target_position: Any = None
    target_orientation: Any = None
    weight: Any = 1.0
    priority: int = 0
    joints: Sequence[str] | None = None
    orientation_weight: float = 20.0
    radius: float = 0.0

    def rows(self, rows: slice | np.ndarray) -> Goal:
        """This goal for the poses ``rows`` only: per-pose targets and weights sliced, shared ones kept."""

        def pick(v: Any, ndim: int) -> Any:
            if v is None:
                return None
            a = np.asarray(v, np.float64)
            return a[rows] if a.ndim > ndim else a

        return dataclasses.replace(
            self,
            target_position=pick(self.target_position, 1),
            target_orientation=pick(self.target_orientation, 2),
            weight=pick(self.weight, 0),
        )


@dataclass
class SolveReport:
    """What :func:`solve` achieved, per pose (leading batch shape of the input) and goal (input order)."""

    position_error: np.ndarray  # (..., ngoals) cm (beyond the goal's radius); 0 for orientation-only goals
    orientation_error: np.ndarray  # (..., ngoals) rad; 0 for goals without an orientation target
    iterations: int
    converged: np.ndarray  # (...,) bool: every goal with a non-zero weight within tolerance
    root_location: np.ndarray | None = None  # (..., 4, 4) when the root was allowed to move

    @property
    def max_position_error(self) -> float:
        return float(self.position_error.max(initial=0.0))

    @property
    def max_orientation_error(self) -> float:
        return float(self.orientation_error.max(initial=0.0))


# --- small vector helpers -----------------------------------------------------------------------------------


def rotation_log(r: np.ndarray) -> np.ndarray:
    """Axis-angle vectors ``(..., 3)`` of rotations ``(..., 3, 3)`` (robust near 0 and pi)."""
    r = np.asarray(r, dtype=np.float64)
    cos = np.clip((np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    v = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    s = np.sin(angle)
    small = s < 1e-6
    scale = np.where(small, 0.5, angle / (2.0 * np.where(small, 1.0, s)))
    out = v * scale[..., None]
    near_pi = small & (angle > 1.0)
    if np.any(near_pi):  # axis from the symmetric part: R = 2 a a^T - I at pi
        sym = (r[near_pi] + np.eye(3)) / 2.0
        col = np.argmax(np.diagonal(sym, axis1=-2, axis2=-1), axis=-1)
        ax = sym[np.arange(len(col)), :, col]
        ax /= np.linalg.norm(ax, axis=-1, keepdims=True)
        out[near_pi] = ax * angle[near_pi][:, None]
    return out


def signed_angle(axis: np.ndarray, v_from: np.ndarray, v_to: np.ndarray) -> np.ndarray:
    """Angle about ``axis`` turning ``v_from`` onto ``v_to`` (both projected on the plane normal to axis)."""
    cross = np.cross(v_from, v_to)
    y = np.sum(axis * cross, axis=-1)
    x = np.sum(v_from * v_to, axis=-1) - np.sum(axis * v_from, axis=-1) * np.sum(axis * v_to, axis=-1)
    return np.arctan2(y, x)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def decompose_rotation(
    m: np.ndarray,
    axes: np.ndarray,
    hint: np.ndarray | None = None,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> np.ndarray:
    """Angles ``(..., 3)`` with ``m = R(a1, t1) @ R(a2, t2) @ R(a3, t3)`` for unit axes ``a1..a3`` given in
    the successive local frames (how a 3-DOF Peabody joint composes its DOFs).

    General Euler angles (Shuster & Markley): ``a1' m a3 = a1' R(a2, t2) a3`` fixes ``t2`` up to two roots,
    then ``t1`` and ``t3`` are the turns about ``a1`` and ``a3`` that finish the job. Of the two solutions the
    one inside ``[lower, upper]`` (if given) and nearest to ``hint`` (default 0) wins. In gimbal lock the
    split between ``t1`` and ``t3`` is arbitrary (``t3`` keeps its hint).
    """
    m = np.asarray(m, dtype=np.float64)[..., :3, :3]
    a = np.asarray(axes, dtype=np.float64).reshape(3, 3)
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    a1, a2, a3 = a
    batch = m.shape[:-2]
    h = np.zeros((*batch, 3)) if hint is None else np.broadcast_to(np.asarray(hint, np.float64), (*batch, 3))
    target = np.einsum("i,...ij,j->...", a1, m, a3)
    d12, d23, d13 = a1 @ a2, a2 @ a3, a1 @ a3
    ca = d13 - d12 * d23
    sb = a1 @ np.cross(a2, a3)
    r = np.hypot(ca, sb)
    phi = np.arctan2(sb, ca)
    ratio = np.clip((target - d12 * d23) / max(r, 1e-12), -1.0, 1.0)
    delta = np.arccos(ratio)
    candidates = []
    for t2 in (phi + delta, phi - delta):
        t2 = _wrap(h[..., 1] + _wrap(t2 - h[..., 1]))
        v = axis_angle(np.broadcast_to(a2, (*batch, 3)), t2) @ a3
        u = m @ a3
        t1 = signed_angle(a1, v, u)
        w = np.einsum("...ji,j->...i", axis_angle(np.broadcast_to(a2, (*batch, 3)), t2), a1)
        u3 = np.einsum("...ji,j->...i", m, a1)
        t3 = -signed_angle(a3, w, u3)
        t1 = h[..., 0] + _wrap(t1 - h[..., 0])
        t3 = h[..., 2] + _wrap(t3 - h[..., 2])
        candidates.append(np.stack([t1, t2, t3], axis=-1))
    c = np.stack(candidates)  # (2, ..., 3)
    cost = np.sum((c - h) ** 2, axis=-1)
    if lower is not None and upper is not None:
        lo = np.asarray(lower, np.float64)
        hi = np.asarray(upper, np.float64)
        outside = np.sum(np.maximum(lo - c, 0.0) + np.maximum(c - hi, 0.0), axis=-1)
        cost = cost + 1e3 * outside
    pick = np.argmin(cost, axis=0)
    return np.take_along_axis(c, pick[None, ..., None], axis=0)[0]


# --- per-figure tables --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _JointTable:
    name: str
    site1: int  # index of the joint's site1 in kin.site_names
    dofs: np.ndarray  # DOF indices in the pose vector, in composition order
    axes: np.ndarray  # (k, 3) local axes
    rot: np.ndarray  # (k,) bool


class _Tables:
    """What the solver precomputes per figure: joints with DOFs and, per site, the DOFs that move it."""

    def __init__(self, kin: FigureKinematics) -> None:
        self.kin = kin
        site_index = {n: i for i, n in enumerate(kin.site_names)}
        self.site_index = site_index
        self.joints: list[_JointTable] = []
        self.joint_dofs: dict[str, np.ndarray] = {}
        for name, joint in kin.figure.joints.items():
            sl = kin.dof_slices[name]
            idx = np.arange(sl.start, sl.stop, dtype=np.intp)
            self.joint_dofs[name] = idx
            if not len(idx):
                continue
            s1 = joint.site1
            key = f"{s1.segment.name}.{s1.name}" if s1.segment is not None else s1.name
            self.joints.append(
                _JointTable(
                    name,
                    site_index[key],
                    idx,
                    np.array([d.axis for d in joint.dofs], dtype=np.float64),
                    np.array([d.kind == "R" for d in joint.dofs], dtype=bool),
                )
            )
        self.rot = np.zeros(kin.ndof, dtype=bool)
        for jt in self.joints:
            self.rot[jt.dofs] = jt.rot
        # per DOF position k within its joint: which joints have one, its DOF index, its axis, the DOF before
        self._site1 = np.array([jt.site1 for jt in self.joints], dtype=np.intp)
        most = max((len(jt.dofs) for jt in self.joints), default=0)
        self._passes: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._passes_prev: list[np.ndarray] = []
        for k in range(most):
            sel = np.array([i for i, jt in enumerate(self.joints) if len(jt.dofs) > k], dtype=np.intp)
            dofs = np.array([self.joints[i].dofs[k] for i in sel], dtype=np.intp)
            axes = np.array([self.joints[i].axes[k] for i in sel], dtype=np.float64)
            self._passes.append((sel, dofs, axes))
            prev = [self.joints[i].dofs[k - 1] for i in sel] if k else []
            self._passes_prev.append(np.array(prev, dtype=np.intp))
        self._paths: dict[tuple[str, tuple[str, ...] | None], tuple[np.ndarray, np.ndarray]] = {}

    def chain(self, site: str, joints: Sequence[str] | None) -> tuple[np.ndarray, np.ndarray]:
        """DOFs moving ``site`` (only ``joints``), signed +1 where the site is on the joint's site2 side."""
        key = (site, None if joints is None else tuple(joints))
        hit = self._paths.get(key)
        if hit is not None:
            return hit
        if site not in self.site_index:
            raise KeyError(f"figure {self.kin.figure.name!r} has no site {site!r}")
        allowed = None if joints is None else set(joints)  # names checked by solve() on the whole figure
        idx: list[int] = []
        sign: list[float] = []
        for jname, forward in self.kin.joint_path(self.kin.root_name, site):
            if allowed is not None and jname not in allowed:
                continue
            d = self.joint_dofs[jname]
            idx.extend(int(i) for i in d)
            sign.extend([1.0 if forward else -1.0] * len(d))
        out = (np.array(idx, dtype=np.intp), np.array(sign, dtype=np.float64))
        self._paths[key] = out
        return out

    def axes_origins(self, q: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World axes and origins ``(B, ndof, 3)`` of every DOF, from site globals ``g`` (B, nsite, 4, 4).

        Vectorised over joints: pass ``k`` handles the k-th DOF of every joint that has one, its frame being
        the joint's site1 frame times the joint's DOFs before it."""
        b = q.shape[0]
        w = np.zeros((b, self.kin.ndof, 3))
        o = np.zeros((b, self.kin.ndof, 3))
        if not self.joints:
            return w, o
        dm = self.kin.dof_matrices(q)
        f = g[:, self._site1]  # (B, J, 4, 4)
        for k, (sel, dofs, axes) in enumerate(self._passes):
            if k:
                f[:, sel] = f[:, sel] @ dm[:, self._passes_prev[k]]
            fs = f[:, sel]
            w[:, dofs] = np.einsum("bjik,jk->bji", fs[..., :3, :3], axes)
            o[:, dofs] = fs[..., :3, 3]
        return w, o


_TABLES: dict[int, _Tables] = {}


def _tables(kin: FigureKinematics) -> _Tables:
    t = _TABLES.get(id(kin))
    if t is None or t.kin is not kin:
        t = _Tables(kin)
        _TABLES[id(kin)] = t
    return t


_REDUCED: dict[tuple[int, tuple[str, ...]], tuple[FigureKinematics, FigureKinematics, np.ndarray | None]] = {}


def _reduced(kin: FigureKinematics, sites: Sequence[str]) -> tuple[FigureKinematics, np.ndarray | None]:
    """The figure cut down to the joints between its root and ``sites`` (plus the pose-vector indices of
    their DOFs), so FK per iteration skips fingers, eyes and other branches no goal depends on; ``None``
    indices when nothing can be cut. DOFs off every goal's path are left as they are."""
    key = (id(kin), tuple(sites))
    hit = _REDUCED.get(key)
    if hit is not None and hit[0] is kin:
        return hit[1], hit[2]
    fig = kin.figure
    needed: dict[str, None] = {}
    for goal in sites:
        for jname, _ in kin.joint_path(kin.root_name, goal):
            needed[jname] = None
    if len(needed) == len(fig.joints):
        _REDUCED[key] = (kin, kin, None)
        return kin, None
    segments = {kin.root_name.partition(".")[0]} | {s.partition(".")[0] for s in sites}
    for jname in needed:
        joint = fig.joints[jname]
        for site in (joint.site1, joint.site2):
            if site.segment is not None:
                segments.add(site.segment.name)
    sub = Figure(fig.name, location=np.array(fig.location, dtype=np.float64), filename=fig.filename)
    for name, seg in fig.segments.items():
        if name in segments:
            copy = sub.add_segment(Segment(name))
            for site in seg.sites.values():
                copy.add_site(Site(site.name, np.array(site.location, dtype=np.float64)))
    idx: list[int] = []
    for jname, joint in fig.joints.items():
        if jname not in needed:
            continue
        s1, s2 = (sub.site(f"{s.segment.name}.{s.name}") for s in (joint.site1, joint.site2))  # type: ignore[union-attr]
        dofs = [Dof(d.kind, d.axis.copy(), d.lower, d.upper, d.value) for d in joint.dofs]
        sub.add_joint(Joint(jname, s1, s2, dofs, np.array(joint.displacement, dtype=np.float64)))
        sl = kin.dof_slices[jname]
        idx.extend(range(sl.start, sl.stop))
    sub.root = sub.site(kin.root_name)
    out = (FigureKinematics(sub), np.array(idx, dtype=np.intp))
    _REDUCED[key] = (kin, *out)
    return out


# --- the solver ---------------------------------------------------------------------------------------------


def _damped_pinv_apply(j: np.ndarray, r: np.ndarray, damping: Any) -> np.ndarray:
    """``J^T (J J^T + l^2 I)^-1 r`` for batches ``j`` (B, m, n), ``r`` (B, m); ``damping`` scalar or (B,)."""
    m = j.shape[1]
    lam2 = np.asarray(damping, np.float64) ** 2
    a = j @ np.swapaxes(j, 1, 2) + np.reshape(lam2, (-1, 1, 1)) * np.eye(m)
    y = np.linalg.solve(a, r[..., None])[..., 0]
    return np.einsum("bmn,bm->bn", j, y)


@dataclass
class _Prepared:
    site: int
    idx: np.ndarray
    sign: np.ndarray
    pos: np.ndarray | None  # (B, 3)
    ori: np.ndarray | None  # (B, 3, 3)
    weight: np.ndarray  # (B,)
    priority: int
    ow: float
    radius: float = 0.0


def _prepare(tab: _Tables, goals: Sequence[Goal], b: int) -> list[_Prepared]:
    out = []
    for g in goals:
        idx, sign = tab.chain(g.site, g.joints)
        pos = None
        if g.target_position is not None:
            pos = np.broadcast_to(np.asarray(g.target_position, np.float64)[..., :3], (b, 3))
        ori = None
        if g.target_orientation is not None:
            ori = np.broadcast_to(np.asarray(g.target_orientation, np.float64)[..., :3, :3], (b, 3, 3))
        if pos is None and ori is None:
            raise ValueError(f"goal on {g.site!r} has neither a position nor an orientation target")
        w = np.broadcast_to(np.asarray(g.weight, np.float64), (b,)).copy()
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"goal on {g.site!r}: weights must be finite and >= 0")
        radius = float(g.radius)
        if not (np.isfinite(radius) and radius >= 0):
            raise ValueError(f"goal on {g.site!r}: radius must be finite and >= 0")
        out.append(
            _Prepared(
                tab.site_index[g.site], idx, sign, pos, ori, w, int(g.priority), g.orientation_weight, radius
            )
        )
    return out


def _root_update(loc: np.ndarray, d: np.ndarray, root_cols: Sequence[int]) -> np.ndarray:
    """Apply a root step: world translation, then rotation about the root's own origin."""
    t = np.zeros((len(loc), 3))
    rv = np.zeros((len(loc), 3))
    for k, c in enumerate(root_cols):
        (t if c < 3 else rv)[:, c % 3] = d[:, k]
    ang = np.linalg.norm(rv, axis=-1)
    ax = rv / np.where(ang > 1e-12, ang, 1.0)[:, None]
    r = axis_angle(ax, ang)
    out = loc.copy()
    out[:, :3, :3] = r @ loc[:, :3, :3]
    out[:, :3, 3] = loc[:, :3, 3] + t
    return out


def solve(
    kin: FigureKinematics,
    pose: np.ndarray,
    goals: Sequence[Goal],
    root_location: np.ndarray | None = None,
    *,
    iterations: int = 60,
    damping: float = 0.5,
    error_damping: float = 1.0,
    tolerance: float = 0.01,
    orientation_tolerance: float = 1e-3,
    max_step: float = 15.0,
    max_dof_step: float = 0.35,
    rest_pose: np.ndarray | None = None,
    rest_gain: float = 0.0,
    stall: float = 1e-4,
    root_dofs: Sequence[str] = (),
    respect_limits: bool = True,
) -> tuple[np.ndarray, SolveReport]:
    """Move ``pose`` (``(ndof,)`` or a batch ``(..., ndof)``) so the goals hold; returns ``(pose, report)``.

    * ``root_location``: the root site's global transform (``(4, 4)`` or per pose), default the figure's
      location. ``root_dofs`` (subset of ``ROOT_DOFS``: world translations ``tx ty tz``, rotations ``rx ry
      rz`` about the root site) lets the root move too; the moved root is ``report.root_location``.
    * ``tolerance`` (cm) / ``orientation_tolerance`` (rad): a pose stops iterating when every goal with a
      non-zero weight is within them, or (best effort, not converged) once no goal's error changes by more
      than ``stall`` cm (``stall / 100`` rad) in an iteration, or after ``iterations``.
    * ``damping`` (cm/rad): the DLS damping of every level; levels below the most important one add their
      remaining error times ``error_damping`` (Levenberg-Marquardt), so goals that cannot be met settle.
    * ``max_step`` (cm) caps the task error used per iteration (the step factor); ``max_dof_step`` (rad or
      cm) caps each level's change of any DOF per iteration.
    * ``rest_pose`` with ``rest_gain`` in (0, 1]: a pull towards that pose in the null space of all goals.
    """
    q0 = np.asarray(pose, dtype=np.float64)
    if q0.shape[-1:] != (kin.ndof,):
        raise ValueError(f"expected poses with {kin.ndof} DOFs in the last axis, got shape {q0.shape}")
    for g in goals:  # unknown names are errors even where the reduced figure would not need them
        if g.site not in kin.site_names:
            raise KeyError(f"figure {kin.figure.name!r} has no site {g.site!r}")
        for j in g.joints or ():
            if j not in kin.dof_slices:
                raise KeyError(f"figure {kin.figure.name!r} has no joint {j!r}")
    options: dict[str, Any] = {
        "iterations": iterations,
        "damping": damping,
        "error_damping": error_damping,
        "tolerance": tolerance,
        "orientation_tolerance": orientation_tolerance,
        "max_step": max_step,
        "max_dof_step": max_dof_step,
        "rest_pose": rest_pose,
        "rest_gain": rest_gain,
        "stall": stall,
        "root_dofs": root_dofs,
        "respect_limits": respect_limits,
    }
    sub, idx = _reduced(kin, sorted({g.site for g in goals}))
    if idx is None:
        return _solve(kin, q0, goals, root_location, **options)
    if rest_pose is not None:
        options["rest_pose"] = np.asarray(rest_pose, np.float64)[..., idx]
    qs, report = _solve(sub, q0[..., idx], goals, root_location, **options)
    out = np.array(np.broadcast_to(q0, (*qs.shape[:-1], kin.ndof)))
    if respect_limits:
        out = np.clip(out, kin.lower, kin.upper)
    out[..., idx] = qs
    return out, report


def solve_frame(
    kin: FigureKinematics,
    start: np.ndarray,
    goals: Sequence[Goal],
    roots: np.ndarray,
    frame: int,
    iterations: int,
    max_dof_step: float,
) -> np.ndarray:
    """Frame ``frame`` of ``goals`` solved from the pose ``start`` and pulled towards it, in steps of at most
    ``max_dof_step`` rad: the building block of tracking a clip frame after frame, each frame warm-started
    from its neighbour's solution so no joint leaps to another IK branch."""
    sub = [g.rows(slice(frame, frame + 1)) for g in goals]
    q, _ = solve(
        kin,
        start[None],
        sub,
        roots[frame : frame + 1],
        iterations=iterations,
        rest_pose=start[None],
        rest_gain=0.1,
        max_dof_step=max_dof_step,
    )
    return q[0]


def _solve(
    kin: FigureKinematics,
    pose: np.ndarray,
    goals: Sequence[Goal],
    root_location: np.ndarray | None,
    *,
    iterations: int,
    damping: float,
    error_damping: float,
    tolerance: float,
    orientation_tolerance: float,
    max_step: float,
    max_dof_step: float,
    rest_pose: np.ndarray | None,
    rest_gain: float,
    stall: float,
    root_dofs: Sequence[str],
    respect_limits: bool,
) -> tuple[np.ndarray, SolveReport]:
    """:func:`solve` on a figure that holds only what the goals need (the defaults live in :func:`solve`)."""
    tab = _tables(kin)
    q0 = np.asarray(pose, dtype=np.float64)
    if q0.shape[-1:] != (kin.ndof,):
        raise ValueError(f"expected poses with {kin.ndof} DOFs in the last axis, got shape {q0.shape}")
    loc_in = kin.figure.location if root_location is None else np.asarray(root_location, np.float64)
    try:
        batch = np.broadcast_shapes(q0.shape[:-1], loc_in.shape[:-2])
    except ValueError:
        raise ValueError(f"poses {q0.shape} and root locations {loc_in.shape} do not broadcast") from None
    b = int(np.prod(batch, dtype=np.int64))
    q = np.broadcast_to(q0, (*batch, kin.ndof)).reshape(b, kin.ndof).copy()
    lo, hi = kin.lower, kin.upper
    if respect_limits:
        q = np.clip(q, lo, hi)
    loc = np.broadcast_to(loc_in, (*batch, 4, 4)).reshape(b, 4, 4).copy()
    unknown = sorted(set(root_dofs) - set(ROOT_DOFS))
    if unknown:
        raise ValueError(f"unknown root DOF {unknown[0]!r} (use {', '.join(ROOT_DOFS)})")
    root_cols = [ROOT_DOFS.index(r) for r in ROOT_DOFS if r in set(root_dofs)]
    nr = len(root_cols)
    n = kin.ndof + nr
    prepared = _prepare(tab, goals, b)
    rest = None
    if rest_pose is not None and rest_gain > 0:
        rest = np.broadcast_to(np.asarray(rest_pose, np.float64), (*batch, kin.ndof)).reshape(b, kin.ndof)
    levels = sorted({p.priority for p in prepared}, reverse=True)
    # a DOF's column only exists for goals whose chain contains it; root columns for every goal
    masks = []
    for p in prepared:
        col = np.zeros(n, dtype=bool)
        col[p.idx] = True
        col[kin.ndof :] = True
        masks.append(col)

    active_rows = np.ones(b, dtype=bool)
    prev_pos = np.full((b, len(prepared)), np.inf)
    prev_ori = np.full((b, len(prepared)), np.inf)
    it = 0
    pos_err = np.zeros((b, len(prepared)))
    ori_err = np.zeros((b, len(prepared)))
    for it in range(iterations + 1):
        rows = np.flatnonzero(active_rows)
        if not len(rows):
            break
        qb, lb = q[rows], loc[rows]
        g = kin.site_globals(qb, lb)
        e_list, j_list = [], []
        w_all, o_all = tab.axes_origins(qb, g)
        for k, p in enumerate(prepared):
            site = g[:, p.site]
            wgt = p.weight[rows]
            blocks_e, blocks_j = [], []
            if p.pos is not None:
                e = p.pos[rows] - site[:, :3, 3]
                dist = np.linalg.norm(e, axis=-1)
                if p.radius > 0:  # aim at the ball's surface: no pull inside it
                    e = e * np.maximum(0.0, 1.0 - p.radius / np.maximum(dist, 1e-12))[:, None]
                    dist = np.maximum(dist - p.radius, 0.0)
                pos_err[rows, k] = dist
                cap = np.minimum(1.0, max_step / np.maximum(dist, 1e-12))
                jp = np.zeros((len(rows), 3, n))
                pr = site[:, None, :3, 3] - o_all[:, p.idx]
                wi = w_all[:, p.idx]
                rot = tab.rot[p.idx]
                cols = np.where(rot[None, :, None], np.cross(wi, pr), wi) * p.sign[None, :, None]
                jp[:, :, p.idx] = np.swapaxes(cols, 1, 2)
                for c_i, c in enumerate(root_cols):
                    if c < 3:
                        jp[:, c, kin.ndof + c_i] = 1.0
                    else:
                        ax = np.zeros(3)
                        ax[c - 3] = 1.0
                        jp[:, :, kin.ndof + c_i] = np.cross(ax, site[:, :3, 3] - lb[:, :3, 3])
                blocks_e.append(e * (cap * wgt)[:, None])
                blocks_j.append(jp * wgt[:, None, None])
            if p.ori is not None:
                ev = rotation_log(p.ori[rows] @ np.swapaxes(site[:, :3, :3], 1, 2))
                ang = np.linalg.norm(ev, axis=-1)
                ori_err[rows, k] = ang
                cap = np.minimum(1.0, 0.5 / np.maximum(ang, 1e-12))
                jo = np.zeros((len(rows), 3, n))
                wi = w_all[:, p.idx] * tab.rot[p.idx][None, :, None] * p.sign[None, :, None]
                jo[:, :, p.idx] = np.swapaxes(wi, 1, 2)
                for c_i, c in enumerate(root_cols):
                    if c >= 3:
                        jo[:, c - 3, kin.ndof + c_i] = 1.0
                s = p.ow * wgt
                blocks_e.append(ev * (cap * s)[:, None])
                blocks_j.append(jo * s[:, None, None])
            e_list.append(np.concatenate(blocks_e, axis=1))
            j_list.append(np.concatenate(blocks_j, axis=1) * masks[k][None, None, :])
        # convergence per pose
        wmat = np.stack([p.weight[rows] for p in prepared], axis=1) if prepared else np.zeros((len(rows), 0))
        ok = np.all(
            (wmat == 0) | ((pos_err[rows] <= tolerance) & (ori_err[rows] <= orientation_tolerance)), axis=1
        )
        # best effort reached: no goal's error moved by more than a micrometre (or microradian) in a step
        change = np.maximum(
            np.abs(pos_err[rows] - prev_pos[rows]).max(axis=1, initial=0.0),
            np.abs(ori_err[rows] - prev_ori[rows]).max(axis=1, initial=0.0) * 1e2,
        )
        ok |= change < stall
        prev_pos[rows], prev_ori[rows] = pos_err[rows], ori_err[rows]
        if it == iterations:
            break
        active_rows[rows[ok]] = False
        keep = ~ok
        if not np.any(keep):
            break
        rows = rows[keep]
        qb, lb = qb[keep], lb[keep]
        e_list = [e[keep] for e in e_list]
        j_list = [j[keep] for j in j_list]
        step = _priority_step(
            e_list,
            j_list,
            prepared,
            levels,
            qb,
            lo,
            hi,
            kin.ndof,
            n,
            damping,
            error_damping,
            max_dof_step,
            respect_limits,
            None if rest is None else rest_gain * (rest[rows] - qb),
        )
        qn = qb + step[:, : kin.ndof]
        if respect_limits:
            qn = np.clip(qn, lo, hi)
        q[rows] = qn
        if nr:
            loc[rows] = _root_update(lb, step[:, kin.ndof :], root_cols)
    # final residuals for every pose
    g = kin.site_globals(q, loc)
    for k, p in enumerate(prepared):
        site = g[:, p.site]
        if p.pos is not None:
            pos_err[:, k] = np.linalg.norm(p.pos - site[:, :3, 3], axis=-1)
            if p.radius > 0:
                pos_err[:, k] = np.maximum(pos_err[:, k] - p.radius, 0.0)
        if p.ori is not None:
            ori_err[:, k] = np.linalg.norm(rotation_log(p.ori @ np.swapaxes(site[:, :3, :3], 1, 2)), axis=-1)
    wmat = np.stack([p.weight for p in prepared], axis=1) if prepared else np.zeros((b, 0))
    converged = np.all((wmat == 0) | ((pos_err <= tolerance) & (ori_err <= orientation_tolerance)), axis=1)
    report = SolveReport(
        position_error=pos_err.reshape(*batch, len(prepared)),
        orientation_error=ori_err.reshape(*batch, len(prepared)),
        iterations=it,
        converged=converged.reshape(batch),
        root_location=loc.reshape(*batch, 4, 4) if nr else None,
    )
    return q.reshape(*batch, kin.ndof), report


def _null_space(basis: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A, C)`` such that ``x - A @ (C @ x)`` projects free-DOF vectors ``x`` onto the null space of the
    more important levels, whose (projected) Jacobian rows are the columns of ``basis`` ``(B, n, r)``,
    restricted to the ``free`` DOFs: ``A = V'``, ``C = (V'^T V' + e I)^-1 V'^T`` with ``V'`` the basis without
    the frozen DOFs' rows.

    One small batched solve instead of an SVD or an ``n x n`` projector (batched LAPACK eigen-solvers are
    slow for small matrices). The ridge ``e`` (1e-8 of the mean squared row norm) leaves directions with
    singular values under 1e-4 of the typical one unprotected: they hardly move the task anyway, and this
    keeps nearly dependent goal rows from blowing up."""
    if basis.shape[2] == 0:
        return basis, np.swapaxes(basis, 1, 2)
    v = basis if free.all() else basis * free[:, :, None]
    vt = np.swapaxes(v, 1, 2)
    gram = vt @ v
    scale = np.trace(gram, axis1=1, axis2=2) / gram.shape[1]
    ridge = 1e-8 * np.maximum(scale, 1e-12)
    return v, np.linalg.solve(gram + ridge[:, None, None] * np.eye(gram.shape[1]), vt)


def _rest_step(
    rest_step: np.ndarray,
    qc: np.ndarray,
    free: np.ndarray,
    basis: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    ndof: int,
    respect_limits: bool,
) -> np.ndarray:
    """The pull towards the rest pose, projected into the goals' null space and kept inside the limits by
    a uniform scale; DOFs that would be pushed through a limit are frozen and the projection redone."""
    b, n = free.shape
    free = free.copy()
    out = np.zeros((b, n))
    for _ in range(_CLAMP_PASSES if respect_limits else 1):
        rs = np.zeros((b, n))
        rs[:, :ndof] = rest_step
        rs *= free
        a, c = _null_space(basis, free)
        if a.shape[2]:
            rs = rs - (a @ (c @ rs[:, :, None]))[:, :, 0]
        if not respect_limits:
            return rs
        s = rs[:, :ndof]
        room = np.where(s > 0, hi - qc, lo - qc)
        moving = np.abs(s) > 1e-15
        frac = np.where(moving, np.maximum(room / np.where(moving, s, 1.0), 0.0), np.inf)
        alpha = np.minimum(frac.min(axis=1, initial=np.inf), 1.0)
        out = rs * alpha[:, None]
        stuck = moving & (frac <= 1e-9)
        if not stuck.any():
            break
        free[:, :ndof] &= ~stuck
    return out


def _priority_step(
    e_list: list[np.ndarray],
    j_list: list[np.ndarray],
    prepared: list[_Prepared],
    levels: list[int],
    q: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    ndof: int,
    n: int,
    damping: float,
    error_damping: float,
    max_dof_step: float,
    respect_limits: bool,
    rest_step: np.ndarray | None,
) -> np.ndarray:
    """One prioritized DLS step with joint-limit handling; returns ``(B, n)``.

    Levels are solved from the most important down; each level only acts in the null space of the levels
    above (their projected Jacobian rows, see :func:`_null_space`; never an ``n x n`` projector). A level's
    step is scaled down until no DOF leaves its range (a uniform scale stays in the null space above), the
    DOFs that reached a limit are frozen for this and every less important level, and the rest of the
    level's error is solved again without them (Baerlocher & Boulic's clamping loop, done per level so a
    less important goal can never take a DOF away from a more important one by driving it into a limit).
    Each level's step is also capped at ``max_dof_step`` per DOF on its own, so an ill-conditioned less
    important level cannot shrink the more important levels' steps.
    """
    b = q.shape[0]
    by_level = []
    for lev in levels:
        ks = [k for k, p in enumerate(prepared) if p.priority == lev]
        by_level.append(
            (np.concatenate([e_list[k] for k in ks], 1), np.concatenate([j_list[k] for k in ks], 1))
        )
    free = np.ones((b, n), dtype=bool)
    dq = np.zeros((b, n))
    basis = np.zeros((b, n, 0))
    for level, (e, j) in enumerate(by_level):
        rows = np.arange(b)
        jh_all = np.zeros((b, j.shape[1], n))
        grow = error_damping if level > 0 else 0.0
        for _ in range(_CLAMP_PASSES if respect_limits else 1):
            fr = free[rows]
            a, c = _null_space(basis[rows], fr)
            jm = j[rows] * fr[:, None, :]
            jh = jm - (jm @ a) @ c if a.shape[2] else jm
            r = e[rows] - np.einsum("bmn,bn->bm", j[rows], dq[rows])
            # below the top level the damping grows with the level's remaining error (Levenberg-Marquardt,
            # Sugihara 2011): a less important goal that cannot be met settles instead of oscillating (its
            # oscillation would leak into the levels above at second order); a nearly met one converges fast
            lam = np.sqrt(damping**2 + grow * np.sum(r * r, axis=1))
            step = _damped_pinv_apply(jh, r, lam)
            big = np.abs(step[:, :ndof]).max(axis=1, initial=0.0)
            step *= np.minimum(1.0, max_dof_step / np.maximum(big, 1e-12))[:, None]
            jh_all[rows] = jh
            if not respect_limits:
                dq[rows] += step
                break
            s = step[:, :ndof]
            qc = q[rows] + dq[rows, :ndof]
            room = np.where(s > 0, hi - qc, lo - qc)
            moving = fr[:, :ndof] & (np.abs(s) > 1e-15)
            frac = np.where(moving, np.maximum(room / np.where(moving, s, 1.0), 0.0), np.inf)
            alpha = np.minimum(frac.min(axis=1, initial=np.inf), 1.0)
            dq[rows] += alpha[:, None] * step
            more = alpha < 1.0
            if not more.any():
                break
            hit = moving & (frac <= alpha[:, None] + 1e-12)
            rows = rows[more]
            free[rows, :ndof] &= ~hit[more]
        basis = np.concatenate([basis, np.swapaxes(jh_all, 1, 2)], axis=2)
    if rest_step is not None:
        dq = dq + _rest_step(rest_step, q + dq[:, :ndof], free, basis, lo, hi, ndof, respect_limits)
    return dq


# --- closed-form two-link chains ----------------------------------------------------------------------------


def two_link(
    kin: FigureKinematics,
    pose: np.ndarray,
    upper_joint: str,
    lower_joint: str,
    site: str,
    target: np.ndarray,
    root_location: np.ndarray | None = None,
    lower_dof: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form reach of ``site`` to ``target`` with a 3-DOF upper joint (hip, shoulder) and one DOF of a
    lower joint (knee, elbow flexion); other DOFs keep their values. Poses ``(ndof,)`` or ``(..., ndof)``.

    The lower DOF's angle solves ``|H - p(theta)| = |H - target|`` exactly about its real axis (``H`` the
    upper joint's centre), choosing the root inside the limits nearest to the current angle; the upper joint
    then takes the minimal rotation carrying the site onto the target, decomposed into its DOF angles. Out
    of reach, the chain stretches (or folds) as far as its limits allow towards the target. Returns
    ``(pose, residual_cm)``. Both joints must be walked away from the root, the upper joint purely rotational.
    """
    tab = _tables(kin)
    q0 = np.asarray(pose, dtype=np.float64)
    batch = q0.shape[:-1]
    b = int(np.prod(batch, dtype=np.int64))
    q = q0.reshape(b, kin.ndof).copy()
    loc_in = kin.figure.location if root_location is None else np.asarray(root_location, np.float64)
    loc = np.broadcast_to(loc_in, (*batch, 4, 4)).reshape(b, 4, 4)
    tgt = np.broadcast_to(np.asarray(target, np.float64)[..., :3], (*batch, 3)).reshape(b, 3)
    path = dict(kin.joint_path(kin.root_name, site))
    for jn in (upper_joint, lower_joint):
        if path.get(jn) is not True:
            raise ValueError(f"two_link: joint {jn!r} is not walked from the root towards {site!r}")
    up = next(jt for jt in tab.joints if jt.name == upper_joint)
    low = next(jt for jt in tab.joints if jt.name == lower_joint)
    if len(up.dofs) != 3 or not up.rot.all() or not low.rot[lower_dof]:
        raise ValueError("two_link needs a 3-DOF rotational upper joint and a rotational lower DOF")
    si = tab.site_index[site]
    # 1. the lower DOF from the distance to the upper joint's centre
    g = kin.site_globals(q, loc)
    w_all, o_all = tab.axes_origins(q, g)
    i = int(low.dofs[lower_dof])
    w, o = w_all[:, i], o_all[:, i]
    hpt = g[:, up.site1, :3, 3]
    p = g[:, si, :3, 3]
    hv, pv = hpt - o, p - o
    d2 = np.sum((tgt - hpt) ** 2, axis=-1)
    hw, pw = np.sum(hv * w, -1), np.sum(pv * w, -1)
    a = np.sum(hv * pv, -1) - hw * pw
    s = np.sum(hv * np.cross(w, pv), -1)
    want = (np.sum(hv * hv, -1) + np.sum(pv * pv, -1) - d2) / 2.0 - hw * pw
    r = np.hypot(a, s)
    phi = np.arctan2(s, a)
    delta = np.arccos(np.clip(want / np.maximum(r, 1e-12), -1.0, 1.0))
    cur = q[:, i]
    cands = np.stack([cur + _wrap(phi + delta), cur + _wrap(phi - delta)])  # angle = current + rotation
    lo_i, hi_i = kin.lower[i], kin.upper[i]
    outside = np.maximum(lo_i - cands, 0) + np.maximum(cands - hi_i, 0)
    cost = 1e3 * outside + np.abs(cands - cur)
    new = np.clip(np.take_along_axis(cands, np.argmin(cost, 0)[None], 0)[0], lo_i, hi_i)
    q[:, i] = new
    # 2. the upper joint's minimal rotation, in its site1 frame
    g = kin.site_globals(q, loc)
    s1 = g[:, up.site1]
    rot1 = s1[:, :3, :3]
    pl = np.einsum("bji,bj->bi", rot1, g[:, si, :3, 3] - s1[:, :3, 3])
    tl = np.einsum("bji,bj->bi", rot1, tgt - s1[:, :3, 3])
    pu = pl / np.maximum(np.linalg.norm(pl, axis=-1, keepdims=True), 1e-12)
    tu = tl / np.maximum(np.linalg.norm(tl, axis=-1, keepdims=True), 1e-12)
    axis = np.cross(pu, tu)
    sn = np.linalg.norm(axis, axis=-1)
    ang = np.arctan2(sn, np.sum(pu * tu, -1))
    axis = np.where(sn[:, None] > 1e-12, axis / np.maximum(sn, 1e-12)[:, None], np.array([1.0, 0.0, 0.0]))
    rmin = axis_angle(axis, ang)
    dm = kin.dof_matrices(q)
    d_up = dm[:, up.dofs[0], :3, :3] @ dm[:, up.dofs[1], :3, :3] @ dm[:, up.dofs[2], :3, :3]
    angles = decompose_rotation(
        rmin @ d_up, up.axes, hint=q[:, up.dofs], lower=kin.lower[up.dofs], upper=kin.upper[up.dofs]
    )
    q[:, up.dofs] = np.clip(angles, kin.lower[up.dofs], kin.upper[up.dofs])
    g = kin.site_globals(q, loc)
    res = np.linalg.norm(g[:, si, :3, 3] - tgt, axis=-1)
    return q.reshape(*batch, kin.ndof), res.reshape(batch)
