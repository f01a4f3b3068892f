"""Sampling many soldiers at once: the server's hot path.

A :class:`ClipLibrary` holds every clip for one *figure set* (the prototype figures a soldier is made of, e.g.
``DI.fig`` + a rifle file) concatenated frame after frame:

* ``joint_data`` ``(total_frames, ndof)`` float32 in the pose-vector order of the prototypes (figure after
  figure; each figure's joints in file order, DOFs in order); DOFs a clip does not drive hold the figure's
  neutral value, so a sampled row is a complete pose.
* ``fig_data`` ``(total_frames, nfig, 7)`` float32: each prototype's figure channel ``(px, py, pz, qw, qx, qy,
  qz)`` (identity when a clip has none) and ``fig_root`` ``(total_frames, nfig)`` int16 indices into
  ``root_names`` (-1: none).
* an offset table ``clip_start``, ``clip_nframes``, ``clip_fps``.

:meth:`ClipLibrary.sample` takes one array entry per soldier and does all of them in a handful of numpy calls
(two gathers and a blend), with the same frame arithmetic as :func:`server.motion.playback.frame_position`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from peabody.model import Figure
from protocol import fused
from protocol.bitpack import scratch
from server.motion.binding import bind_channelset, neutral_pose, protofiletype
from server.motion.blend_loop import blend_rows, frame_rows
from server.motion.channelset import Channelset
from server.motion.errors import BindingError

_IDENTITY7 = np.array([0, 0, 0, 1, 0, 0, 0], dtype=np.float32)


@dataclass
class LibrarySample:
    """Output buffers of :meth:`ClipLibrary.sample` (reuse one per tick through ``out=``)."""

    joints: np.ndarray  # (N, ndof) float32 pose vectors
    figures: np.ndarray  # (N, nfig, 7) float32 position + quaternion (w, x, y, z)
    roots: np.ndarray  # (N, nfig) int16 root site indices into ClipLibrary.root_names, -1 = none
    ended: np.ndarray  # (N,) bool: the clip has played to its end (its last frame is shown)
    position: np.ndarray  # (N,) float64 fractional frame within the clip
    _scratch_j: np.ndarray = field(repr=False, default=None)  # type: ignore[arg-type]
    _scratch_f: np.ndarray = field(repr=False, default=None)  # type: ignore[arg-type]
    _weights_a: np.ndarray = field(repr=False, default=None)  # type: ignore[arg-type]
    _weights_b: np.ndarray = field(repr=False, default=None)  # type: ignore[arg-type]

    @classmethod
    def empty(cls, n: int, ndof: int, nfig: int) -> LibrarySample:
        return cls(
            joints=np.empty((n, ndof), np.float32),
            figures=np.empty((n, nfig, 7), np.float32),
            roots=np.empty((n, nfig), np.int16),
            ended=np.empty(n, bool),
            position=np.empty(n, np.float64),
            _scratch_j=np.empty((n, ndof), np.float32),
            _scratch_f=np.empty((n, nfig, 7), np.float32),
            _weights_a=np.empty((n, nfig, 7), np.float32),
            _weights_b=np.empty((n, nfig, 7), np.float32),
        )


class ClipLibrary:
    """All clips of one figure set, concatenated for vectorised sampling."""

    def __init__(self, figures: Sequence[Figure], name: str | None = None) -> None:
        types = [protofiletype(f) for f in figures]
        if not figures or len(set(types)) != len(types):
            raise BindingError("a clip library needs figures of distinct file types")
        self.name = name or "+".join(types)
        self.prototypes = list(figures)
        self.figure_types = types
        sizes = [f.dof_count for f in figures]
        self.figure_offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.ndof = int(self.figure_offsets[-1])
        self.nfig = len(figures)
        self.neutral = np.concatenate([neutral_pose(f) for f in figures]).astype(np.float32)
        self.root_names: list[str] = []
        self._root_index: dict[str, int] = {}
        self.clip_names: list[str] = []
        self._clip_index: dict[str, int] = {}
        self._chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._fps: list[float] = []
        self._dirty = True
        self._finalize()

    # -- building ----------------------------------------------------------------------------------
    def add(self, channelset: Channelset, name: str | None = None, *, _finalize: bool = True) -> int:
        """Append a clip (bound to the prototypes through the usual binding rules); returns its clip id."""
        key = name or channelset.name
        if key in self._clip_index:
            raise ValueError(f"clip {key!r} is already in library {self.name!r}")
        bound = bind_channelset(channelset, self.prototypes)
        n = channelset.nframes
        joints = np.tile(self.neutral, (n, 1))
        figs = np.tile(_IDENTITY7, (n, self.nfig, 1))
        roots = np.full((n, self.nfig), -1, np.int16)
        for bf in bound.figures:
            i = self.figure_types.index(bf.protofiletype)
            joints[:, self.figure_offsets[i] + bf.dst] = channelset.joint_data[:, bf.src]
            k = bf.figure_channel
            if k >= 0:
                figs[:, i, :3] = channelset.fig_pos[:, k]
                figs[:, i, 3:] = channelset.fig_quat[:, k]
                remap = np.array([self._root(r) for r in channelset.root_names], np.int16)
                roots[:, i] = remap[channelset.fig_root[:, k]]
        self._chunks.append((joints, figs, roots))
        self._fps.append(float(channelset.fps))
        self._clip_index[key] = len(self.clip_names)
        self.clip_names.append(key)
        self._dirty = True
        if _finalize:
            self._finalize()
        return self._clip_index[key]

    def extend(self, channelsets: list[Channelset]) -> list[int]:
        """Add several clips (each under its own name), concatenating the arrays once."""
        ids = [self.add(cs, _finalize=False) for cs in channelsets]
        self._finalize()
        return ids

    def _root(self, site: str) -> int:
        if site not in self._root_index:
            self._root_index[site] = len(self.root_names)
            self.root_names.append(site)
        return self._root_index[site]

    def _finalize(self) -> None:
        if not self._dirty:
            return
        if self._chunks:
            self.joint_data = np.ascontiguousarray(np.concatenate([c[0] for c in self._chunks]))
            self.fig_data = np.ascontiguousarray(np.concatenate([c[1] for c in self._chunks]))
            self.fig_root = np.ascontiguousarray(np.concatenate([c[2] for c in self._chunks]))
        else:
            self.joint_data = np.zeros((0, self.ndof), np.float32)
            self.fig_data = np.zeros((0, self.nfig, 7), np.float32)
            self.fig_root = np.zeros((0, self.nfig), np.int16)
        self.clip_nframes = np.array([len(c[0]) for c in self._chunks], np.int64)
        self.clip_start = np.concatenate([[0], np.cumsum(self.clip_nframes)[:-1]]).astype(np.int64)
        self.clip_fps = np.array(self._fps, np.float64)
        self.clip_duration = (self.clip_nframes - 1) / np.maximum(self.clip_fps, 1e-300)
        self._slerp_tables()
        self._dirty = False

    def _slerp_tables(self) -> None:
        """Per row, what slerping towards the next row of the same clip needs, so sampling does no arccos.

        ``_theta`` is the angle between the two quaternions (at least 1e-6, where the weights tend to lerp's),
        ``_inv_sin`` = 1/sin(theta), ``_inv_sin_next`` the same signed so the short arc is taken, and
        ``_reroot`` flags a root site change (never blended).
        """
        total = len(self.joint_data)
        nxt = np.minimum(np.arange(total) + 1, total - 1)
        if total:
            last_rows = self.clip_start + self.clip_nframes - 1
            nxt[last_rows] = last_rows
        q = self.fig_data[..., 3:].astype(np.float64)
        dot = np.sum(q * q[nxt], axis=-1)
        theta = np.maximum(np.arccos(np.minimum(np.abs(dot), 1.0)), 1e-6)
        inv = 1.0 / np.sin(theta)
        self._theta = theta.astype(np.float32)
        self._inv_sin = inv.astype(np.float32)
        self._inv_sin_next = np.where(dot < 0, -inv, inv).astype(np.float32)
        self._reroot = self.fig_root != self.fig_root[nxt]
        self._reroot_any = self._reroot.any(axis=1)

    # -- queries ----------------------------------------------------------------------------------
    def clip_id(self, name: str) -> int:
        try:
            return self._clip_index[name]
        except KeyError:
            raise KeyError(f"library {self.name!r} has no clip {name!r}") from None

    @property
    def nclips(self) -> int:
        return len(self.clip_names)

    @property
    def nbytes(self) -> int:
        self._finalize()
        return int(self.joint_data.nbytes + self.fig_data.nbytes + self.fig_root.nbytes)

    def figure_slice(self, figure_type: str) -> slice:
        """Columns of ``joints`` that hold the pose vector of the prototype of ``figure_type``."""
        i = self.figure_types.index(figure_type)
        return slice(int(self.figure_offsets[i]), int(self.figure_offsets[i + 1]))

    # -- the hot path ----------------------------------------------------------------------------------
    def sample(
        self,
        clip_id: np.ndarray,
        start_time: np.ndarray,
        direction: np.ndarray,
        duration: np.ndarray,
        now: float | np.ndarray,
        out: LibrarySample | None = None,
        *,
        interpolate: bool = True,
    ) -> LibrarySample:
        """Sample N soldiers at ``now``: soldier *i* plays clip ``clip_id[i]`` since ``start_time[i]``,
        forwards when ``direction[i] > 0`` (or True), over ``duration[i]`` seconds (<= 0: stored time).

        Positions are clamped at the clip's end; ``out.ended`` flags the soldiers whose play is over so the
        caller runs per-soldier logic only for those.
        """
        self._finalize()
        clip = np.asarray(clip_id, dtype=np.int64)
        n = clip.shape[0]
        if out is None or out.joints.shape != (n, self.ndof) or out._scratch_j is None:
            out = self._fresh(n)
        if n == 0:
            return out
        if fused.AVAILABLE and interpolate:  # the frames, gathers and blends compiled (the sines in numpy)
            g0, g1 = np.empty(n, np.int64), np.empty(n, np.int64)
            w = np.empty(n, np.float32)
            now_ = np.broadcast_to(np.asarray(now, np.float64), (n,))
            frame_rows()(
                clip,
                np.asarray(start_time, np.float64),
                np.asarray(direction),
                np.asarray(duration, np.float64),
                now_,
                self.clip_nframes,
                self.clip_duration,
                self.clip_start,
                out.position,
                out.ended,
                g0,
                g1,
                w,
            )
            qa, qb = self._slerp_weights(g0, w) if self.nfig else (w[:, None], w[:, None])
            blend_rows()(self.joint_data, self.fig_data, g0, g1, w, qa, qb, out.joints, out.figures)
            if self.nfig:
                self._roots(g0, g1, w, out)
            return out
        nfr = self.clip_nframes[clip]
        last = (nfr - 1).astype(np.float64)
        dur = np.asarray(duration, dtype=np.float64)
        total = np.where(dur > 0, dur, self.clip_duration[clip])
        elapsed = np.asarray(now, dtype=np.float64) - np.asarray(start_time, dtype=np.float64)
        safe_total = np.where(total > 0, total, 1.0)
        u = np.where(total > 0, np.clip(elapsed / safe_total, 0.0, 1.0), 1.0)
        u = np.where(np.asarray(direction) > 0, u, 1.0 - u)
        pos = np.multiply(u, last, out=out.position)
        np.greater_equal(elapsed, total, out=out.ended)
        base = self.clip_start[clip]
        if not interpolate:
            i0 = np.minimum(np.floor(pos + 0.5).astype(np.int64), nfr - 1)
            g = base + i0
            np.take(self.joint_data, g, axis=0, out=out.joints, mode="clip")
            np.take(self.fig_data, g, axis=0, out=out.figures, mode="clip")
            np.take(self.fig_root, g, axis=0, out=out.roots, mode="clip")
            return out
        i0 = np.minimum(np.floor(pos).astype(np.int64), nfr - 1)
        w = (pos - i0).astype(np.float32)
        g0 = base + i0
        g1 = base + np.minimum(i0 + 1, nfr - 1)
        # mode="clip": rows are valid by construction, and "raise" would buffer the output
        a = np.take(self.joint_data, g0, axis=0, out=out.joints, mode="clip")
        b = np.take(self.joint_data, g1, axis=0, out=out._scratch_j, mode="clip")
        b -= a
        b *= w[:, None]
        a += b
        if self.nfig:
            self._blend_figures(g0, g1, w, out)
        return out

    def _fresh(self, n: int) -> LibrarySample:
        """New output arrays (the caller keeps them) over this thread's reused work buffers: a tick of
        10,000 soldiers would otherwise take 4 MB of fresh scratch, page-faulted in on some ticks."""
        sc = scratch()
        return LibrarySample(
            joints=np.empty((n, self.ndof), np.float32),
            figures=np.empty((n, self.nfig, 7), np.float32),
            roots=np.empty((n, self.nfig), np.int16),
            ended=np.empty(n, bool),
            position=np.empty(n, np.float64),
            _scratch_j=sc.get("sample.joints", (n, self.ndof), np.float32),
            _scratch_f=sc.get("sample.figures", (n, self.nfig, 7), np.float32),
            _weights_a=sc.get("sample.weights_a", (n, self.nfig, 7), np.float32),
            _weights_b=sc.get("sample.weights_b", (n, self.nfig, 7), np.float32),
        )

    def _blend_figures(self, g0: np.ndarray, g1: np.ndarray, w: np.ndarray, out: LibrarySample) -> None:
        # Rows are (pos, quat) per figure. Both blends are a * wa + b * wb: lerp weights (1-t, t) for the
        # position, slerp weights sin((1-t)θ)/sinθ, ±sin(tθ)/sinθ (θ precomputed per row) for the quaternion.
        # Weights are expanded to full rows so every numpy call runs one long contiguous loop.
        fa = np.take(self.fig_data, g0, axis=0, out=out.figures, mode="clip")
        fb = np.take(self.fig_data, g1, axis=0, out=out._scratch_f, mode="clip")
        wa, wb = out._weights_a, out._weights_b
        qa, qb = self._slerp_weights(g0, w)
        rest = 1.0 - w
        for k in range(self.nfig):
            for c in range(3):
                wa[:, k, c] = rest
                wb[:, k, c] = w
        for c in range(3, 7):
            wa[..., c] = qa
            wb[..., c] = qb
        fa *= wa
        fb *= wb
        fa += fb
        self._roots(g0, g1, w, out)

    def _slerp_weights(self, g0: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, nfig) float32 slerp weights of the quaternions of rows ``g0`` and the next at ``w``."""
        theta = np.take(self._theta, g0, axis=0, mode="clip")
        t_theta = np.empty_like(theta)
        # filled a figure and a component at a time: numpy broadcasts an (n, 1) over a last axis of nfig (or
        # 3, 4) with an inner loop per row, 3-6 times dearer than these strided passes
        for k in range(self.nfig):
            np.multiply(theta[:, k], w, out=t_theta[:, k])
        qa = np.sin(theta - t_theta)
        qa *= np.take(self._inv_sin, g0, axis=0, mode="clip")
        qb = np.sin(t_theta, out=t_theta)
        qb *= np.take(self._inv_sin_next, g0, axis=0, mode="clip")
        return qa, qb

    def _roots(self, g0: np.ndarray, g1: np.ndarray, w: np.ndarray, out: LibrarySample) -> None:
        """The figures' root sites of rows ``g0``; a row re-rooted before the next shows the nearest frame."""
        fa = out.figures
        np.take(self.fig_root, g0, axis=0, out=out.roots, mode="clip")
        changed_rows = np.take(self._reroot_any, g0, mode="clip")
        if changed_rows.any():  # re-rooted between the two frames: show the nearest frame, never a blend
            idx = np.nonzero(self._reroot[g0])
            g_near = np.where(w[idx[0]] >= 0.5, g1[idx[0]], g0[idx[0]])
            fa[idx] = self.fig_data[g_near, idx[1]]
            out.roots[idx] = self.fig_root[g_near, idx[1]]
