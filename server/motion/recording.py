"""Recording channels and turning them into channelsets (seed 002: write_channelset, reroot_figure_channel).

A :class:`Recording` is what Jack's per-object channels hold after ``go``: for a list of figures, per frame
the pose vector, the root site and that site's global transform. :func:`write_channelset` pulls frames
``begin, begin+stride, ..., end`` out of it (begin=100, end=220, stride=2 → 61 frames = 60 intervals, 2 s at
30 fps) into a channelset with one figure channel per figure and one joint channel per joint with DOFs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from peabody.model import Figure, Site
from server.motion.binding import bind_channelset, neutral_pose, protofiletype
from server.motion.channelset import Channelset, FigureTrack, JointTrack, make_channelset
from server.motion.errors import ChannelsetError


def site_name(site: Site) -> str:
    """``segment.site``: how figure channels name root sites."""
    return f"{site.segment.name}.{site.name}" if site.segment is not None else site.name


@dataclass
class Recording:
    """Per-frame pose vectors, root sites and root transforms of a list of figures."""

    figures: list[Figure]
    poses: dict[str, list[np.ndarray]] = field(default_factory=dict)
    roots: dict[str, list[str]] = field(default_factory=dict)
    locations: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for f in self.figures:
            self.poses.setdefault(f.name, [])
            self.roots.setdefault(f.name, [])
            self.locations.setdefault(f.name, [])

    @property
    def nframes(self) -> int:
        return len(self.poses[self.figures[0].name]) if self.figures else 0

    def capture(self) -> None:
        """Append the figures' current state (DOF values, root site, location) as the next frame."""
        for f in self.figures:
            if f.root is None:
                raise ChannelsetError(f"figure {f.name!r} has no root site to record")
            self.poses[f.name].append(neutral_pose(f))
            self.roots[f.name].append(site_name(f.root))
            self.locations[f.name].append(np.array(f.location, dtype=np.float64))

    def append(self, figure: str, pose: np.ndarray, root: str, location: np.ndarray) -> None:
        """Append one frame for one figure from arrays (for recordings not made from live figures)."""
        self.poses[figure].append(np.asarray(pose, dtype=np.float32))
        self.roots[figure].append(root)
        self.locations[figure].append(np.asarray(location, dtype=np.float64))


def recording_to_channelset(
    name: str,
    recorded: Recording,
    begin: int,
    end: int,
    fps: float,
    stride: int = 1,
    figures: Sequence[Figure | str] | None = None,
) -> Channelset:
    """Frames ``begin..end`` (inclusive) every ``stride`` of the recording as a channelset at ``fps``."""
    n = recorded.nframes
    if stride < 1 or begin < 0 or end < begin or end >= n:
        raise ChannelsetError(f"bad frame range begin={begin} end={end} stride={stride} (recording has {n})")
    if not fps > 0:
        raise ChannelsetError(f"fps must be > 0, not {fps}")
    frames = np.arange(begin, end + 1, stride)
    by_name = {f.name: f for f in recorded.figures}
    wanted = [by_name[f if isinstance(f, str) else f.name] for f in (figures or recorded.figures)]
    tracks: list[JointTrack | FigureTrack] = []
    for fig in wanted:
        ptype = protofiletype(fig)
        poses = np.asarray(recorded.poses[fig.name], dtype=np.float64)[frames]
        roots = [recorded.roots[fig.name][i] for i in frames]
        locs = np.asarray(recorded.locations[fig.name], dtype=np.float64)[frames]
        tracks.append(FigureTrack(fig.name, ptype, fig.name, roots, locs))
        col = 0
        for jname, joint in fig.joints.items():
            if joint.ndofs:
                tracks.append(JointTrack(jname, ptype, jname, poses[:, col : col + joint.ndofs]))
            col += joint.ndofs
    return make_channelset(name, fps, tracks)


def write_channelset(
    path: str | Path | None,
    name: str,
    recorded: Recording,
    begin: int,
    end: int,
    fps: float,
    stride: int = 1,
    figures: Sequence[Figure | str] | None = None,
) -> Channelset:
    """Jack's ``write_channelset``: build the channelset and write it as Peabody text to ``path``."""
    chset = recording_to_channelset(name, recorded, begin, end, fps, stride, figures)
    if path is not None:
        from server.motion.channelset_file import save_channelset

        save_channelset(chset, path)
    return chset


class SiteKinematics(Protocol):
    """What re-rooting needs from ``peabody.fk.FigureKinematics``."""

    site_names: list[str]

    def site_globals(self, angles: np.ndarray, root_location: np.ndarray | None = None) -> np.ndarray: ...


def reroot_figure_channel(
    channelset: Channelset, figure: Figure, new_root_site: str, kinematics: SiteKinematics
) -> Channelset:
    """Re-express ``figure``'s figure channel so every frame gives ``new_root_site`` and its transform.

    Per frame the pose is taken from the channelset's own joint channels (undriven DOFs: the figure's current
    values), FK gives every site relative to the figure, and ``T_new = T_root @ inv(G_root) @ G_new``. All
    frames are done in one batched FK call. Returns a new channelset; the input is left untouched.
    """
    bound = bind_channelset(channelset, [figure])
    bf = bound.figures[0]
    if bf.figure_channel < 0:
        raise ChannelsetError(
            f"{channelset.name}: no figure channel drives {figure.name!r}", channelset.source
        )
    names = list(kinematics.site_names)
    index = {s: i for i, s in enumerate(names)}
    if new_root_site not in index:
        raise ChannelsetError(f"figure {figure.name!r} has no site {new_root_site!r}", channelset.source)
    n = channelset.nframes
    poses = np.tile(bf.neutral.astype(np.float64), (n, 1))
    poses[:, bf.dst] = channelset.joint_data[:, bf.src]
    glob = kinematics.site_globals(poses)  # (n, nsite, 4, 4)
    chan = next(c for c in channelset.figure_channels() if c.column == bf.figure_channel)
    old_roots = channelset.roots(chan)
    missing = sorted({r for r in old_roots if r not in index})
    if missing:
        raise ChannelsetError(f"figure {figure.name!r} has no site {missing[0]!r}", channelset.source)
    r_idx = np.array([index[r] for r in old_roots])
    rows = np.arange(n)
    rel = np.linalg.inv(glob[rows, r_idx]) @ glob[rows, index[new_root_site]]
    new_t = channelset.transforms(chan) @ rel
    tracks = channelset.tracks()
    pos = next(i for i, c in enumerate(channelset.channels) if c is chan)
    tracks[pos] = FigureTrack(chan.name, chan.protofiletype, chan.object, [new_root_site] * n, new_t)
    return make_channelset(channelset.name, channelset.fps, tracks, channelset.source)
