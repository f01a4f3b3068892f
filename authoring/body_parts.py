"""Body parts of a soldier figure for the quality check: which mesh nodes touch the ground, how far they
slide while they do, and how deep a rifle goes into the body.

Parts are named by what a viewer sees (``left_foot``, ``right_knee``, ``left_forearm``, ``chest``, ...) and
found from segment names, so DI.fig (one thoracic segment) and soldier.fig (t1..t12, finger segments) map
to the same parts. Everything here is vectorised over frames and nodes: one contact run is a stretch of
frames where a node is below the contact height, and its slide is the horizontal extent of the node's
positions over the run (the largest spread of their projections on ``DIRECTIONS`` ground directions, at
most 0.5 % short of the true diameter).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

DIRECTIONS = 16
_ANGLES = np.arange(DIRECTIONS) * np.pi / DIRECTIONS
# (2, DIRECTIONS) unit ground directions (X, Z) over a half turn: a spread is the largest of its projections
GROUND_DIRECTIONS = np.stack([np.cos(_ANGLES), np.sin(_ANGLES)])
CHUNK = 4096  # hull-depth candidates per batch
SIDE_PARTS = (
    (re.compile(r"(foot|toes)$"), "foot"),
    (re.compile(r"lower_leg$"), "knee"),
    (re.compile(r"upper_leg$"), "thigh"),
    (re.compile(r"(palm|thumb\d|index\d|middle\d|ring\d|pinky\d)$"), "hand"),
    (re.compile(r"lower_arm$"), "forearm"),
    (re.compile(r"upper_arm$"), "upper_arm"),
    (re.compile(r"clavicle$"), "chest"),
    (re.compile(r"eyeball$"), "head"),
)
TRUNK_PARTS = (
    (re.compile(r"^(upper_torso|thoracic|t\d+)$"), "chest"),
    (re.compile(r"^(middle_torso|lumbar|l\d+)$"), "belly"),
    (re.compile(r"^lower_torso$"), "pelvis"),
    (re.compile(r"^(neck|bottom_head|eyes|head)$"), "head"),
)
FOOT_PARTS = ("left_foot", "right_foot")
HAND_PARTS = ("left_hand", "right_hand")
REST_SLACK_CM = (
    0.1  # cm: a node at rest at a resting end stays on the ground while no higher than this above it
)
KNEE_RADIUS_CM = 10.0  # lower-leg nodes this close to the ``knee`` site make up the kneecap


def part_of(segment: str) -> str:
    """The body part a segment belongs to (``left_toes`` -> ``left_foot``); unknown names are their own."""
    for side in ("left", "right"):
        if segment.startswith(side + "_"):
            rest = segment[len(side) + 1 :]
            for pattern, part in SIDE_PARTS:
                if pattern.search(rest):
                    return part if part in ("chest", "head") else f"{side}_{part}"
            return segment
    for pattern, part in TRUNK_PARTS:
        if pattern.match(segment):
            return part
    return segment


@dataclass
class ContactRuns:
    """Every run of frames a node spends below the contact height: its node, first and last frame, and the
    horizontal extent (cm) of the node's positions over the run."""

    node: np.ndarray
    first: np.ndarray
    last: np.ndarray
    slide: np.ndarray

    def per_node(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Per node of ``k``: the largest slide over one run and the number of runs."""
        slide = np.zeros(k)
        runs = np.zeros(k, dtype=int)
        np.maximum.at(slide, self.node, self.slide)
        np.add.at(runs, self.node, 1)
        return slide, runs

    def worst(self, mask: np.ndarray) -> int | None:
        """Index of the run that slides furthest among the nodes in ``mask`` (None without a run)."""
        pick = np.flatnonzero(mask[self.node])
        return None if not len(pick) else int(pick[np.argmax(self.slide[pick])])


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of each run of True in the 1-D ``mask``."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def ground_extent(xz: np.ndarray) -> float:
    """Horizontal spread (cm) of ground points ``(m, 2)`` (X, Z): the largest extent of their projections on
    :data:`GROUND_DIRECTIONS`, as a contact run's slide is measured."""
    proj = xz @ GROUND_DIRECTIONS
    return float((proj.max(axis=0) - proj.min(axis=0)).max())


def contact_runs(
    points: np.ndarray,
    height: float,
    release: np.ndarray | float | None = None,
    rest_ends: tuple[bool, bool] = (False, False),
) -> ContactRuns:
    """The contact runs of the nodes of ``points`` ``(n, k, 3)`` (world, cm, +Y up). Contact is judged by
    height alone, so a fast skim just above the ground counts as sliding. With ``release`` (cm, one for
    every node or per node ``(k,)``, at least ``height``), a node that comes down to ``height`` is on the
    ground for as long as it stays below ``release`` either side of it: one dragged just above ``height``
    as it lifts off still slides, one that never comes down to ``height`` is in the air. ``rest_ends``:
    whether the first and the last frame are resting postures; a node below ``release`` there rests on the
    ground for as long as it stays no higher than it rests there (:func:`_resting`; the posture check's
    ``rest_contact_cm`` holds a part within 2 cm as resting: DI's right elbow lies 1.58 cm up in
    PRONE_FIRE, and a recoil that slid it 3.3 cm while it dipped to 1.31 cm read 0)."""
    n, _, _ = points.shape
    heights = points[..., 1]
    near = heights <= (height if release is None else np.maximum(release, height))
    touching = np.flatnonzero(
        (heights <= height).any(axis=0) | (near[0] & rest_ends[0]) | (near[-1] & rest_ends[1])
    )
    if not len(touching):
        empty = np.zeros(0, dtype=int)
        return ContactRuns(empty, empty, empty, np.zeros(0))
    c = np.zeros((len(touching), n + 1), dtype=bool)  # a separator frame between nodes
    c[:, :n] = near[:, touching].T
    flat = c.ravel()
    starts = np.flatnonzero(flat & ~np.r_[False, flat[:-1]])
    stops = np.flatnonzero(flat & ~np.r_[flat[1:], False])
    if release is not None:  # a run near the ground that never comes down to it is in the air
        y = np.full((len(touching), n + 1), np.inf)
        y[:, :n] = heights[:, touching].T
        down = np.minimum.reduceat(np.where(flat, y.ravel(), np.inf), starts) <= height
        starts, stops = starts[down], stops[down]
        edges = np.zeros(len(flat) + 1, dtype=int)
        np.add.at(edges, starts, 1)
        np.add.at(edges, stops + 1, -1)
        flat = np.cumsum(edges[:-1]) > 0
        if any(rest_ends):
            flat |= _resting(y[:, :n], height, near[:, touching].T, rest_ends).ravel()
            starts = np.flatnonzero(flat & ~np.r_[False, flat[:-1]])
            stops = np.flatnonzero(flat & ~np.r_[flat[1:], False])
    proj = np.zeros((len(touching), n + 1, DIRECTIONS))
    proj[:, :n] = points[:, touching][..., [0, 2]].transpose(1, 0, 2) @ GROUND_DIRECTIONS
    proj = proj.reshape(-1, DIRECTIONS)
    hi = np.maximum.reduceat(np.where(flat[:, None], proj, -np.inf), starts, axis=0)
    lo = np.minimum.reduceat(np.where(flat[:, None], proj, np.inf), starts, axis=0)
    return ContactRuns(touching[starts // (n + 1)], starts % (n + 1), stops % (n + 1), (hi - lo).max(axis=1))


def _resting(y: np.ndarray, height: float, near: np.ndarray, rest_ends: tuple[bool, bool]) -> np.ndarray:
    """Per node of heights ``y`` ``(m, n)`` (frames along axis 1), the frames ``(m, n + 1)`` (a separator
    frame last) of its rest at each resting end of ``rest_ends`` where it is ``near`` the ground: the
    frames from that end over which it stays no higher than it rests there (:data:`REST_SLACK_CM`). A
    limb landing at a shallow angle near the ground before it rests there is not on the ground yet."""
    m, n = y.shape
    out = np.zeros((m, n + 1), dtype=bool)
    for end, at in ((rest_ends[0], 0), (rest_ends[1], n - 1)):
        if not end:
            continue
        level = np.maximum(y[:, at], height) + REST_SLACK_CM
        ok = (y <= level[:, None]) & near & near[:, at : at + 1]
        run = np.logical_and.accumulate(ok if at == 0 else ok[:, ::-1], axis=1)
        out[:, :n] |= run if at == 0 else run[:, ::-1]
    return out


def contact_slides(points: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Per node of ``points`` ``(n, k, 3)``: the largest horizontal slide (cm) over one run of frames below
    ``height``, and the number of such runs (see :func:`contact_runs`)."""
    return contact_runs(points, height).per_node(points.shape[1])


@dataclass
class SegmentHulls:
    """Convex hulls of body segments in their own frames: ``equations`` ``(m, F, 4)`` (outward normals and
    offsets, padded with never-binding rows), bounding spheres ``centres`` ``(m, 3)`` / ``radii``."""

    segments: np.ndarray
    equations: np.ndarray
    centres: np.ndarray
    radii: np.ndarray

    @classmethod
    def build(cls, nodes: np.ndarray, segs: np.ndarray, keep: np.ndarray) -> SegmentHulls:
        """Hulls (scipy's Qhull) of the mesh nodes ``(k, 4)`` of every segment index in ``keep``."""
        from scipy.spatial import ConvexHull, QhullError

        idx, eqs, cen, rad = [], [], [], []
        for s in keep:
            pts = nodes[segs == s, :3]
            if len(pts) < 4:
                continue
            try:
                hull = ConvexHull(pts)
            except QhullError:  # flat or degenerate: nothing to be inside of
                continue
            c = pts.mean(axis=0)
            idx.append(int(s))
            eqs.append(hull.equations)
            cen.append(c)
            rad.append(float(np.linalg.norm(pts - c, axis=1).max()))
        f = max((len(e) for e in eqs), default=1)
        pad = np.zeros((len(eqs), f, 4))
        pad[..., 3] = -1e9  # 0 . p - 1e9 < 0: a padding row never limits the depth
        for i, e in enumerate(eqs):
            pad[i, : len(e)] = e
        return cls(np.array(idx, dtype=int), pad, np.array(cen).reshape(-1, 3), np.array(rad))

    def depth(self, points: np.ndarray, seg_globals: np.ndarray) -> tuple[float, int, int]:
        """Deepest penetration (cm) of ``points`` ``(n, k, 3)`` (world) into any hull, with its frame and
        segment index (``-1`` when nothing is inside). ``seg_globals``: ``(n, nseg, 4, 4)``."""
        return self.deepest(points, seg_globals)[:3]

    def deepest(self, points: np.ndarray, seg_globals: np.ndarray) -> tuple[float, int, int, int]:
        """:meth:`depth` and the index (of ``k``) of the deepest point (``-1`` when nothing is inside)."""
        f, m, p, d, _ = self._inside(points, seg_globals)
        if not len(f) or d.max() <= 0:
            return 0.0, -1, -1, -1
        best = int(np.argmax(d))
        return float(d[best]), int(f[best]), int(self.segments[m[best]]), int(p[best])

    def clearance(self, points: np.ndarray, seg_globals: np.ndarray) -> np.ndarray:
        """Per point ``(k, 3)`` (world) a lower bound of its distance (cm) outside the nearest hull (the
        largest of its face distances; negative inside), for one frame's ``seg_globals`` ``(nseg, 4, 4)``
        (every hull, no bounding-sphere cut: a point just outside one counts)."""
        if not len(self.segments):
            return np.full(len(points), np.inf)
        g = seg_globals[self.segments]  # (m, 4, 4)
        local = np.einsum("mji,mkj->mki", g[:, :3, :3], points[None, :, :] - g[:, None, :3, 3])
        gap = np.einsum("mfi,mki->mkf", self.equations[..., :3], local) + self.equations[:, None, :, 3]
        return np.asarray(gap.max(axis=2).min(axis=0))

    def exits(self, points: np.ndarray, seg_globals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per frame of ``points`` ``(n, k, 3)``: the deepest point's depth in a hull (cm, 0 when nothing is
        inside) and the world direction ``(n, 3)`` out of that hull through its nearest face."""
        n = len(points)
        depth, out = np.zeros(n), np.zeros((n, 3))
        f, m, _, d, normal = self._inside(points, seg_globals)
        for i in np.argsort(d):  # the deepest of each frame last
            if d[i] > depth[f[i]]:
                depth[f[i]], out[f[i]] = d[i], seg_globals[f[i], self.segments[m[i]], :3, :3] @ normal[i]
        return depth, out

    def _inside(
        self, points: np.ndarray, seg_globals: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The (frame, hull, point) of every point within a hull's bounding sphere, its depth inside the hull
        (cm, negative outside) and the normal of the face it is nearest to (the hull's frame)."""
        empty = np.zeros(0, dtype=int)
        if not len(self.segments):
            return empty, empty, empty, np.zeros(0), np.zeros((0, 3))
        g = seg_globals[:, self.segments]  # (n, m, 4, 4)
        centre = np.einsum("fmij,mj->fmi", g[..., :3, :3], self.centres) + g[..., :3, 3]
        near = (
            np.linalg.norm(points[:, None, :, :] - centre[:, :, None, :], axis=-1) < self.radii[None, :, None]
        )
        f, m, p = np.nonzero(near)
        d = np.empty(len(f))
        normal = np.empty((len(f), 3))
        for a in range(0, len(f), CHUNK):  # bounded memory: candidates x hull faces
            b = slice(a, a + CHUNK)
            rot, org = g[f[b], m[b], :3, :3], g[f[b], m[b], :3, 3]
            local = np.einsum("cji,cj->ci", rot, points[f[b], p[b]] - org)  # world -> segment frame
            eq = self.equations[m[b]]
            gap = -(np.einsum("cfi,ci->cf", eq[..., :3], local) + eq[..., 3])
            face = np.argmin(gap, axis=1)
            d[b] = gap[np.arange(len(face)), face]
            normal[b] = eq[np.arange(len(face)), face, :3]
        return f, m, p, d, normal
