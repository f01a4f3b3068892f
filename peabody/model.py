"""The Peabody data model (seed 000, chapter 7): environment, figures, segments, sites, joints, DOFs.

Conventions (fixed for the whole project):

* Transforms are 4x4 float64 numpy arrays acting on **column vectors** (``p_world = T @ p_local``).
* Lengths are centimetres, angles radians, Jack axes (+Y up, zero heading along -Z).
* A joint's displacement goes *from site1 to site2*; its DOFs compose **left to right in local frames**:
  ``D = dof[0] @ dof[1] @ ... @ dof[n-1]`` (7.2.5.2).
* Globals: ``segment_global(seg2) = site_global(site1) @ D @ inv(site2.location)`` across a joint,
  ``site_global(site) = segment_global(site.segment) @ site.location``.

The spanning tree from the world (7.2.2) and forward kinematics live in :mod:`peabody.fk`;
this module only holds the objects and their names.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

DofKind = Literal["R", "T"]


def identity() -> np.ndarray:
    return np.eye(4)


@dataclass
class Dof:
    """One degree of freedom: a rotation (radians) or translation (cm) about/along ``axis``."""

    kind: DofKind
    axis: np.ndarray  # (3,) unit vector in the joint's current local frame
    lower: float = -np.inf
    upper: float = np.inf
    value: float = 0.0  # the current angle/distance ("displacement" in the language)

    def __post_init__(self) -> None:
        self.axis = np.asarray(self.axis, dtype=np.float64).reshape(3)


@dataclass
class Psurf:
    """Polygonal surface (chapter 8): 0-based indices in memory, 1-based in ``.pss`` files."""

    nodes: np.ndarray  # (n, 3) float64, cm, segment frame
    faces: list[np.ndarray]  # each a 1-D int array of node indices (polygons, any size)
    face_attributes: np.ndarray | None = None  # (f,) int attribute index per face
    attributes: list[dict] = field(default_factory=list)  # {"name":..., "ambient":..., "diffuse":..., ...}
    filename: str | None = None
    # (e, 2) 0-based node pairs listed in the file's edge section, or None (psurf.psurf_edges computes them)
    edges: np.ndarray | None = None
    # (nnodes, nedges, nfaces) per csurf (8.3), in order; empty means one csurf holding everything
    csurfs: list[tuple[int, int, int]] = field(default_factory=list)

    @property
    def polygon_count(self) -> int:
        return len(self.faces)


@dataclass
class Site:
    name: str
    location: np.ndarray = field(default_factory=identity)  # relative to its segment
    segment: Segment | None = field(default=None, repr=False)

    @property
    def fullname(self) -> str:
        seg = self.segment
        if seg is None:
            return self.name
        return f"{seg.fullname}.{self.name}"


@dataclass
class Segment:
    name: str
    sites: dict[str, Site] = field(default_factory=dict)
    psurf: Psurf | None = None
    psurf_file: str | None = None  # as written in the file (relative path)
    psurf_transform: np.ndarray | None = None  # `psurf = "x.pss" * scale(...)`
    figure: Figure | None = field(default=None, repr=False)
    attributes: dict[str, object] = field(default_factory=dict)  # other assignments, kept for round trips

    @property
    def fullname(self) -> str:
        return self.name if self.figure is None else f"{self.figure.name}.{self.name}"

    def add_site(self, site: Site) -> Site:
        site.segment = self
        self.sites[site.name] = site
        return site


@dataclass
class Joint:
    name: str
    site1: Site
    site2: Site
    dofs: list[Dof] = field(default_factory=list)
    displacement: np.ndarray = field(default_factory=identity)  # used only when there are no DOFs
    figure: Figure | None = field(default=None, repr=False)

    @property
    def fullname(self) -> str:
        return self.name if self.figure is None else f"{self.figure.name}.{self.name}"

    @property
    def ndofs(self) -> int:
        return len(self.dofs)


@dataclass
class Figure:
    name: str
    segments: dict[str, Segment] = field(default_factory=dict)
    joints: dict[str, Joint] = field(default_factory=dict)
    root: Site | None = None
    location: np.ndarray = field(default_factory=identity)  # global transform of the root site
    filename: str | None = None  # the figure file it was read from ("DI.fig"): the protofiletype
    source: str | None = None  # absolute path of that file when instantiated with `file = "DI.fig";`

    def add_segment(self, segment: Segment) -> Segment:
        segment.figure = self
        self.segments[segment.name] = segment
        return segment

    def add_joint(self, joint: Joint) -> Joint:
        joint.figure = self
        self.joints[joint.name] = joint
        return joint

    def sites(self) -> list[Site]:
        return [s for seg in self.segments.values() for s in seg.sites.values()]

    def site(self, dotted: str) -> Site:
        """Find ``segment.site`` (local to this figure)."""
        seg_name, _, site_name = dotted.partition(".")
        try:
            return self.segments[seg_name].sites[site_name]
        except KeyError:
            raise KeyError(f"figure {self.name!r} has no site {dotted!r}") from None

    @property
    def dof_count(self) -> int:
        return sum(j.ndofs for j in self.joints.values())


@dataclass
class Environment:
    """All figures plus the immovable ``world`` segment (which has site ``base``)."""

    figures: dict[str, Figure] = field(default_factory=dict)
    world: Segment = field(default_factory=lambda: Segment("world", sites={}))
    # extension blocks (e.g. channelsets) register their objects here by block keyword
    extensions: dict[str, dict[str, object]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if "base" not in self.world.sites:
            self.world.add_site(Site("base"))

    def add_figure(self, figure: Figure) -> Figure:
        self.figures[figure.name] = figure
        return figure
