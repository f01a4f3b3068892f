"""Channelsets and sharedchannels (seed 002, 3.4.1): recorded motion as a few contiguous float32 arrays.

A *sharedchannel* is a channel not bound to an object: a joint channel (``"sharedjoint"``, the joint's angles
in radians per frame) or a figure channel (``"sharedfigure"``, per frame the figure's root site name and that
site's global transform). A *channelset* groups sharedchannels recorded together at one ``fps``.

Memory layout (no Python object per frame):

* ``joint_data``  ``(nframes, ncolumns)`` float32 — every joint channel's angles side by side; a joint channel
  owns columns ``column : column + width``.
* ``fig_pos``     ``(nframes, nfig, 3)`` float32 cm; ``fig_quat`` ``(nframes, nfig, 4)`` float32
  ``(w,x,y,z)``, made sign-continuous along frames so slerp never takes the long way; a figure channel owns
  index ``column``.
* ``fig_root``    ``(nframes, nfig)`` int16 indices into ``root_names`` (site names like
  ``"lower_torso.proximal"``).

Frames versus ``size``: a channelset holds ``nframes`` samples ``0 .. nframes-1`` and ``size = nframes - 1``
is the number of *intervals*, so ``duration = size / fps`` (the seed's ``size = 48`` file has frames 0..48 and
``size = 90, fps = 60`` is 1.5 s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from peabody import quaternion
from server.motion.errors import ChannelsetError

ChannelType = Literal["sharedfigure", "sharedjoint"]
CHANNEL_TYPES: tuple[str, ...] = ("sharedfigure", "sharedjoint")


@dataclass(frozen=True)
class SharedChannel:
    """Metadata of one sharedchannel; its data lives in the owning channelset's arrays.

    ``column``: first column in ``joint_data`` (joint channel) or index into the figure arrays (figure
    channel);
    ``width``: number of angles (joint channel) or 1 (figure channel).
    """

    name: str
    type: ChannelType
    protofiletype: str
    object: str
    column: int
    width: int

    @property
    def is_joint(self) -> bool:
        return self.type == "sharedjoint"

    @property
    def is_figure(self) -> bool:
        return self.type == "sharedfigure"


@dataclass
class JointTrack:
    """Input to :func:`make_channelset`: a joint channel's angles ``(nframes, width)`` in radians."""

    name: str
    protofiletype: str
    object: str
    angles: np.ndarray


@dataclass
class FigureTrack:
    """Input to :func:`make_channelset`: per frame a root site name and its global 4x4 transform."""

    name: str
    protofiletype: str
    object: str
    roots: Sequence[str]
    transforms: np.ndarray  # (nframes, 4, 4)


@dataclass(eq=False)
class Channelset:
    """A named set of sharedchannels sampled at ``fps``; see the module docstring for the layout."""

    name: str
    fps: float
    channels: tuple[SharedChannel, ...]
    joint_data: np.ndarray
    fig_pos: np.ndarray
    fig_quat: np.ndarray
    fig_root: np.ndarray
    root_names: tuple[str, ...]
    source: str | None = None
    # locomotion clips (optional file fields): distance covered by the recorded step (cm) and the constant
    # ground speed it was recorded at (cm/s), so playback can be scaled to a requested speed
    stride_length: float | None = None
    ground_speed: float | None = None
    # the frame from which the hands no longer hold the rifle (a death lets go of it): palms are checked on
    # the grip, and slaving holds them there, only before it
    release_frame: int | None = None
    # the entity's own move over the clip, (x cm, z cm, yaw degrees about +Y, + = to the left), for clips
    # that turn or step the soldier to a new place: its last frame is its start posture moved by this
    end_offset: tuple[float, float, float] | None = None
    _by_name: dict[str, int] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ChannelsetError(f"channelset {self.name!r}: fps must be > 0, not {self.fps}", self.source)
        self.fps = float(self.fps)
        self.channels = tuple(self.channels)
        self.root_names = tuple(self.root_names)
        self.joint_data = np.ascontiguousarray(self.joint_data, dtype=np.float32)
        self.fig_pos = np.ascontiguousarray(self.fig_pos, dtype=np.float32)
        self.fig_quat = np.ascontiguousarray(self.fig_quat, dtype=np.float32)
        self.fig_root = np.ascontiguousarray(self.fig_root, dtype=np.int16)
        n = self.joint_data.shape[0]
        njoint = sum(c.width for c in self.channels if c.is_joint)
        nfig = sum(1 for c in self.channels if c.is_figure)
        ok = (
            n >= 1
            and self.joint_data.shape == (n, njoint)
            and self.fig_pos.shape == (n, nfig, 3)
            and self.fig_quat.shape == (n, nfig, 4)
            and self.fig_root.shape == (n, nfig)
        )
        if not ok:
            raise ChannelsetError(f"channelset {self.name!r}: inconsistent array shapes", self.source)
        if not np.isfinite((n - 1) / self.fps):
            raise ChannelsetError(f"channelset {self.name!r}: fps {self.fps} is too small", self.source)
        finite = (np.isfinite(a).all() for a in (self.joint_data, self.fig_pos, self.fig_quat))
        if not all(finite):
            raise ChannelsetError(f"channelset {self.name!r}: values must be finite float32", self.source)
        if nfig and (self.fig_root.min() < 0 or self.fig_root.max() >= len(self.root_names)):
            raise ChannelsetError(f"channelset {self.name!r}: root site index out of range", self.source)
        for what in ("stride_length", "ground_speed"):
            v = getattr(self, what)
            if v is not None:
                v = float(v)
                if not (math.isfinite(v) and v >= 0):
                    msg = f"channelset {self.name!r}: {what} must be >= 0, not {v}"
                    raise ChannelsetError(msg, self.source)
                setattr(self, what, v)
        if self.release_frame is not None:
            r = self.release_frame
            if not (float(r).is_integer() and 0 <= r < n):
                msg = f"channelset {self.name!r}: release_frame must be a frame 0..{n - 1}, not {r}"
                raise ChannelsetError(msg, self.source)
            self.release_frame = int(r)
        if self.end_offset is not None:
            off = tuple(float(v) for v in self.end_offset)
            if len(off) != 3 or not all(math.isfinite(v) for v in off):
                msg = f"channelset {self.name!r}: end_offset must be three finite numbers (x, z cm, yaw deg)"
                raise ChannelsetError(msg, self.source)
            self.end_offset = (off[0], off[1], off[2])
        self._by_name = {}
        for i, c in enumerate(self.channels):
            self._by_name.setdefault(c.name, i)

    # -- sizes ----------------------------------------------------------------------------------
    @property
    def nframes(self) -> int:
        return int(self.joint_data.shape[0])

    @property
    def size(self) -> int:
        """Intervals between the stored frames (what the file's ``size`` field says)."""
        return self.nframes - 1

    @property
    def count(self) -> int:
        return len(self.channels)

    @property
    def duration(self) -> float:
        """Stored playing time in seconds: ``size / fps``."""
        return self.size / self.fps

    @property
    def nbytes(self) -> int:
        """Bytes held by the frame data (the arrays, not the small metadata)."""
        return int(self.joint_data.nbytes + self.fig_pos.nbytes + self.fig_quat.nbytes + self.fig_root.nbytes)

    # -- channels ----------------------------------------------------------------------------------
    def joint_channels(self) -> list[SharedChannel]:
        return [c for c in self.channels if c.is_joint]

    def figure_channels(self) -> list[SharedChannel]:
        return [c for c in self.channels if c.is_figure]

    def channel(self, name: str) -> SharedChannel:
        try:
            return self.channels[self._by_name[name]]
        except KeyError:
            raise KeyError(f"channelset {self.name!r} has no sharedchannel {name!r}") from None

    def angles(self, channel: SharedChannel) -> np.ndarray:
        """``(nframes, width)`` view of a joint channel's angles."""
        if not channel.is_joint:
            raise ValueError(f"{channel.name!r} is not a joint channel")
        return self.joint_data[:, channel.column : channel.column + channel.width]

    def roots(self, channel: SharedChannel) -> list[str]:
        """Per-frame root site names of a figure channel."""
        return [self.root_names[i] for i in self.fig_root[:, channel.column]]

    def transforms(self, channel: SharedChannel) -> np.ndarray:
        """``(nframes, 4, 4)`` float64 global transforms of a figure channel's root site."""
        if not channel.is_figure:
            raise ValueError(f"{channel.name!r} is not a figure channel")
        k = channel.column
        return quaternion.to_transform(self.fig_pos[:, k].astype(np.float64), self.fig_quat[:, k])

    def tracks(self) -> list[JointTrack | FigureTrack]:
        """The channels back as tracks (file order), e.g. to edit and rebuild with :func:`make_channelset`."""
        out: list[JointTrack | FigureTrack] = []
        for c in self.channels:
            if c.is_joint:
                out.append(JointTrack(c.name, c.protofiletype, c.object, self.angles(c).copy()))
            else:
                out.append(FigureTrack(c.name, c.protofiletype, c.object, self.roots(c), self.transforms(c)))
        return out


def _rigid_check(t: np.ndarray, name: str, source: str | None) -> None:
    r = t[:, :3, :3]
    if not np.isfinite(t).all():
        raise ChannelsetError(f"figure channel {name!r}: transforms must be finite", source)
    err = np.abs(np.einsum("nij,nkj->nik", r, r) - np.eye(3)).max(initial=0.0)
    if err > 1e-3 or (len(r) and np.linalg.det(r).min() <= 0):
        raise ChannelsetError(f"figure channel {name!r}: transforms must be finite and rigid", source)


def make_channelset(
    name: str, fps: float, tracks: Sequence[JointTrack | FigureTrack], source: str | None = None
) -> Channelset:
    """Pack tracks (in order) into the contiguous channelset layout; validates frame counts."""
    if not tracks:
        raise ChannelsetError(f"channelset {name!r} has no sharedchannels", source)
    lengths = {len(t.angles) if isinstance(t, JointTrack) else len(t.transforms) for t in tracks}
    if len(lengths) != 1:
        raise ChannelsetError(f"channelset {name!r}: sharedchannels have different frame counts", source)
    n = lengths.pop()
    if n < 1:
        raise ChannelsetError(f"channelset {name!r} has no frames", source)
    channels: list[SharedChannel] = []
    joint_cols: list[np.ndarray] = []
    col = 0
    pos: list[np.ndarray] = []
    quats: list[np.ndarray] = []
    root_idx: list[np.ndarray] = []
    root_names: dict[str, int] = {}
    for t in tracks:
        if isinstance(t, JointTrack):
            a = np.asarray(t.angles, dtype=np.float64)
            if a.ndim == 1:
                a = a[:, None]
            if a.ndim != 2 or a.shape[1] < 1 or not np.isfinite(a).all():
                raise ChannelsetError(f"joint channel {t.name!r}: angles must be finite (nframes, k)", source)
            channels.append(SharedChannel(t.name, "sharedjoint", t.protofiletype, t.object, col, a.shape[1]))
            joint_cols.append(a)
            col += a.shape[1]
        else:
            tr = np.asarray(t.transforms, dtype=np.float64)
            if tr.shape != (n, 4, 4) or len(t.roots) != n:
                raise ChannelsetError(f"figure channel {t.name!r}: need {n} roots and 4x4 transforms", source)
            _rigid_check(tr, t.name, source)
            channels.append(SharedChannel(t.name, "sharedfigure", t.protofiletype, t.object, len(pos), 1))
            pos.append(tr[:, :3, 3])
            quats.append(quaternion.make_continuous(quaternion.from_matrix(tr)))
            root_idx.append(np.array([root_names.setdefault(r, len(root_names)) for r in t.roots]))
    if len(root_names) > np.iinfo(np.int16).max:
        raise ChannelsetError(f"channelset {name!r}: too many distinct root sites", source)
    nfig = len(pos)
    return Channelset(
        name=name,
        fps=float(fps),
        channels=tuple(channels),
        joint_data=np.concatenate(joint_cols, axis=1) if joint_cols else np.zeros((n, 0)),
        fig_pos=np.stack(pos, axis=1) if nfig else np.zeros((n, 0, 3)),
        fig_quat=np.stack(quats, axis=1) if nfig else np.zeros((n, 0, 4)),
        fig_root=np.stack(root_idx, axis=1) if nfig else np.zeros((n, 0), dtype=np.int16),
        root_names=tuple(root_names),
        source=source,
    )


def channelsets_close(a: Channelset, b: Channelset, atol: float = 1e-5) -> bool:
    """Same name, fps, channel metadata and frame data within ``atol``.

    Quaternions are compared up to sign, as ``|a . b| >= 1 - max(atol, 1e-6)`` (float32 dot products).
    """
    if (a.name, a.fps, a.channels) != (b.name, b.fps, b.channels) or a.nframes != b.nframes:
        return False
    if a.fig_root.shape != b.fig_root.shape:
        return False
    ra = np.array(a.root_names, dtype=object)[a.fig_root] if a.root_names else a.fig_root
    rb = np.array(b.root_names, dtype=object)[b.fig_root] if b.root_names else b.fig_root
    dots = np.abs(np.sum(a.fig_quat.astype(np.float64) * b.fig_quat, axis=-1))
    return bool(
        np.array_equal(ra, rb)
        and np.allclose(a.joint_data, b.joint_data, atol=atol, rtol=0)
        and np.allclose(a.fig_pos, b.fig_pos, atol=atol, rtol=1e-6)
        and np.all(dots >= 1.0 - max(atol, 1e-6))
    )
