"""Small synthetic figures and clips, for tests and benchmarks that must not depend on shipped data.

A synthetic figure is a chain of segments ``s0 - s1 - ...`` joined by joints with 1-3 rotational DOFs (axes
cycling z, y, x), rooted at ``s0.proximal``: a valid Peabody model, so binding and FK work on it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from peabody.model import Dof, Figure, Joint, Segment, Site
from server.motion.channelset import Channelset, FigureTrack, JointTrack, make_channelset

_AXES = (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]))


def translation(x: float, y: float, z: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def make_figure(
    name: str, filename: str, joints: Sequence[tuple[str, int]], segment_length: float = 10.0
) -> Figure:
    """A chain figure with the given ``(joint name, DOF count)`` list; DOF values start at 0."""
    fig = Figure(name=name, filename=filename)
    segs = []
    for i in range(len(joints) + 1):
        seg = fig.add_segment(Segment(f"s{i}"))
        seg.add_site(Site("proximal", np.eye(4)))
        seg.add_site(Site("distal", translation(0.0, segment_length, 0.0)))
        segs.append(seg)
    for i, (jname, ndof) in enumerate(joints):
        dofs = [Dof("R", _AXES[k % 3]) for k in range(ndof)]
        fig.add_joint(Joint(jname, segs[i].sites["distal"], segs[i + 1].sites["proximal"], dofs))
    fig.root = segs[0].sites["proximal"]
    return fig


def make_soldier(name: str = "soldier", filename: str = "toy_soldier.fig", ndof: int = 50) -> Figure:
    """A chain figure with ``ndof`` DOFs in joints of 3, 2 and 1 DOFs (like DI.fig: 23 joints, 50 DOFs)."""
    spec: list[tuple[str, int]] = []
    left = ndof
    k = 0
    while left > 0:
        n = min((3, 2, 1)[k % 3], left)
        spec.append((f"j{k}", n))
        left -= n
        k += 1
    return make_figure(name, filename, spec)


def synthetic_channelset(
    name: str,
    figures: Sequence[Figure],
    nframes: int,
    fps: float = 60.0,
    seed: int = 0,
    root: str = "s0.proximal",
) -> Channelset:
    """A smooth random clip driving every joint of ``figures`` plus one figure channel per figure."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, nframes)[:, None]
    tracks: list[JointTrack | FigureTrack] = []
    for fig in figures:
        ptype = fig.filename or ""
        for jname, joint in fig.joints.items():
            a0, a1 = rng.uniform(-1.0, 1.0, (2, joint.ndofs))
            phase = rng.uniform(0, np.pi, joint.ndofs)
            angles = a0 + (a1 - a0) * t + 0.1 * np.sin(2 * np.pi * t + phase)
            tracks.append(JointTrack(jname, ptype, jname, angles))
        heading = rng.uniform(-np.pi, np.pi) + np.pi * t[:, 0]
        tr = np.tile(np.eye(4), (nframes, 1, 1))
        tr[:, 0, 0] = tr[:, 2, 2] = np.cos(heading)
        tr[:, 0, 2] = np.sin(heading)
        tr[:, 2, 0] = -np.sin(heading)
        tr[:, :3, 3] = rng.uniform(-50, 50, 3) + 100.0 * t
        tracks.append(FigureTrack(fig.name, ptype, fig.name, [root] * nframes, tr))
    return make_channelset(name, fps, tracks)


def toy_soldier(name: str = "soldier") -> Figure:
    """The 7-DOF soldier the test channelsets in ``tests/data/motion`` are recorded for."""
    return make_figure(
        name, "toy_soldier.fig", [("waist", 3), ("neck", 2), ("right_knee", 1), ("left_knee", 1)]
    )


def toy_rifle(name: str = "rifle") -> Figure:
    """A one-segment rifle (no joints, just a figure channel)."""
    return make_figure(name, "toy_rifle.fig", [])
