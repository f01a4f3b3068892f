"""Vertical ray casts into the terrain (seed 002, 7.4): the ground height under each soldier's feet.

"Our geometry being defined such that the coordinate origin is located between the human's feet, this is a
simple matter of casting a vertical ray into the scene". A vertical ray only needs the triangles whose
footprint (their XY projection) covers the point, so the triangles are bucketed once into a uniform XY grid
(a CSR table: cell -> triangles) and a batch of rays is answered with a handful of vectorised array
operations: gather the candidates of every ray's cell, barycentric test in XY, interpolate z, keep the
highest hit below the ray's start. Walls (no footprint) are never hit. This is the answer trimesh's
ray-triangle intersector gives for rays ``(x, y, z_from) -> -Z`` (tests compare them), without its rtree.
"""

from __future__ import annotations

import numpy as np

MAX_CELL_ENTRIES = 4_000_000  # memory bound of the bucket table; the cell size grows until it fits


class GroundQuery:
    """Heights of a triangle mesh (Performer axes, +Z up) under batches of points."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, cell: float | None = None) -> None:
        v = np.asarray(vertices, np.float64)
        t = np.asarray(triangles, np.int64).reshape(-1, 3)
        p0, p1, p2 = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
        e1 = p1[:, :2] - p0[:, :2]
        e2 = p2[:, :2] - p0[:, :2]
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        lo = np.minimum(np.minimum(p0, p1), p2)[:, :2]
        hi = np.maximum(np.maximum(p0, p1), p2)[:, :2]
        size = np.maximum(hi - lo, 0.0).max(axis=1)
        keep = np.abs(det) > 1e-12 * np.maximum(size, 1e-9) ** 2
        self._p0 = p0[keep]
        self._dz1 = (p1 - p0)[keep, 2]
        self._dz2 = (p2 - p0)[keep, 2]
        self._e1 = e1[keep]
        self._e2 = e2[keep]
        self._inv = 1.0 / det[keep]
        lo, hi, size = lo[keep], hi[keep], size[keep]
        self.ntriangles = int(keep.sum())
        if self.ntriangles == 0:
            self.origin = np.zeros(2)
            self.cell = 1.0
            self.shape = (1, 1)
            self._start = np.zeros(2, np.int64)
            self._order = np.zeros(0, np.int64)
            self.bounds = np.zeros((2, 3))
            return
        self.bounds = np.stack([v[t[keep]].reshape(-1, 3).min(0), v[t[keep]].reshape(-1, 3).max(0)])
        self.origin = lo.min(axis=0)
        extent = np.maximum(hi.max(axis=0) - self.origin, 1e-6)
        cell = float(cell) if cell else float(np.clip(2.0 * np.median(size), 0.05, 100.0))
        while True:
            shape = np.maximum(np.ceil(extent / cell).astype(np.int64), 1)
            i0 = np.clip(((lo - self.origin) // cell).astype(np.int64), 0, shape - 1)
            i1 = np.clip(((hi - self.origin) // cell).astype(np.int64), 0, shape - 1)
            spans = (i1 - i0 + 1).prod(axis=1)
            if spans.sum() <= MAX_CELL_ENTRIES:
                break
            cell *= 2.0
        self.cell = cell
        self.shape = (int(shape[0]), int(shape[1]))
        # every (triangle, covered cell) pair, vectorised: per triangle a rectangle of cells
        tri = np.repeat(np.arange(len(spans)), spans)
        k = np.arange(spans.sum()) - np.repeat(np.cumsum(spans) - spans, spans)
        width = (i1[:, 0] - i0[:, 0] + 1)[tri]
        cx = i0[tri, 0] + k % width
        cy = i0[tri, 1] + k // width
        cells = cx * self.shape[1] + cy
        order = np.argsort(cells, kind="stable")
        self._order = tri[order]
        counts = np.bincount(cells, minlength=self.shape[0] * self.shape[1])
        self._start = np.concatenate([[0], np.cumsum(counts)])

    def heights(self, xy: np.ndarray, z_from: np.ndarray | float = np.inf) -> np.ndarray:
        """Height of the highest surface at or below ``z_from`` under each point ``(..., 2)``; NaN if none.

        ``z_from`` is where each ray starts (default: above everything, so a roof is found before the
        street under it)."""
        xy = np.asarray(xy, np.float64)
        shape = xy.shape[:-1]
        pts = xy.reshape(-1, 2)
        zf = np.broadcast_to(np.asarray(z_from, np.float64), shape).reshape(-1)
        out = np.full(len(pts), np.nan)
        if self.ntriangles == 0 or not len(pts):
            return out.reshape(shape)
        ij = np.floor((pts - self.origin) / self.cell).astype(np.int64)
        inside = (ij >= 0).all(axis=1) & (ij[:, 0] < self.shape[0]) & (ij[:, 1] < self.shape[1])
        rays = np.flatnonzero(inside)
        cell = ij[rays, 0] * self.shape[1] + ij[rays, 1]
        first = self._start[cell]
        count = self._start[cell + 1] - first
        ray = np.repeat(rays, count)
        k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        tri = self._order[np.repeat(first, count) + k]
        d = pts[ray] - self._p0[tri, :2]
        a = (d[:, 0] * self._e2[tri, 1] - d[:, 1] * self._e2[tri, 0]) * self._inv[tri]
        b = (self._e1[tri, 0] * d[:, 1] - self._e1[tri, 1] * d[:, 0]) * self._inv[tri]
        eps = 1e-9
        hit = (a >= -eps) & (b >= -eps) & (a + b <= 1.0 + eps)
        z = self._p0[tri, 2] + a * self._dz1[tri] + b * self._dz2[tri]
        hit &= z <= zf[ray] + 1e-6
        best = np.full(len(pts), -np.inf)
        np.maximum.at(best, ray[hit], z[hit])
        found = np.isfinite(best)
        out[found] = best[found]
        return out.reshape(shape)
