"""Bound channelsets (seed 002, 3.4.1): a channelset's sharedchannels attached to concrete figures.

A sharedchannel binds to every object of its type whose figure was read from the file named by its
``protofiletype``: joint channels to the joint named by ``object``, figure channels to the figure itself. The
bound channelset holds only small index maps (channelset column → the figure's pose-vector index) and shares
the channelset's frame arrays, so binding one clip to ten soldiers costs bytes, not megabytes.

Pose vector (project-wide layout, same as ``peabody.fk.FigureKinematics.dof_slices``): the figure's
joints in ``figure.joints`` order, each joint's DOFs in order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import PurePath

import numpy as np

from peabody import quaternion
from peabody.model import Figure
from server.motion.channelset import Channelset, SharedChannel
from server.motion.errors import BindingError


def protofiletype(figure: Figure) -> str:
    """The figure file's base name ("DI.fig"): what sharedchannels match against."""
    return PurePath(figure.filename).name if figure.filename else ""


def pose_layout(figure: Figure) -> dict[str, slice]:
    """Joint name → slice of the figure's pose vector (joints in file order, DOFs in order)."""
    out: dict[str, slice] = {}
    start = 0
    for name, joint in figure.joints.items():
        out[name] = slice(start, start + joint.ndofs)
        start += joint.ndofs
    return out


def neutral_pose(figure: Figure) -> np.ndarray:
    """The figure's current DOF values as a pose vector (what undriven DOFs keep)."""
    return np.array([d.value for j in figure.joints.values() for d in j.dofs], dtype=np.float32)


def find_joint(figure: Figure, obj: str) -> str | None:
    """Resolve a joint channel's ``object`` in ``figure``: the joint name, or ``figure.joint``."""
    if obj in figure.joints:
        return obj
    prefix = figure.name + "."
    if obj.startswith(prefix) and obj[len(prefix) :] in figure.joints:
        return obj[len(prefix) :]
    return None


@dataclass(frozen=True)
class FigurePlacement:
    """A figure's location from a figure channel: its root site and that site's global transform."""

    root: str
    position: np.ndarray  # (3,) cm
    quaternion: np.ndarray  # (4,) (w, x, y, z)

    def matrix(self) -> np.ndarray:
        return quaternion.to_transform(np.asarray(self.position, np.float64), self.quaternion)


@dataclass(frozen=True)
class BoundFigure:
    """Index maps for one driven figure: ``pose[dst] = joint_data[frame, src]``."""

    figure: str
    protofiletype: str
    ndof: int
    src: np.ndarray  # (k,) int32 columns of the channelset's joint_data
    dst: np.ndarray  # (k,) int32 indices into the figure's pose vector
    figure_channel: int  # index into the channelset's figure arrays, -1 when no figure channel drives it
    neutral: np.ndarray  # (ndof,) float32 values of undriven DOFs

    @property
    def nbytes(self) -> int:
        return int(self.src.nbytes + self.dst.nbytes + self.neutral.nbytes)


@dataclass(frozen=True)
class BoundSample:
    """One sampled instant: full pose vectors and placements of every bound figure."""

    poses: dict[str, np.ndarray]
    placements: dict[str, FigurePlacement | None]


@dataclass(eq=False)
class BoundChannelset:
    """A channelset bound to figures (named like ``"stand2crawl/soldier3"``)."""

    name: str
    channelset: Channelset
    figures: tuple[BoundFigure, ...]
    unbound: tuple[str, ...] = ()  # sharedchannels that found nothing to drive

    @property
    def nbytes(self) -> int:
        """Bytes this binding adds on top of the shared channelset data."""
        return sum(f.nbytes for f in self.figures)

    def figure(self, name: str) -> BoundFigure:
        for f in self.figures:
            if f.figure == name:
                return f
        raise KeyError(f"bound channelset {self.name!r} does not drive figure {name!r}")

    def sample(self, position: float, interpolate: bool = True) -> BoundSample:
        """Poses and placements at fractional frame ``position`` (clamped to the stored frames).

        Joint angles are lerped and positions lerped, orientations slerped between the two neighbouring
        frames; with ``interpolate=False`` (or a root site change between them) the nearest frame is used.
        """
        cs = self.channelset
        last = cs.nframes - 1
        p = min(max(float(position), 0.0), float(last))
        if interpolate:
            i0 = min(math.floor(p), last)
            i1 = min(i0 + 1, last)
            w = p - i0
        else:
            i0 = i1 = min(math.floor(p + 0.5), last)
            w = 0.0
        poses: dict[str, np.ndarray] = {}
        placements: dict[str, FigurePlacement | None] = {}
        for bf in self.figures:
            pose = bf.neutral.copy()
            a = cs.joint_data[i0, bf.src]
            b = cs.joint_data[i1, bf.src]
            pose[bf.dst] = a + np.float32(w) * (b - a)
            poses[bf.figure] = pose
            k = bf.figure_channel
            if k < 0:
                placements[bf.figure] = None
                continue
            r0, r1 = cs.fig_root[i0, k], cs.fig_root[i1, k]
            if r0 != r1:  # a re-rooting between the frames: never blend two different sites
                i = i0 if w < 0.5 else i1
                placements[bf.figure] = FigurePlacement(
                    cs.root_names[cs.fig_root[i, k]], cs.fig_pos[i, k].copy(), cs.fig_quat[i, k].copy()
                )
                continue
            pa, pb = cs.fig_pos[i0, k], cs.fig_pos[i1, k]
            q = quaternion.slerp(cs.fig_quat[i0, k], cs.fig_quat[i1, k], np.float32(w)).astype(np.float32)
            placements[bf.figure] = FigurePlacement(cs.root_names[r0], pa + np.float32(w) * (pb - pa), q)
        return BoundSample(poses, placements)

    def apply(self, position: float, figures: Mapping[str, Figure], interpolate: bool = True) -> None:
        """Set the bound figures' DOF values and locations (model objects) from one sampled instant."""
        s = self.sample(position, interpolate)
        for name, pose in s.poses.items():
            fig = figures[name]
            dofs = [d for j in fig.joints.values() for d in j.dofs]
            for d, v in zip(dofs, pose.tolist(), strict=True):
                d.value = v
            pl = s.placements[name]
            if pl is not None:
                fig.root = fig.site(pl.root)
                fig.location = pl.matrix()


def _joint_channel_maps(
    cs: Channelset, fig: Figure, ptype: str, strict: bool, unbound: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    layout = pose_layout(fig)
    src: list[int] = []
    dst: list[int] = []
    driven: set[str] = set()
    for c in cs.joint_channels():
        if c.protofiletype != ptype:
            continue
        jname = find_joint(fig, c.object)
        if jname is None or jname in driven:
            why = "no such joint" if jname is None else "joint already driven"
            if strict:
                raise BindingError(f"{cs.name}: sharedchannel {c.name!r} ({c.object}) on {fig.name}: {why}")
            unbound.append(c.name)
            continue
        sl = layout[jname]
        if sl.stop - sl.start != c.width:
            raise BindingError(
                f"{cs.name}: sharedchannel {c.name!r} has {c.width} angles but joint "
                f"{fig.name}.{jname} has {sl.stop - sl.start} DOFs"
            )
        driven.add(jname)
        src.extend(range(c.column, c.column + c.width))
        dst.extend(range(sl.start, sl.stop))
    return np.array(src, dtype=np.int32), np.array(dst, dtype=np.int32)


def _figure_channel_for(cs: Channelset, fig: Figure, ptype: str) -> SharedChannel | None:
    cands = [c for c in cs.figure_channels() if c.protofiletype == ptype]
    for c in cands:
        if c.object == fig.name:
            return c
    return cands[0] if cands else None


def bind_channelset(
    channelset: Channelset, figures: Sequence[Figure], name: str | None = None, *, strict: bool = False
) -> BoundChannelset:
    """Bind ``channelset`` to ``figures`` (e.g. a soldier and its gun).

    Each figure is driven by the sharedchannels whose ``protofiletype`` equals its file's base name. A joint
    channel whose joint is missing goes to ``unbound`` (or raises with ``strict``); a DOF-count mismatch
    always raises :class:`BindingError`, and so does a channelset that drives none of the figures.
    """
    bound: list[BoundFigure] = []
    unbound: list[str] = []
    used: set[str] = set()
    for fig in figures:
        ptype = protofiletype(fig)
        fchan = _figure_channel_for(channelset, fig, ptype)
        src, dst = _joint_channel_maps(channelset, fig, ptype, strict, unbound)
        if fchan is None and len(src) == 0:
            continue
        if fchan is not None:
            used.add(fchan.name)
        used.update(c.name for c in channelset.joint_channels() if c.protofiletype == ptype)
        bound.append(
            BoundFigure(
                figure=fig.name,
                protofiletype=ptype,
                ndof=fig.dof_count,
                src=src,
                dst=dst,
                figure_channel=fchan.column if fchan is not None else -1,
                neutral=neutral_pose(fig),
            )
        )
    if not bound:
        types = sorted({c.protofiletype for c in channelset.channels})
        raise BindingError(f"{channelset.name}: none of the figures is of type {', '.join(types)}")
    unbound.extend(c.name for c in channelset.channels if c.name not in used and c.name not in unbound)
    if strict and unbound:
        raise BindingError(f"{channelset.name}: sharedchannels not bound: {', '.join(unbound)}")
    default = f"{channelset.name}/{bound[0].figure}"
    return BoundChannelset(name or default, channelset, tuple(bound), tuple(dict.fromkeys(unbound)))
