"""Parts on the ground stay put: a simulated clip's drift along the ground is taken out of its root.

The ragdoll of :mod:`authoring.deaths` skids: while a soldier's knees buckle and he pitches forward, the parts
he rests on slide 5-12 cm over the ground (MuJoCo's soft contacts under the muscles that shape the fall;
more friction, ``noslip``, ``impratio``, and pinning loaded parts with ``connect`` constraints did not stop
it). So the recorded frames are moved back horizontally, frame by frame, by how far the parts on the ground
moved: per part the mean motion of its mesh nodes that touched the ground (the check's contact height) in
this frame and the one before, averaged over those parts, accumulated from the first frame (which stays
where it is). The whole figure moves as one (root and rifle), so no pose changes: where the body skids as a
whole the skid is gone, where one part drags against the others it is only shared out.

A body landing on its side also turns on the ground as it skids (kfire2dead: its thigh slid 7.4 cm, belly
4 and chest 3.1 after the drift was out). :func:`plant_turns` takes out the turn about the vertical too: per
frame the rigid motion in the ground plane (a turn and a shift, least squares, each part weighing alike)
that carries the nodes on the ground in this frame and the one before back onto where they were.
"""

from __future__ import annotations

import numpy as np

from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.model import Figure


def ground_drift(points: np.ndarray, touching: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """``(n, 3)`` how far (cm, horizontal) the parts on the ground moved into each frame: ``points``
    ``(n, k, 3)`` mesh nodes per frame, ``touching`` ``(n, k)`` on the ground, ``parts`` ``(k,)`` their body
    parts; per part the mean motion of its nodes touching in both frames, averaged over the parts (0 with
    none)."""
    drift = np.zeros((len(points), 3))
    for f in range(1, len(points)):
        both = touching[f] & touching[f - 1]
        step = points[f] - points[f - 1]
        moves = [step[both & (parts == p)].mean(axis=0) for p in np.unique(parts[both])]
        if moves:
            drift[f] = np.mean(moves, axis=0)
    drift[:, 1] = 0.0
    return drift


def plant(frames: ClipFrames, soldier: Figure) -> ClipFrames:
    """``frames`` with the drift of the parts on the ground taken out (see the module docstring)."""
    figs = FigureSet({"body": soldier})
    nodes, segs = figs.nodes("body")
    g = figs.kin["body"].segment_globals(frames.poses, frames.roots)
    points = np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes)
    touching = points[..., 1] <= CONTACT_HEIGHT_CM
    shift = -np.cumsum(ground_drift(points, touching, figs.node_parts("body")), axis=0)
    roots, rifles = np.array(frames.roots), np.array(frames.rifles)
    roots[:, :3, 3] += shift
    rifles[:, :3, 3] += shift
    return ClipFrames(frames.poses, roots, rifles, frames.fps)


def ground_steps(points: np.ndarray, touching: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` per frame the rigid motion of the ground plane (homogeneous, on ``(x, z, 1)``) that
    carries the nodes touching in this frame and the one before (``points`` ``(n, k, 3)``, ``touching``
    ``(n, k)``, ``parts`` ``(k,)``) back onto where they were: least squares (Kabsch), each part weighing
    alike; none where fewer than 3 nodes touch in both."""
    steps = np.repeat(np.eye(3)[None], len(points), axis=0)
    for f in range(1, len(points)):
        both = touching[f] & touching[f - 1]
        if both.sum() < 3:
            continue
        a, b = points[f, both][:, [0, 2]], points[f - 1, both][:, [0, 2]]
        _, inverse, count = np.unique(parts[both], return_inverse=True, return_counts=True)
        w = 1.0 / count[inverse]
        w /= w.sum()
        ca, cb = w @ a, w @ b
        u, _, vt = np.linalg.svd(((a - ca) * w[:, None]).T @ (b - cb))
        turn = vt.T @ np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
        steps[f, :2, :2] = turn
        steps[f, :2, 2] = cb - turn @ ca
    return steps


def plant_turns(frames: ClipFrames, soldier: Figure) -> ClipFrames:
    """``frames`` with the shift and the turn on the ground of the parts on it taken out (see the module
    docstring), accumulated from the first frame; the rifle goes with the body (a dropped one too: the
    arms were laid beside it where it lies)."""
    figs = FigureSet({"body": soldier})
    nodes, segs = figs.nodes("body")
    g = figs.kin["body"].segment_globals(frames.poses, frames.roots)
    points = np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes)
    steps = ground_steps(points, points[..., 1] <= CONTACT_HEIGHT_CM, figs.node_parts("body"))
    moves = np.repeat(np.eye(4)[None], len(steps), axis=0)
    plane = np.eye(3)
    for f in range(len(steps)):
        plane = plane @ steps[f]
        moves[f][np.ix_([0, 2], [0, 2])] = plane[:2, :2]
        moves[f][[0, 2], 3] = plane[:2, 2]
    return ClipFrames(frames.poses, moves @ frames.roots, moves @ frames.rifles, frames.fps)
