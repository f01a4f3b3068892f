"""The motion system (seed 000, chapter 5): key postures, motions over time, constraints, recording at 60 fps.

A :class:`Motion` moves one figure *from* wherever it is at its start time *to* a target over ``duration``
seconds (Jack's preaction snapshots the start, apply interpolates, postaction leaves the result in place).
Targets: a :class:`KeyPosture` (whole pose vector and figure location), a :class:`JointTarget` (some
joints), a :class:`LocationTarget` (figure location only) or a :class:`SiteTarget` (a site goal solved by IK).
The interpolation parameter is ``velocity_control(s)`` of the normalised time ``s``; site goals also get a
weight from :func:`weight_function`.

:class:`MotionScript` holds the motions of several figures (a soldier and his rifle) plus per-frame
constraint hooks (:class:`SiteConstraint` — a site on another figure's site, e.g. palms on the rifle;
:class:`PinSite` — keep a site where it was, e.g. a planted foot; :class:`Attach` — carry a figure on another
figure's site) and :meth:`MotionScript.interpolate` turns it into a
:class:`~server.motion.recording.Recording`.

Evaluation is vectorised over frames: motions are applied in start order (a later motion wins where two
drive the same DOF, as in Jack's motion list) to whole frame ranges; DOFs no motion drives keep their last
value. Hooks then run in the order added; consecutive IK hooks on one figure are solved together, every frame
of the clip in one batched :func:`authoring.ik.solve` call, pulling towards the interpolated posture
in the goals' null space so the animator's key postures survive (``MotionScript.ik_options`` go to the
solver; site-target motions come first). A hook's ``fade`` slides its goal in from, and back out to, where
the site is without it, so switching a constraint on or off never pops. Weights only matter for site goals:
posture, joint and location motions simply interpolate.

Time: seconds. Frame ``round(t * fps)`` of a motion ending at ``t`` holds its target exactly.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from authoring import ik
from peabody import quaternion
from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset, site_name


class VelocityControl(enum.Enum):
    """Jack's velocity controls: normalised time ``t`` in [0, 1] -> interpolation progress in [0, 1]."""

    CONSTANT = "constant"
    ACCELERATE = "accelerate"
    DECELERATE = "decelerate"
    EASE_IN_OUT = "easein_easeout"

    def __call__(self, t: Any) -> np.ndarray:
        return velocity_control(self, t)


class WeightFunction(enum.Enum):
    """Jack's weight functions: normalised time ``t`` -> a constraint weight in [0, weight]."""

    CONSTANT = "constant"
    DECAY = "decay"
    EASEIN_EASEOUT = "easein_easeout"


VC_CONSTANT = VelocityControl.CONSTANT
VC_ACCELERATE = VelocityControl.ACCELERATE
VC_DECELERATE = VelocityControl.DECELERATE
VC_EASEIN_EASEOUT = VelocityControl.EASE_IN_OUT
WF_CONSTANT = WeightFunction.CONSTANT
WF_DECAY = WeightFunction.DECAY
WF_EASEIN_EASEOUT = WeightFunction.EASEIN_EASEOUT


def velocity_control(kind: VelocityControl | str, t: Any) -> np.ndarray:
    """``velocitycontrol(type, t)``: constant ``t``; accelerate ``t^2``; decelerate ``1-(1-t)^2``;
    ease-in/ease-out ``(1 - cos(pi t)) / 2`` (zero speed at both ends, so chained clips meet smoothly)."""
    k = VelocityControl(kind)
    s = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    if k is VelocityControl.CONSTANT:
        return s
    if k is VelocityControl.ACCELERATE:
        return s * s
    if k is VelocityControl.DECELERATE:
        return 1.0 - (1.0 - s) ** 2
    return (1.0 - np.cos(np.pi * s)) / 2.0


def weight_function(kind: WeightFunction | str, weight: float, t: Any) -> np.ndarray:
    """``weightfunction(type, weight, t)``: constant ``weight``; decay ``weight (1 - t)`` (the constraint lets
    go as the motion ends); ease-in/ease-out ``weight (1 - cos(pi t)) / 2`` (takes hold smoothly)."""
    k = WeightFunction(kind)
    s = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    if k is WeightFunction.CONSTANT:
        return np.full_like(s, float(weight))
    if k is WeightFunction.DECAY:
        return weight * (1.0 - s)
    return weight * (1.0 - np.cos(np.pi * s)) / 2.0


# --- targets ------------------------------------------------------------------------------------------------


@dataclass
class KeyPosture:
    """A named posture of several figures: pose vector and figure location (root site global) per figure."""

    name: str
    poses: dict[str, np.ndarray] = field(default_factory=dict)
    locations: dict[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def capture(cls, name: str, figures: Sequence[Figure]) -> KeyPosture:
        """The figures' current DOF values and locations."""
        poses = {f.name: np.array([d.value for j in f.joints.values() for d in j.dofs]) for f in figures}
        return cls(name, poses, {f.name: np.array(f.location, dtype=np.float64) for f in figures})

    def with_pose(self, figure: str, pose: np.ndarray, location: np.ndarray | None = None) -> KeyPosture:
        """A copy with one figure's entry replaced."""
        poses = dict(self.poses)
        locs = dict(self.locations)
        poses[figure] = np.asarray(pose, dtype=np.float64)
        if location is not None:
            locs[figure] = np.asarray(location, dtype=np.float64)
        return KeyPosture(self.name, poses, locs)


@dataclass
class JointTarget:
    """Angles for some joints of the motion's figure (joint name -> its DOF values)."""

    angles: dict[str, Any]


@dataclass
class LocationTarget:
    """A figure location (root site global, 4x4)."""

    location: np.ndarray


@dataclass
class SiteTarget:
    """A site goal reached by IK: the goal slides from the site's place at the start to ``position`` /
    ``orientation`` (world). With ``hold`` the goal stays at the target after the motion ends."""

    site: str
    position: np.ndarray | None = None
    orientation: np.ndarray | None = None
    priority: int = 0
    joints: Sequence[str] | None = None
    hold: bool = True


Target = KeyPosture | JointTarget | LocationTarget | SiteTarget


@dataclass
class Motion:
    """One motion of one figure (``figure`` is the figure's name in the script)."""

    figure: str
    start: float
    duration: float
    target: Target
    velocity_control: VelocityControl = VelocityControl.EASE_IN_OUT
    weight_function: WeightFunction = WeightFunction.CONSTANT
    weight: float = 1.0
    name: str = ""

    def __post_init__(self) -> None:
        if (
            not (np.isfinite(self.start) and np.isfinite(self.duration))
            or self.start < 0
            or self.duration < 0
        ):
            raise ValueError(
                f"motion {self.name or self.figure!r}: start and duration must be finite and >= 0"
            )
        self.velocity_control = VelocityControl(self.velocity_control)
        self.weight_function = WeightFunction(self.weight_function)

    @property
    def end(self) -> float:
        return self.start + self.duration


# --- constraint hooks ---------------------------------------------------------------------------------------


@dataclass
class SiteConstraint:
    """Keep ``figure.site`` on ``other.other_site`` (both figures in the script) in every frame of
    ``[start, end]`` (``end=None``: to the end); with ``orientation`` the frames align too, after ``offset``
    (the site's frame relative to the other site's frame, default identity). ``fade`` (s): the goal slides
    in from (and back out to) where the site is without it over that long at each end of the window."""

    figure: str
    site: str
    other: str
    other_site: str
    start: float = 0.0
    end: float | None = None
    orientation: bool = False
    offset: np.ndarray | None = None
    weight: float = 1.0
    priority: int = 0
    joints: Sequence[str] | None = None
    orientation_weight: float = 20.0
    fade: float = 0.0


@dataclass
class PinSite:
    """Keep ``figure.site`` where it is at ``start`` (in the state before this hook) until ``end``; e.g. a
    planted foot. ``orientation`` pins its frame too; ``fade`` as for :class:`SiteConstraint`."""

    figure: str
    site: str
    start: float
    end: float
    orientation: bool = False
    weight: float = 1.0
    priority: int = 0
    joints: Sequence[str] | None = None
    orientation_weight: float = 20.0
    fade: float = 0.0


@dataclass
class Attach:
    """Carry ``figure`` on ``parent.parent_site``: its location becomes that site's frame times ``offset``
    (default: the relative placement at ``start``) in every frame of ``[start, end]``."""

    figure: str
    parent: str
    parent_site: str
    start: float = 0.0
    end: float | None = None
    offset: np.ndarray | None = None


Hook = SiteConstraint | PinSite | Attach
_IkItem = SiteConstraint | PinSite | Motion  # what one IK batch solves (Attach moves a location, no IK)


@dataclass
class ScriptFrames:
    """The evaluated script: per figure ``poses`` (nframes, ndof) and ``locations`` (nframes, 4, 4)."""

    fps: float
    times: np.ndarray
    poses: dict[str, np.ndarray]
    locations: dict[str, np.ndarray]
    reports: list[ik.SolveReport] = field(default_factory=list)

    @property
    def nframes(self) -> int:
        return len(self.times)


class MotionScript:
    """Motions and constraint hooks over several figures; ``initial`` is the posture at time 0."""

    def __init__(
        self,
        figures: Sequence[Figure],
        initial: KeyPosture | None = None,
        *,
        duration: float | None = None,
        ik_options: dict[str, Any] | None = None,
    ) -> None:
        self.figures = {f.name: f for f in figures}
        self.kinematics = {f.name: FigureKinematics(f) for f in figures}
        start = initial if initial is not None else KeyPosture.capture("initial", figures)
        self.initial = KeyPosture.capture("initial", figures)
        for name in self.figures:
            if name in start.poses:
                self.initial.poses[name] = np.asarray(start.poses[name], np.float64)
            if name in start.locations:
                self.initial.locations[name] = np.asarray(start.locations[name], np.float64)
        self.duration = duration
        self.motions: list[Motion] = []
        self.hooks: list[Hook] = []
        self.ik_options: dict[str, Any] = {"rest_gain": 0.1}
        self.ik_options.update(ik_options or {})

    # -- building -------------------------------------------------------------------------------------------
    def add(self, motion: Motion) -> Motion:
        if motion.figure not in self.figures:
            raise KeyError(f"motion on unknown figure {motion.figure!r}")
        tgt = motion.target
        if isinstance(tgt, KeyPosture) and motion.figure not in {*tgt.poses, *tgt.locations}:
            raise KeyError(f"key posture {tgt.name!r} has nothing for {motion.figure!r}")
        self.motions.append(motion)
        return motion

    def move_to(
        self,
        key: KeyPosture,
        start: float,
        duration: float,
        velocity_control: VelocityControl = VelocityControl.EASE_IN_OUT,
    ) -> list[Motion]:
        """One motion per figure of ``key`` that is in the script (e.g. soldier and rifle together)."""
        names = [n for n in self.figures if n in key.poses or n in key.locations]
        return [self.add(Motion(n, start, duration, key, velocity_control, name=key.name)) for n in names]

    def constrain(self, hook: Hook) -> Hook:
        for name in (hook.figure, getattr(hook, "other", None), getattr(hook, "parent", None)):
            if name is not None and name not in self.figures:
                raise KeyError(f"constraint on unknown figure {name!r}")
        self.hooks.append(hook)
        return hook

    @property
    def end_time(self) -> float:
        if self.duration is not None:
            return float(self.duration)
        return max((m.end for m in self.motions), default=0.0)

    # -- evaluation ---------------------------------------------------------------------------------------
    def evaluate(self, fps: float = 60.0) -> ScriptFrames:
        """Every frame ``0 .. round(end_time * fps)``: kinematic interpolation, then the hooks."""
        if not fps > 0:
            raise ValueError("fps must be > 0")
        nframes = round(self.end_time * fps) + 1
        times = np.arange(nframes) / fps
        state = _State(self, nframes, fps)
        order = sorted(range(len(self.motions)), key=lambda i: (self._frame(self.motions[i].start, fps), i))
        site_motions: list[Motion] = []
        for i in order:
            m = self.motions[i]
            if isinstance(m.target, SiteTarget):
                site_motions.append(m)
            else:
                state.apply(m)
        poses, locs = state.finish()
        frames = ScriptFrames(fps, times, poses, locs)
        # site-target motions behave like hooks that come first, in start order
        pending: list[Hook | Motion] = [*site_motions, *self.hooks]
        batch: list[_IkItem] = []
        for item in pending:
            if isinstance(item, Attach):
                self._solve(frames, batch)
                batch = []
                self._attach(frames, item)
                continue
            if batch and batch[0].figure != item.figure:
                self._solve(frames, batch)
                batch = []
            batch.append(item)
        self._solve(frames, batch)
        return frames

    def interpolate(self, fps: float = 60.0) -> Recording:
        """Jack's ``go``: evaluate every frame and record it (pose vectors, root sites, root globals)."""
        frames = self.evaluate(fps)
        rec = Recording(list(self.figures.values()))
        for name, fig in self.figures.items():
            if fig.root is None:
                raise ValueError(f"figure {name!r} has no root site")
            root = site_name(fig.root)
            p, loc = frames.poses[name], frames.locations[name]
            rec.poses[name].extend(np.asarray(p, dtype=np.float32))
            rec.roots[name].extend([root] * frames.nframes)
            rec.locations[name].extend(np.asarray(loc, dtype=np.float64))
        return rec

    def to_channelset(self, name: str, fps: float = 60.0) -> Channelset:
        """Interpolate and record every frame into a channelset (one figure channel per figure)."""
        rec = self.interpolate(fps)
        return recording_to_channelset(name, rec, 0, rec.nframes - 1, fps)

    # -- internals ----------------------------------------------------------------------------------------
    @staticmethod
    def _frame(t: float, fps: float) -> int:
        return round(t * fps)

    def _window(self, start: float, end: float | None, frames: ScriptFrames) -> tuple[int, int]:
        f0 = min(self._frame(start, frames.fps), frames.nframes - 1)
        f1 = frames.nframes - 1 if end is None else min(self._frame(end, frames.fps), frames.nframes - 1)
        return f0, max(f0, f1)

    def _attach(self, frames: ScriptFrames, hook: Attach) -> None:
        f0, f1 = self._window(hook.start, hook.end, frames)
        kp = self.kinematics[hook.parent]
        site = kp.site_globals(
            frames.poses[hook.parent][f0 : f1 + 1], frames.locations[hook.parent][f0 : f1 + 1]
        )
        g = site[:, kp.site_names.index(hook.parent_site)]
        offset = hook.offset
        if offset is None:
            offset = np.linalg.inv(g[0]) @ frames.locations[hook.figure][f0]
        frames.locations[hook.figure][f0 : f1 + 1] = g @ offset

    def _solve(self, frames: ScriptFrames, batch: Sequence[_IkItem]) -> None:
        if not batch:
            return
        name = batch[0].figure
        kin = self.kinematics[name]
        n = frames.nframes
        goals: list[ik.Goal] = []
        for item in batch:
            goal = self._goal(frames, item, n)
            if goal is not None:
                goals.append(goal)
        if not goals:
            return
        weights = np.stack([np.broadcast_to(np.asarray(g.weight, np.float64), (n,)) for g in goals])
        rows = np.flatnonzero(np.any(weights > 0, axis=0))
        if not len(rows):
            return
        sub = [g.rows(rows) for g in goals]
        pose = frames.poses[name][rows]
        opts = dict(self.ik_options)
        q, report = ik.solve(kin, pose, sub, frames.locations[name][rows], rest_pose=pose, **opts)
        frames.poses[name][rows] = q
        if report.root_location is not None:
            frames.locations[name][rows] = report.root_location
        frames.reports.append(report)

    def _goal(self, frames: ScriptFrames, item: _IkItem, n: int) -> ik.Goal | None:
        fps = frames.fps
        name = item.figure
        kin = self.kinematics[name]
        if isinstance(item, Motion):
            tgt = item.target
            assert isinstance(tgt, SiteTarget)
            f0 = min(self._frame(item.start, fps), n - 1)
            f1 = max(f0, min(self._frame(item.end, fps), n - 1))
            here = kin.site_globals(frames.poses[name][f0], frames.locations[name][f0])[
                kin.site_names.index(tgt.site)
            ]
            s = np.clip((np.arange(n) - f0) / max(f1 - f0, 1), 0.0, 1.0)
            if f1 == f0:
                s = (np.arange(n) >= f0).astype(np.float64)
            u = item.velocity_control(s)
            w = weight_function(item.weight_function, item.weight, s)
            live = (np.arange(n) >= f0) & ((np.arange(n) <= f1) | tgt.hold)
            w = np.where(live, w, 0.0)
            pos = None
            if tgt.position is not None:
                p1 = np.asarray(tgt.position, np.float64)[:3]
                pos = here[:3, 3] + u[:, None] * (p1 - here[:3, 3])
            ori = None
            if tgt.orientation is not None:
                q0 = quaternion.from_matrix(here[None, :3, :3])[0]
                q1 = quaternion.from_matrix(np.asarray(tgt.orientation, np.float64)[None, :3, :3])[0]
                ori = quaternion.to_transform(np.zeros((n, 3)), _slerp(q0, q1, u))[:, :3, :3]
            return ik.Goal(tgt.site, pos, ori, w, tgt.priority, tgt.joints)
        f0, f1 = self._window(item.start, item.end, frames)
        w = np.zeros(n)
        w[f0 : f1 + 1] = item.weight
        if isinstance(item, PinSite):
            g0 = kin.site_globals(frames.poses[name][f0], frames.locations[name][f0])[
                kin.site_names.index(item.site)
            ]
            t = np.broadcast_to(g0, (n, 4, 4))
        else:
            ko = self.kinematics[item.other]
            g = ko.site_globals(frames.poses[item.other], frames.locations[item.other])
            t = g[:, ko.site_names.index(item.other_site)]
            if item.offset is not None:
                t = t @ item.offset
        if item.fade > 0:  # slide the goal in from / out to the site's place without this hook
            here = kin.site_globals(frames.poses[name], frames.locations[name])[
                :, kin.site_names.index(item.site)
            ]
            k = np.arange(n)
            span = max(item.fade * fps, 1e-9)
            f = velocity_control(VelocityControl.EASE_IN_OUT, np.minimum((k - f0) / span, (f1 - k) / span))
            pos = here[:, :3, 3] + f[:, None] * (t[:, :3, 3] - here[:, :3, 3])
            qa = quaternion.from_matrix(here[:, :3, :3])
            qb = quaternion.from_matrix(t[:, :3, :3])
            rot = quaternion.to_transform(pos, quaternion.slerp(qa, qb, f))
            t = rot
        ori = t[:, :3, :3] if item.orientation else None
        return ik.Goal(item.site, t[:, :3, 3], ori, w, item.priority, item.joints, item.orientation_weight)


def _slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    q1 = q1 if float(np.dot(q0, q1)) >= 0 else -q1
    return quaternion.slerp(np.broadcast_to(q0, (len(u), 4)), np.broadcast_to(q1, (len(u), 4)), u)


class _State:
    """Written values per figure over all frames; unwritten frames hold the last written value."""

    def __init__(self, script: MotionScript, nframes: int, fps: float) -> None:
        self.script = script
        self.n = nframes
        self.fps = fps
        self.values: dict[str, np.ndarray] = {}
        self.written: dict[str, np.ndarray] = {}
        self.pos: dict[str, np.ndarray] = {}
        self.quat: dict[str, np.ndarray] = {}
        self.loc_written: dict[str, np.ndarray] = {}
        for name, kin in script.kinematics.items():
            self.values[name] = np.zeros((nframes, kin.ndof))
            self.written[name] = np.zeros((nframes, kin.ndof), dtype=bool)
            self.pos[name] = np.zeros((nframes, 3))
            self.quat[name] = np.zeros((nframes, 4))
            self.loc_written[name] = np.zeros(nframes, dtype=bool)

    def _last(self, values: np.ndarray, written: np.ndarray, f: int, initial: np.ndarray) -> np.ndarray:
        """Per column, the last written value at a frame <= f, else ``initial``."""
        w = written[: f + 1]
        if not len(w):
            return initial.copy()
        rev = w[::-1]
        has = rev.any(axis=0)
        last = f - np.argmax(rev, axis=0)
        cols = np.arange(values.shape[1])
        return np.where(has, values[last, cols], initial)

    def apply(self, m: Motion) -> None:
        script = self.script
        name = m.figure
        kin = script.kinematics[name]
        f0 = min(round(m.start * self.fps), self.n - 1)
        f1 = max(f0, min(round(m.end * self.fps), self.n - 1))
        frames = np.arange(f0, f1 + 1)
        s = (frames - f0) / (f1 - f0) if f1 > f0 else np.ones(1)
        u = m.velocity_control(s)[:, None]
        target = m.target
        goal_pose: np.ndarray | None = None
        dofs = np.arange(0)
        goal_loc: np.ndarray | None = None
        if isinstance(target, KeyPosture):
            if name in target.poses:
                goal_pose = np.asarray(target.poses[name], np.float64).reshape(kin.ndof)
                dofs = np.arange(kin.ndof)
            goal_loc = target.locations.get(name)
        elif isinstance(target, JointTarget):
            idx: list[int] = []
            vals: list[float] = []
            for jname, ang in target.angles.items():
                if jname not in kin.dof_slices:
                    raise KeyError(f"figure {name!r} has no joint {jname!r}")
                sl = kin.dof_slices[jname]
                a = np.atleast_1d(np.asarray(ang, np.float64))
                if a.shape != (sl.stop - sl.start,):
                    raise ValueError(f"joint {jname!r} takes {sl.stop - sl.start} values, got {a.shape}")
                idx.extend(range(sl.start, sl.stop))
                vals.extend(a.tolist())
            dofs = np.array(idx, dtype=np.intp)
            goal_pose = np.zeros(kin.ndof)
            goal_pose[dofs] = vals
        elif isinstance(target, LocationTarget):
            goal_loc = target.location
        if goal_pose is not None and len(dofs):
            init = script.initial.poses[name]
            snap = self._last(self.values[name], self.written[name], f0, init)[dofs]
            self.values[name][f0 : f1 + 1, dofs] = snap + u * (goal_pose[dofs] - snap)
            self.written[name][f0 : f1 + 1, dofs] = True
        if goal_loc is not None:
            init_loc = script.initial.locations[name]
            init7 = np.concatenate([init_loc[:3, 3], quaternion.from_matrix(init_loc[None, :3, :3])[0]])
            both = np.concatenate([self.pos[name], self.quat[name]], axis=1)
            wr = np.repeat(self.loc_written[name][:, None], 7, axis=1)
            snap7 = self._last(both, wr, f0, init7)
            g = np.asarray(goal_loc, np.float64)
            q1 = quaternion.from_matrix(g[None, :3, :3])[0]
            self.pos[name][frames] = snap7[:3] + u * (g[:3, 3] - snap7[:3])
            self.quat[name][frames] = _slerp(snap7[3:] / np.linalg.norm(snap7[3:]), q1, u[:, 0])
            self.loc_written[name][frames] = True

    def finish(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        poses: dict[str, np.ndarray] = {}
        locs: dict[str, np.ndarray] = {}
        for name in self.script.figures:
            poses[name] = _forward_fill(
                self.values[name], self.written[name], self.script.initial.poses[name]
            )
            init_loc = self.script.initial.locations[name]
            init7 = np.concatenate([init_loc[:3, 3], quaternion.from_matrix(init_loc[None, :3, :3])[0]])
            both = np.concatenate([self.pos[name], self.quat[name]], axis=1)
            wr = np.repeat(self.loc_written[name][:, None], 7, axis=1)
            filled = _forward_fill(both, wr, init7)
            quat = filled[:, 3:] / np.linalg.norm(filled[:, 3:], axis=1, keepdims=True)
            locs[name] = quaternion.to_transform(filled[:, :3], quat)
        return poses, locs


def _forward_fill(values: np.ndarray, written: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """Unwritten entries take the last written value above them in their column (else ``initial``)."""
    n = len(values)
    idx = np.where(written, np.arange(n)[:, None], -1)
    np.maximum.accumulate(idx, axis=0, out=idx)
    cols = np.arange(values.shape[1])
    out = np.where(idx >= 0, values[np.maximum(idx, 0), cols], initial[None, :])
    return out
