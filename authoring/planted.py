"""Parts on the ground stay put: a simulated clip's drift along the ground is taken out of its root.

The ragdoll of :mod:`authoring.deaths` skids: while a soldier's knees buckle and he pitches forward, the parts
he rests on slide 5-12 cm over the ground (MuJoCo's soft contacts under the muscles that shape the fall;
more friction, ``noslip``, ``impratio``, and pinning loaded parts with ``connect`` constraints did not stop
it). So the recorded frames are moved back horizontally, frame by frame, by how far the parts on the ground
moved: per part the mean motion of its mesh nodes that touched the ground (the check's contact height) in
this frame and the one before, averaged over those parts, accumulated from the first frame (which stays
where it is). The whole figure moves as one (root and rifle), so no pose changes: where the body skids as a
whole the skid is gone, where one part drags against the others it is only shared out.
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
