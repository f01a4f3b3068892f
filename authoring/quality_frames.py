"""The motion library's clips played on their figures for the quality check: figures with cached kinematics,
mesh nodes, body parts and segment hulls, and every frame of a channelset as poses and root globals."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from authoring.body_parts import HAND_PARTS, KNEE_RADIUS_CM, SegmentHulls, part_of
from authoring.quality_limbs import part_hulls
from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset


class QualityError(Exception):
    """A library that cannot be checked (missing figure, unbindable channelset); carries the file."""

    def __init__(self, message: str, source: str | None = None) -> None:
        super().__init__(f"{source}: {message}" if source else message)
        self.source = source


@dataclass
class FigureSet:
    """Figures (by file type, e.g. ``"DI.fig"``) with cached kinematics and mesh nodes."""

    figures: dict[str, Figure]

    def __post_init__(self) -> None:
        self.kin = {t: FigureKinematics(f) for t, f in self.figures.items()}
        self._nodes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._cache: dict[str, Any] = {}

    @classmethod
    def from_dir(cls, folder: Path, types: Sequence[str]) -> FigureSet:
        from peabody.loader import read_figure

        figs = {}
        for t in types:
            path = Path(folder) / t
            if not path.is_file():
                raise QualityError(f"figure file {t!r} not found in {folder}")
            figs[t] = read_figure(path)
        return cls(figs)

    def nodes(self, ptype: str) -> tuple[np.ndarray, np.ndarray]:
        """Mesh nodes ``(k, 4)`` (homogeneous, segment frames) and their segments; sites if no psurfs."""
        hit = self._nodes.get(ptype)
        if hit is not None:
            return hit
        fig = self.figures[ptype]
        kin = self.kin[ptype]
        pts, segs = [], []
        for i, name in enumerate(kin.segment_names):
            seg = fig.segments[name]
            if seg.psurf is None or not len(seg.psurf.nodes):
                continue
            nodes = np.c_[
                np.asarray(seg.psurf.nodes, np.float64).reshape(-1, 3), np.ones(len(seg.psurf.nodes))
            ]
            if seg.psurf_transform is not None:
                nodes = nodes @ np.asarray(seg.psurf_transform).T
            pts.append(nodes)
            segs.append(np.full(len(nodes), i))
        if not pts:  # no geometry loaded: use the sites
            for s in fig.sites():
                if s.segment is None:
                    continue
                pts.append(np.asarray(s.location)[None, :, 3])
                segs.append(np.array([kin.segment_names.index(s.segment.name)]))
        out = (np.concatenate(pts), np.concatenate(segs))
        self._nodes[ptype] = out
        return out

    def node_parts(self, ptype: str) -> np.ndarray:
        """Per mesh node its body part (``left_foot``, ``chest``, ...; kneecap nodes are ``*_kneecap``)."""
        key = f"parts:{ptype}"
        hit = self._cache.get(key)
        if hit is None:
            nodes, segs = self.nodes(ptype)
            kin, fig = self.kin[ptype], self.figures[ptype]
            hit = np.array([part_of(kin.segment_names[s]) for s in segs], dtype=object)
            for side in ("left", "right"):
                name = f"{side}_lower_leg"
                if f"{name}.knee" not in kin.site_names:
                    continue
                knee = np.asarray(fig.site(f"{name}.knee").location)[:3, 3]
                near = np.linalg.norm(nodes[:, :3] - knee, axis=1) < KNEE_RADIUS_CM
                hit[(segs == kin.segment_names.index(name)) & near] = f"{side}_kneecap"
            self._cache[key] = hit
        return hit

    def hulls(self, ptype: str, hands: bool = False) -> SegmentHulls:
        """Convex hulls of the body segments a rifle must stay out of (all but the hands; ``hands``: every
        segment, e.g. what a dropped rifle may rest on)."""
        key = f"hulls:{ptype}:{hands}"
        hit = self._cache.get(key)
        if hit is None:
            nodes, segs = self.nodes(ptype)
            names = self.kin[ptype].segment_names
            keep = np.array(
                [s for s in np.unique(segs) if hands or part_of(names[s]) not in HAND_PARTS], dtype=int
            )
            hit = SegmentHulls.build(nodes, segs, keep)
            self._cache[key] = hit
        return hit

    def limb_hulls(self, ptype: str) -> dict[str, SegmentHulls]:
        """Per body part others must stay out of, its segments' hulls (:mod:`authoring.quality_limbs`)."""
        key = f"limbs:{ptype}"
        hit = self._cache.get(key)
        if hit is None:
            nodes, segs = self.nodes(ptype)
            hit = part_hulls(nodes, segs, list(self.kin[ptype].segment_names))
            self._cache[key] = hit
        return hit


@dataclass
class ClipFrames:
    """A channelset played on its figures: per figure file type, poses ``(n, ndof)`` and root globals."""

    channelset: Channelset
    poses: dict[str, np.ndarray]
    locations: dict[str, np.ndarray]


def play(channelset: Channelset, figures: FigureSet) -> ClipFrames:
    """Every frame of ``channelset`` as pose vectors and root-site globals for each figure type it drives."""
    types = sorted({c.protofiletype for c in channelset.channels})
    missing = [t for t in types if t not in figures.figures]
    if missing:
        raise QualityError(f"no figure of type {missing[0]!r} to play {channelset.name}", channelset.source)
    figs = [figures.figures[t] for t in types]
    bound = bind_channelset(channelset, figs)
    n = channelset.nframes
    poses, locs = {}, {}
    for bf in bound.figures:
        ptype = bf.protofiletype
        fig = figures.figures[ptype]
        kin = figures.kin[ptype]
        q = np.tile(bf.neutral.astype(np.float64), (n, 1))
        q[:, bf.dst] = channelset.joint_data[:, bf.src]
        if bf.figure_channel < 0:
            loc = np.broadcast_to(fig.location, (n, 4, 4)).copy()
        else:
            chan = next(c for c in channelset.figure_channels() if c.column == bf.figure_channel)
            loc = channelset.transforms(chan)
            roots = channelset.roots(chan)
            root = kin.root_name
            if any(r != root for r in roots):
                g = kin.site_globals(q, np.broadcast_to(np.eye(4), (n, 4, 4)))
                idx = np.array([kin.site_names.index(r) for r in roots])
                loc = loc @ np.linalg.inv(g[np.arange(n), idx]) @ g[:, kin.site_names.index(root)]
        poses[ptype] = q
        locs[ptype] = loc
    return ClipFrames(channelset, poses, locs)
