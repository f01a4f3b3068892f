"""Slaving and re-recording (seed 002, 3.4.4): drive the low-resolution DI.fig from a soldier.fig master.

Per frame (all frames of a clip at once):

1. **Copy** the master's joint angles to the slave's joints of the same name (legs, arms, clavicles, neck,
   head; the slave's ``eyes`` take the master's ``left_eye``).
2. **Blend the spine**: the master's ``waist`` + 17 vertebral joints are folded onto the slave's torso joints
   by matching segment orientations — slave ``waist`` turns ``lumbar`` like the master's ``l3`` (waist, vl5,
   vl4), ``belly`` turns ``middle_torso`` like ``t12`` (vl3, vl2, vl1), ``upper_spine`` turns ``upper_torso``
   like the master's (vt12 .. vt1); each composed rotation is decomposed into the slave joint's DOF angles
   (:func:`authoring.ik.decompose_rotation`). ``spine_compression`` starts at 0.
3. **Solve the constraint table** (:data:`SLAVE_CONSTRAINTS`) with the palm centres at the highest priority,
   so that when not every site can match the hands stay on the gun.
4. **Make the clip temporally coherent** (:meth:`MasterSlavePair.slave_clip`, used by the re-recording):
   a frame solved alone resolves the chains' redundancy wherever its iterations stop, so the slave's offset
   from the copied angles is smoothed over the clip (the copied arm angles a little too) and the goals are
   tracked from there frame after frame, each frame warm-started from its neighbour's solution; the first
   and last frames stay the frames solved alone, so clips meeting at a posture node agree. A frame solved
   alone is polished by the tracking's own small-step solve (:meth:`MasterSlavePair._polish`), so the
   tracks leave their end frames on the same branch. Where an arm still leaps near its shoulder's pole and
   the master's does not, it is eased (:mod:`~authoring.slave_leaps`) and its palms put back.

The sight and elbow goals are balls (:data:`GOAL_RADIUS`, ``ik.Goal.radius``): within 0.9 cm of the master's
site they count as met. Chased to the millimetre they made the slave pop: prone with the neck at its
extension limit the last 0.75 cm of sight could only be had by bending and twisting the neck 14/21 degrees,
to either side (a saddle), and the left shoulder's Euler angles swung round their pole when the arm passed
90 degrees while falling.

The seed's joint chains are kept except that the palm goals may also turn the shoulder: at the highest
priority they must be able to win, and the elbow goals (shoulder chain) then act in their null space — the
seed's stated intent. Every goal pulls towards the copied angles in its null space, so unconstrained DOFs
keep the master's values.

``slave_parameters("yes","yes","yes","yes",0.50,"yes",0.50,"yes","yes")`` — the seed shows the call but not
its meaning; our reading, in order: copy joint angles, blend the spine, match the torso (DI_belly, DI_torso),
match the sight, torso/sight goal weight, match the palms, elbow goal weight, match the elbows, palms at the
highest priority. :func:`reslave_channelset` is the re-recording: play a soldier channelset on the master
(:func:`create_channelset_motion`), slave every frame, record ``DI`` plus the untouched rifle channel — or,
given a rifle figure of the slave's own and its placements (the M16 library,
:mod:`~authoring.rifle_swap`), the palms on that rifle's grip and handguard (:data:`RIFLE_HOLDS`, the
elbows following half their move) and its channel in place of the master's rifle.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from authoring import ik
from authoring.signal_shaping import gaussian, smoothstep
from authoring.slave_leaps import ease_leaps
from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.binding import bind_channelset, protofiletype
from server.motion.channelset import Channelset, FigureTrack, JointTrack, make_channelset
from server.motion.errors import ChannelsetError
from server.motion.recording import Recording, recording_to_channelset, site_name


@dataclass(frozen=True)
class SlaveConstraint:
    """One row of the seed's table: slave end effector, master goal site, slave joint chain."""

    name: str
    slave_site: str
    master_site: str
    joints: tuple[str, ...]
    group: str  # "torso", "sight", "palm", "elbow"


SLAVE_CONSTRAINTS: tuple[SlaveConstraint, ...] = (
    SlaveConstraint(
        "DI_belly", "middle_torso.upper_torso", "t12.DI_middletarget", ("waist", "belly"), "torso"
    ),
    SlaveConstraint(
        "DI_torso",
        "upper_torso.distal",
        "upper_torso.distal",
        ("belly", "spine_compression", "upper_spine"),
        "torso",
    ),
    SlaveConstraint("DI_sight", "bottom_head.sight", "bottom_head.sight", ("neck", "head"), "sight"),
    SlaveConstraint(
        "DI_leftpalm",
        "left_palm.palmcenter",
        "left_palm.palmcenter",
        ("left_clavicle", "left_shoulder", "left_elbow", "left_wrist"),
        "palm",
    ),
    SlaveConstraint(
        "DI_rightpalm",
        "right_palm.palmcenter",
        "right_palm.palmcenter",
        ("right_clavicle", "right_shoulder", "right_elbow", "right_wrist"),
        "palm",
    ),
    SlaveConstraint(
        "DI_leftelbow",
        "left_upper_arm.distal",
        "left_upper_arm.distal",
        ("left_clavicle", "left_shoulder"),
        "elbow",
    ),
    SlaveConstraint(
        "DI_rightelbow",
        "right_upper_arm.distal",
        "right_upper_arm.distal",
        ("right_clavicle", "right_shoulder"),
        "elbow",
    ),
)

# slave torso joint -> (master segment below the folded joints, master segment above them)
SPINE_BLEND: dict[str, tuple[str, str]] = {
    "waist": ("lower_torso", "l3"),
    "belly": ("l3", "t12"),
    "upper_spine": ("t12", "upper_torso"),
}
NAME_MAP: dict[str, str] = {"eyes": "left_eye"}  # slave joint -> master joint where the names differ
# cm: how close a slave site must come to the master's for its goal to count as met (ik.Goal.radius). The
# sight and elbows are secondary: chasing their last centimetre twists the neck round a saddle (prone, neck
# at its extension limit) or swings the shoulder's Euler angles round their pole (arm raised 90 degrees).
GOAL_RADIUS: dict[str, float] = {"torso": 0.0, "sight": 0.9, "palm": 0.0, "elbow": 0.9}
# slave palm -> the rifle site it holds, when the slave holds a rifle of its own (the M16 library)
RIFLE_HOLDS: dict[str, str] = {
    "right_palm.palmcenter": "rifle.grip",
    "left_palm.palmcenter": "rifle.handguard",
}
ELBOW_FOLLOW = 0.5  # an elbow goal moves by this much of its palm's move onto another rifle's site
SMOOTH_SIGMA_FRAMES = 3.0  # Gaussian smoothing of the slave's offset from the copied angles over a clip
SMOOTH_MAX_DOF_STEP = 0.05  # rad per iteration of the re-solve after smoothing: stays on its branch
COPY_SIGMA_FRAMES = 1.0  # Gaussian smoothing of the copied arm angles before the tracking
TRACK_ITERATIONS = 12  # per frame of the frame-after-frame tracking of the smoothed clip
TRACK_SETTLE_ITERATIONS = 20  # the forward and backward tracks' blend put back on the goals
# passes of the tracking's own solve (TRACK_ITERATIONS small steps each) that polish a lone solve: stopped by
# its 80 iterations with a palm still 3-4 mm off (an elbow goal out of reach pulling against it), a clip's end
# frame left the tracks' first step to finish the job (prone: 11-20 degrees of wrist in one frame). The out of
# reach elbow goal keeps drifting the arm in the palms' null space, with a hop now and then (prone: 3.5 deg
# at the 4th pass); after 8 passes a pass moves it < 0.2 degrees
POLISH_PASSES = 8
# the arms eased where they leap and the master's do not (slave_leaps), and the palms' solve after that
ARM_CHAINS = tuple(
    tuple(f"{side}_{j}" for j in ("clavicle", "shoulder", "elbow", "wrist")) for side in ("left", "right")
)
EASE_ITERATIONS, EASE_DOF_STEP, EASE_REST_GAIN, EASE_DAMPING = 60, 0.01, 0.5, 3.0
START_EASE_FRAMES = 12  # a death's solved offset from the copied angles eased in over its first 0.2 s


@dataclass
class SlaveParameters:
    """What the slaving does; see the module docstring for the reading of the seed's 9 arguments."""

    copy_angles: bool = True
    blend_spine: bool = True
    match_torso: bool = True
    match_sight: bool = True
    torso_weight: float = 0.5
    match_palms: bool = True
    elbow_weight: float = 0.5
    match_elbows: bool = True
    palm_priority: bool = True


def _yes(v: Any, what: str) -> bool:
    if isinstance(v, bool):
        return v
    s = str(v).strip().lower()
    if s in ("yes", "y", "true", "on", "1"):
        return True
    if s in ("no", "n", "false", "off", "0"):
        return False
    raise ValueError(f'slave_parameters: {what} must be "yes" or "no", not {v!r}')


def slave_parameters(*args: Any) -> SlaveParameters:
    """Parse the seed's 9-argument form ``("yes","yes","yes","yes",0.50,"yes",0.50,"yes","yes")``."""
    names = [f.name for f in dataclasses.fields(SlaveParameters)]
    if len(args) != len(names):
        raise ValueError(
            f"slave_parameters takes {len(names)} arguments ({', '.join(names)}), got {len(args)}"
        )
    values: dict[str, Any] = {}
    for name, v in zip(names, args, strict=True):
        if name.endswith("weight"):
            w = float(v)
            if not (np.isfinite(w) and w > 0):
                raise ValueError(f"slave_parameters: {name} must be a positive number, not {v!r}")
            values[name] = w
        else:
            values[name] = _yes(v, name)
    return SlaveParameters(**values)


@dataclass
class MasterSlavePair:
    """A soldier.fig master, a DI.fig slave and (optionally) the rifle they carry."""

    master: Figure
    slave: Figure
    rifle: Figure | None = None
    parameters: SlaveParameters = field(default_factory=SlaveParameters)
    on: bool = True
    ik_options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.master_kin = FigureKinematics(self.master)
        self.slave_kin = FigureKinematics(self.slave)
        mk, sk = self.master_kin, self.slave_kin
        src: list[int] = []
        dst: list[int] = []
        for jname, sl in sk.dof_slices.items():
            mname = NAME_MAP.get(jname, jname)
            msl = mk.dof_slices.get(mname)
            if jname in SPINE_BLEND or msl is None or sl.stop - sl.start != msl.stop - msl.start:
                continue
            src.extend(range(msl.start, msl.stop))
            dst.extend(range(sl.start, sl.stop))
        self._src = np.array(src, dtype=np.intp)
        self._dst = np.array(dst, dtype=np.intp)
        self._spine = [
            (j, mk.segment_names.index(a), mk.segment_names.index(b))
            for j, (a, b) in SPINE_BLEND.items()
            if j in sk.dof_slices and sk.dof_slices[j].stop - sk.dof_slices[j].start == 3
        ]
        if self.slave.root is None or self.master.root is None:
            raise ValueError("master and slave need root sites")
        self._slave_root = site_name(self.slave.root)
        if self._slave_root not in mk.site_names:
            raise ValueError(f"master has no site {self._slave_root!r} to place the slave's root on")
        for c in SLAVE_CONSTRAINTS:
            if c.slave_site not in sk.site_names or c.master_site not in mk.site_names:
                raise ValueError(
                    f"{c.name}: site missing ({c.slave_site} on slave, {c.master_site} on master)"
                )

    def slave_parameters(self, *args: Any) -> SlaveParameters:
        """Jack's ``slave_parameters`` on this pair (9 arguments, see :func:`slave_parameters`)."""
        self.parameters = slave_parameters(*args)
        return self.parameters

    def turn_slave_on(self) -> None:
        self.on = True

    def turn_slave_off(self) -> None:
        self.on = False

    # -- slaving ----------------------------------------------------------------------------------------
    def copy_pose(self, master_pose: np.ndarray, master_globals: np.ndarray) -> np.ndarray:
        """Steps 1-2: the slave's starting pose ``(..., ndof)`` from master poses and segment globals."""
        sk = self.slave_kin
        batch = master_pose.shape[:-1]
        out = np.broadcast_to(sk.neutral_pose(), (*batch, sk.ndof)).copy()
        if self.parameters.copy_angles:
            out[..., self._dst] = master_pose[..., self._src]
        if self.parameters.blend_spine:
            for jname, lo_seg, hi_seg in self._spine:
                rel = (
                    np.swapaxes(master_globals[..., lo_seg, :3, :3], -1, -2)
                    @ master_globals[..., hi_seg, :3, :3]
                )
                sl = sk.dof_slices[jname]
                joint = self.slave.joints[jname]
                axes = np.array([d.axis for d in joint.dofs])
                ang = ik.decompose_rotation(rel, axes, lower=sk.lower[sl], upper=sk.upper[sl])
                out[..., sl] = ang
            if "spine_compression" in sk.dof_slices:
                out[..., sk.dof_slices["spine_compression"]] = 0.0
        return np.clip(out, sk.lower, sk.upper)

    def goals(
        self, master_sites: np.ndarray, *, targets: Mapping[str, np.ndarray] | None = None
    ) -> list[ik.Goal]:
        """Step 3's goals from the master's site globals ``(..., nsite, 4, 4)``; ``targets`` (slave site ->
        positions ``(..., 3)``) sends those sites there instead of to the master's sites."""
        p = self.parameters
        mk = self.master_kin
        on = {"torso": p.match_torso, "sight": p.match_sight, "palm": p.match_palms, "elbow": p.match_elbows}
        weight = {"torso": p.torso_weight, "sight": p.torso_weight, "palm": 1.0, "elbow": p.elbow_weight}
        out = []
        for c in SLAVE_CONSTRAINTS:
            if not on[c.group]:
                continue
            target = master_sites[..., mk.site_names.index(c.master_site), :3, 3]
            if targets is not None and c.slave_site in targets:
                target = np.asarray(targets[c.slave_site], np.float64)
            priority = 2 if (c.group == "palm" and p.palm_priority) else 1
            out.append(
                ik.Goal(
                    c.slave_site,
                    target,
                    None,
                    weight[c.group],
                    priority,
                    c.joints,
                    radius=GOAL_RADIUS[c.group],
                )
            )
        return out

    def slave_pose(
        self,
        master_pose: np.ndarray,
        master_location: np.ndarray | None = None,
        release_frame: int | None = None,
        *,
        targets: Mapping[str, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(slave_pose, slave_location)`` for master poses ``(ndof,)`` or ``(..., ndof)`` and the master's
        root site globals (default: the master figure's location). The slave's root site is put where the
        master's site of the same name is."""
        mk, sk = self.master_kin, self.slave_kin
        q = np.asarray(master_pose, dtype=np.float64)
        loc = self.master.location if master_location is None else np.asarray(master_location, np.float64)
        batch = np.broadcast_shapes(q.shape[:-1], loc.shape[:-2])
        q = np.broadcast_to(q, (*batch, mk.ndof))
        loc = np.broadcast_to(loc, (*batch, 4, 4))
        segs = mk.segment_globals(q, loc)
        sites = mk.site_globals(q, loc)
        slave_loc = sites[..., mk.site_names.index(self._slave_root), :, :].copy()
        start = self.copy_pose(q, segs)
        goals = self.goals(sites, targets=targets)
        if not goals:
            return start, slave_loc
        opts: dict[str, Any] = {"iterations": 80, "rest_gain": 0.1, "tolerance": 0.02}
        opts.update(self.ik_options)
        pose, self.last_report = ik.solve(sk, start, goals, slave_loc, rest_pose=start, **opts)
        return _let_go(self._polish(pose, goals, slave_loc), start, release_frame), slave_loc

    def slave_clip(
        self,
        master_poses: np.ndarray,
        master_locations: np.ndarray,
        release_frame: int | None = None,
        *,
        targets: Mapping[str, np.ndarray] | None = None,
        let_go_in_place: bool = False,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`slave_pose` over the frames ``(n, ndof)`` of a clip, made temporally coherent.

        Each frame solved alone resolves the chains' redundancy (clavicle against shoulder, the arm's twist)
        wherever its iterations happen to stop, so neighbouring frames can differ by tens of degrees. So the
        slave's offset from the copied angles is smoothed over the clip (Gaussian, ``SMOOTH_SIGMA_FRAMES``),
        tapered towards the first and the last frame's offset near each end (not to each frame's own: near
        an end it could sit on another branch than the end's and pop as the clip leaves or reaches its
        posture), the copied angles of the goals' chains smoothed a little (``COPY_SIGMA_FRAMES``: a master's
        one-frame turn of a redundant DOF is not copied as a pop), and the goals tracked from there frame
        after frame (:meth:`_track`, small steps of ``SMOOTH_MAX_DOF_STEP``: solved each frame alone the
        shoulder's Euler angles jumped 20-28 degrees between frames near their pole while crawling), pulled
        towards the smoothed pose. DOFs no goal moves keep the master's
        angles; the first and last frames stay exactly :meth:`slave_pose`'s (a frame's solution alone), so
        every clip meeting at a posture node is slaved to the same pose there. ``let_go_in_place``: from
        ``release_frame`` on the arms blend from their pose as the hands let go into the copied angles, not
        from their goals tracked on (:func:`_let_go_in_place`)."""
        mk, sk = self.master_kin, self.slave_kin
        q = np.asarray(master_poses, dtype=np.float64)
        loc = np.asarray(master_locations, dtype=np.float64)
        pose, slave_loc = self.slave_pose(q, loc, release_frame, targets=targets)
        n = len(pose)
        goals = self.goals(mk.site_globals(q, loc), targets=targets)
        if n < 3 or not goals:
            return pose, slave_loc
        start = self.copy_pose(q, mk.segment_globals(q, loc))
        offset = pose - start
        half = int(np.ceil(3.0 * SMOOTH_SIGMA_FRAMES))
        smooth = gaussian(offset, SMOOTH_SIGMA_FRAMES)
        frames = np.arange(n)
        taper = np.minimum(1.0, np.minimum(frames, frames[::-1]) / half)[:, None]
        ends = np.where(frames[:, None] < n / 2, offset[:1], offset[-1:])  # each half leans on its end
        # a redundant arm DOF that the master turns by many degrees in one frame need not pop on the slave
        # too: the copied angles of the goals' chains are smoothed a little (the palms are solved again)
        arms = np.zeros(sk.ndof, dtype=bool)
        for g in goals:
            for j in g.joints or ():
                arms[sk.dof_slices[j]] = True
        base = start.copy()
        base[:, arms] += taper * (gaussian(start[:, arms], COPY_SIGMA_FRAMES) - start[:, arms])
        blend = sk.clamp(base + ends + taper * (smooth - ends))
        out = self._track(blend, goals, slave_loc, pose[0], pose[-1])
        if release_frame is None:  # (a death's arms are flung, then blended into the copied angles)
            out = self._ease_leaps(out, start, goals, slave_loc)
        out = _let_go(out, start, release_frame)
        if let_go_in_place and release_frame is not None:
            limbs = np.zeros(sk.ndof, dtype=bool)
            for j in (j for chain in ARM_CHAINS for j in chain if j in sk.dof_slices):
                limbs[sk.dof_slices[j]] = True
            out = _let_go_in_place(out, start, release_frame, limbs)
        out[[0, -1]] = pose[[0, -1]]
        if release_frame is not None:  # (a death starts from rest: the master's body is still there)
            out = self._ease_start(out, start, goals, slave_loc, release_frame)
        return out, slave_loc

    def _ease_start(
        self, poses: np.ndarray, copied: np.ndarray, goals: list[ik.Goal], roots: np.ndarray, release: int
    ) -> np.ndarray:
        """A death's first :data:`START_EASE_FRAMES` frames: the tracks' offset from the ``copied`` angles
        eased in from the first frame's (smoothstep; the master's own motion kept as it is), the palms put
        back on their goals (:meth:`_palms_back`) while the hands still hold the rifle (before frame
        ``release``: after it, :func:`_let_go` fades them into the copied angles). The tracks leave the
        lone-solved first frame at once: an elbow goal out of reach drifts the arm in the palm's null space
        at every solve (8 polish passes still turn the prone deaths' wrist 0.08 rad, the track's first step
        0.063 rad: the DI's fingertips 1.1 cm in one frame, 0.63 m/s where the master starts at 0.46)."""
        m = min(START_EASE_FRAMES, len(poses) // 2)
        u = np.arange(1, m)[:, None] / m
        eased = poses.copy()  # (the first frame stays slave_pose's exactly)
        offset = poses[:m] - copied[:m]
        eased[1:m] = copied[1:m] + offset[0] + smoothstep(u) * (offset[1:] - offset[0])
        return self._palms_back(eased, np.arange(1, min(m, release)), goals, roots)

    def _palms_back(
        self, poses: np.ndarray, rows: np.ndarray, goals: list[ik.Goal], roots: np.ndarray
    ) -> np.ndarray:
        """``poses`` with the palms of ``rows`` put back on their goals in small, heavily damped steps held
        near the given poses (the elbow goals, often out of reach, would keep pulling the arms)."""
        held = [g.rows(rows) for g in goals if g.site in RIFLE_HOLDS]
        opts: dict[str, Any] = {"tolerance": 0.02}
        opts.update(self.ik_options)
        opts.update(iterations=EASE_ITERATIONS, max_dof_step=EASE_DOF_STEP, rest_gain=EASE_REST_GAIN)
        opts.update(damping=EASE_DAMPING)
        out = poses.copy()
        out[rows], _ = ik.solve(self.slave_kin, poses[rows], held, roots[rows], rest_pose=poses[rows], **opts)
        return out

    def _ease_leaps(
        self, poses: np.ndarray, copied: np.ndarray, goals: list[ik.Goal], roots: np.ndarray
    ) -> np.ndarray:
        """The arms eased through the frames where they leap and the master's do not
        (:mod:`~authoring.slave_leaps`: near their shoulders' pole), and the palms of the eased frames put
        back in small, heavily damped steps held near the eased pose (undamped, the shoulder's angles near
        its pole, which turn the arm least, leap again)."""
        eased = ease_leaps(self.slave_kin, poses, copied, ARM_CHAINS)
        rows = np.flatnonzero(np.any(eased != poses, axis=1))
        if not len(rows):
            return poses
        return self._palms_back(eased, rows, goals, roots)

    def _polish(self, poses: np.ndarray, goals: list[ik.Goal], roots: np.ndarray) -> np.ndarray:
        """Lone solves ``poses`` ``(..., ndof)`` carried on by the tracking's own small-step solve until it
        leaves them (nearly) where they are: a clip's tracks start from its end frames, and an end their first
        step still had to finish put the frame next to it on another branch (a wrist 11-20 degrees away).
        A frame's polished pose depends on that frame alone, so clips meeting at a posture node agree."""
        opts: dict[str, Any] = {"rest_gain": 0.1, "tolerance": 0.02}
        opts.update(self.ik_options)
        opts.update(iterations=TRACK_ITERATIONS, max_dof_step=SMOOTH_MAX_DOF_STEP)
        out = poses
        for _ in range(POLISH_PASSES):
            out, _ = ik.solve(self.slave_kin, out, goals, roots, rest_pose=out, **opts)
        return out

    def _track(
        self, blend: np.ndarray, goals: list[ik.Goal], roots: np.ndarray, first: np.ndarray, last: np.ndarray
    ) -> np.ndarray:
        """The goals solved frame after frame near ``blend`` ``(n, ndof)``, each frame warm-started from its
        neighbour's correction of the blend (so no joint leaps to another IK branch between frames): tracked
        forwards from ``first`` and backwards from ``last``, the two eased into each other over the clip and
        put back on the goals in a few small steps."""
        sk = self.slave_kin
        n = len(blend)
        opts: dict[str, Any] = {"rest_gain": 0.1, "tolerance": 0.02}
        opts.update(self.ik_options)
        opts.update(iterations=TRACK_ITERATIONS, max_dof_step=SMOOTH_MAX_DOF_STEP)
        frame_goals = [[g.rows(slice(i, i + 1)) for g in goals] for i in range(n)]

        def along(order: range, end: np.ndarray) -> np.ndarray:
            out = np.empty_like(blend)
            out[order[0]] = prev = end
            for i in order[1:]:
                start = sk.clamp(blend[i] + (prev - blend[i - 1 if order.step > 0 else i + 1]))
                q, _ = ik.solve(
                    sk, start[None], frame_goals[i], roots[i : i + 1], rest_pose=start[None], **opts
                )
                out[i] = prev = q[0]
            return out

        fwd, bwd = along(range(n), first), along(range(n - 1, -1, -1), last)
        u = np.linspace(0.0, 1.0, n)[:, None]
        mixed = fwd + u * u * (3.0 - 2.0 * u) * (bwd - fwd)
        opts.update(iterations=TRACK_SETTLE_ITERATIONS, max_dof_step=0.2 * SMOOTH_MAX_DOF_STEP)
        out, self.last_report = ik.solve(sk, mixed, goals, roots, rest_pose=mixed, **opts)
        return out

    def update(self) -> None:
        """The SimulationFunction: when on, set the slave figure from the master figure's current state."""
        if not self.on:
            return
        pose, loc = self.slave_pose(self.master_kin.neutral_pose(), self.master.location)
        self.slave_kin.set_pose(pose)
        self.slave.location = loc


RELEASE_FADE_FRAMES = 12  # after the hands let go, the arm goals fade out over this many frames


def _let_go(solved: np.ndarray, copied: np.ndarray, release_frame: int | None) -> np.ndarray:
    """Slave poses ``(n, ndof)`` of a clip whose hands let go of the rifle at ``release_frame`` (a death):
    the solved poses while the rifle is held, blending (smoothstep over :data:`RELEASE_FADE_FRAMES`) into
    the copied angles and blended spine. Solving a flung body onto the master's palms, elbows and torso
    sites flipped the DI's shoulders and spine between branches (up to 160 degrees in one frame), the DI's
    torso being shaped differently; fading the goals' weights still snapped at the end (IK meets a goal of
    any weight), so the poses themselves are blended."""
    if release_frame is None or solved.ndim != 2:
        return solved
    u = np.clip((np.arange(len(solved)) - release_frame) / RELEASE_FADE_FRAMES, 0.0, 1.0)
    w = (u * u * (3.0 - 2.0 * u))[:, None]
    return solved + w * (copied - solved)


def _let_go_in_place(
    poses: np.ndarray, copied: np.ndarray, release_frame: int, arms: np.ndarray
) -> np.ndarray:
    """Slave poses ``(n, ndof)`` whose ``arms`` DOFs, from ``release_frame`` on, blend (as :func:`_let_go`)
    from their pose in the frame before into the ``copied`` angles: the arms' goals tracked on after the
    hands let go leapt (ststow2dead's M16 slave's right shoulder, 19.5-24.6 degrees in the first frame)."""
    if not 0 < release_frame < len(poses):
        return poses
    u = np.clip((np.arange(len(poses)) - release_frame + 1) / RELEASE_FADE_FRAMES, 0.0, 1.0)
    w = (u * u * (3.0 - 2.0 * u))[release_frame:, None]
    held = poses[release_frame - 1, arms]
    out = poses.copy()
    out[release_frame:, arms] = held + w * (copied[release_frame:, arms] - held)
    return out


def create_master_slave_pair(master: Figure, slave: Figure, rifle: Figure | None = None) -> MasterSlavePair:
    """Jack's ``create_master_slave_pair``: a soldier.fig master and a DI.fig slave (plus their rifle)."""
    return MasterSlavePair(master, slave, rifle)


def turn_slave_on(pair: MasterSlavePair) -> None:
    pair.turn_slave_on()


def turn_slave_off(pair: MasterSlavePair) -> None:
    pair.turn_slave_off()


def create_channelset_motion(channelset: Channelset, figures: Sequence[Figure]) -> Recording:
    """Jack's ``create_channelset_motion`` + interpolation: every frame of ``channelset`` played on
    ``figures`` as a :class:`Recording` (each figure's root site and its global, re-expressed for the
    figure's own root site when the channel recorded another one)."""
    bound = bind_channelset(channelset, list(figures))
    rec = Recording(list(figures))
    n = channelset.nframes
    by_name = {f.name: f for f in figures}
    for bf in bound.figures:
        fig = by_name[bf.figure]
        if fig.root is None:
            raise ChannelsetError(f"figure {fig.name!r} has no root site", channelset.source)
        poses = np.tile(bf.neutral.astype(np.float64), (n, 1))
        poses[:, bf.dst] = channelset.joint_data[:, bf.src]
        root = site_name(fig.root)
        if bf.figure_channel < 0:
            locs = np.broadcast_to(fig.location, (n, 4, 4))
        else:
            chan = next(c for c in channelset.figure_channels() if c.column == bf.figure_channel)
            locs = channelset.transforms(chan)
            roots = channelset.roots(chan)
            if any(r != root for r in roots):
                kin = FigureKinematics(fig)
                g = kin.site_globals(poses, np.broadcast_to(np.eye(4), (n, 4, 4)))
                idx = np.array([kin.site_names.index(r) for r in roots])
                rel = np.linalg.inv(g[np.arange(n), idx]) @ g[:, kin.site_names.index(root)]
                locs = locs @ rel
        rec.poses[fig.name].extend(poses)
        rec.roots[fig.name].extend([root] * n)
        rec.locations[fig.name].extend(np.asarray(locs, dtype=np.float64))
    missing = [f.name for f in figures if not rec.poses[f.name]]
    if missing:
        raise ChannelsetError(f"{channelset.name}: nothing drives figure {missing[0]!r}", channelset.source)
    return rec


_CORE_FIELDS = {
    "name",
    "fps",
    "channels",
    "joint_data",
    "fig_pos",
    "fig_quat",
    "fig_root",
    "root_names",
    "source",
}


def low_name(name: str) -> str:
    """``ststow2kstow.chset`` -> ``ststow2kstow_low.chset`` (the seed's names for re-recorded clips)."""
    for suffix in (".chset.env", ".chset"):
        if name.endswith(suffix):
            return name[: -len(suffix)] + "_low" + suffix
    return name + "_low"


def held_rifle_targets(
    pair: MasterSlavePair,
    master_poses: np.ndarray,
    master_locations: np.ndarray,
    rifle: Figure,
    rifle_locations: np.ndarray,
    release_frame: int | None = None,
) -> dict[str, np.ndarray]:
    """Slave site -> positions ``(n, 3)`` for a slave holding ``rifle`` (at root-site globals
    ``rifle_locations``) where the master holds its own: each palm on its rifle site (:data:`RIFLE_HOLDS`)
    until ``release_frame`` (then easing onto the master's palm over ``RELEASE_FADE_FRAMES``: a step there
    made the tracked wrist jump), and the elbow goal moved by ``ELBOW_FOLLOW`` of the palm's move, so that
    elbow and palm goals do not pull the arm against its limits."""
    mk = pair.master_kin
    master = mk.site_globals(master_poses, master_locations)[..., :3, 3]
    kin = FigureKinematics(rifle)
    sites = kin.site_globals(np.zeros(0), np.asarray(rifle_locations, np.float64))
    out: dict[str, np.ndarray] = {}
    for palm, site in RIFLE_HOLDS.items():
        target = sites[:, kin.site_names.index(site), :3, 3].copy()
        own = master[:, mk.site_names.index(palm)]
        if release_frame is not None:  # eased over the fade of the arm goals, so the hand does not jump
            u = np.clip((np.arange(len(target)) - release_frame) / RELEASE_FADE_FRAMES, 0.0, 1.0)[:, None]
            target += u * u * (3.0 - 2.0 * u) * (own - target)
        out[palm] = target
        side = palm.split("_", 1)[0]
        for c in SLAVE_CONSTRAINTS:
            if c.group == "elbow" and c.slave_site.startswith(side):
                out[c.slave_site] = master[:, mk.site_names.index(c.master_site)] + ELBOW_FOLLOW * (
                    target - own
                )
    return out


def reslave_channelset(
    channelset: Channelset,
    pair: MasterSlavePair,
    name: str | None = None,
    rifle: Figure | None = None,
    rifle_locations: np.ndarray | None = None,
    let_go_in_place: bool = False,
) -> Channelset:
    """Re-record a master channelset for the slave: slave channels (figure + joints) replace the master's,
    every other sharedchannel (the rifle) is copied unchanged, and optional fields (``ground_speed``,
    ``stride_length``, ...) are carried over.

    With ``rifle`` (another rifle figure, e.g. ``M16.fig``) and its root-site globals ``rifle_locations``
    ``(n, 4, 4)``, the slave holds that rifle instead: its palms go on the rifle's grip and handguard (until
    the channelset's ``release_frame``; ``let_go_in_place``: see :meth:`MasterSlavePair.slave_clip`) and its
    figure channel replaces the master's rifle channel."""
    rec = create_channelset_motion(channelset, [pair.master])
    n = rec.nframes
    q = np.asarray(rec.poses[pair.master.name], dtype=np.float64)
    loc = np.asarray(rec.locations[pair.master.name], dtype=np.float64)
    figures = [pair.slave]
    targets = None
    if rifle is not None:
        if rifle_locations is None or np.shape(rifle_locations) != (n, 4, 4):
            raise ValueError(f"{channelset.name}: rifle_locations must be ({n}, 4, 4)")
        figures.append(rifle)
        targets = held_rifle_targets(pair, q, loc, rifle, rifle_locations, channelset.release_frame)
    pose, slave_loc = pair.slave_clip(
        q, loc, channelset.release_frame, targets=targets, let_go_in_place=let_go_in_place
    )
    out = Recording(figures)
    out.poses[pair.slave.name].extend(pose)
    out.roots[pair.slave.name].extend([pair._slave_root] * n)
    out.locations[pair.slave.name].extend(slave_loc)
    if rifle is not None:
        out.poses[rifle.name].extend(np.zeros((n, 0)))
        out.roots[rifle.name].extend([site_name(rifle.root)] * n)  # type: ignore[arg-type]
        out.locations[rifle.name].extend(np.asarray(rifle_locations, np.float64))
    slave_cs = recording_to_channelset(channelset.name, out, 0, n - 1, channelset.fps)
    dropped = {protofiletype(pair.master)}
    if rifle is not None and pair.rifle is not None:
        dropped.add(protofiletype(pair.rifle))
    kept: list[JointTrack | FigureTrack] = [t for t in channelset.tracks() if t.protofiletype not in dropped]
    result = make_channelset(
        name or low_name(channelset.name), channelset.fps, [*slave_cs.tracks(), *kept], channelset.source
    )
    for key, value in vars(channelset).items():  # optional fields, declared or set on the instance
        if key not in _CORE_FIELDS and not key.startswith("_"):
            setattr(result, key, value)
    return result
