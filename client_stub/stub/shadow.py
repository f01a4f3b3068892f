"""Blob shadows: a soft dark ellipse on the ground under each soldier, so he sits on it.

No shadow maps (llvmpipe could not afford them): per soldier, an ellipse over the footprint of his joints in
his entity's frame (a standing soldier's is about round and under his feet, a prone one's long), at the
ground height of the entity. :func:`shadow_matrices` maps the unit square/disc onto it; the moderngl
renderer draws quads with a radial fade, the pyrender one an instanced disc whose vertex alpha fades out.
"""

from __future__ import annotations

import numpy as np

SHADOW_ALPHA = 0.45
SHADOW_LIFT_M = 0.04  # above the ground under the entity, so the depth test keeps it over the terrain
SHADOW_MARGIN_M = 0.18  # beyond the outermost joints
CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]])


def shadow_matrices(world: np.ndarray, margin: float = SHADOW_MARGIN_M) -> np.ndarray:
    """``(n, 4, 4)``: the unit square ``[-1, 1]²`` (z = 0) onto each soldier's shadow, for soldiers whose
    scene-graph node matrices are ``world`` ``(n, nodes, 4, 4)`` (node 0: the entity)."""
    entity = world[:, 0]
    local = np.einsum(
        "nij,nkj->nki", np.linalg.inv(entity)[:, :3, :3], world[:, 1:, :3, 3] - entity[:, None, :3, 3]
    )
    lo = local[..., :2].min(axis=1) - margin
    hi = local[..., :2].max(axis=1) + margin
    placement = np.broadcast_to(np.eye(4), (len(world), 4, 4)).copy()
    placement[:, 0, 0], placement[:, 1, 1] = (hi - lo).T / 2 * 1.15
    placement[:, :2, 3] = (lo + hi) / 2
    placement[:, 2, 3] = SHADOW_LIFT_M
    return entity @ placement


def shadow_quads(world: np.ndarray) -> np.ndarray:
    """``(n, 4, 5)`` shadow quad corners (x, y, z, u, v), ``(u, v)`` in ``[-1, 1]²``."""
    if not len(world):
        return np.zeros((0, 4, 5), np.float32)
    corners = np.column_stack([CORNERS, np.zeros(4), np.ones(4)])
    points = np.einsum("nij,kj->nki", shadow_matrices(world), corners)[..., :3]
    return np.concatenate([points, np.broadcast_to(CORNERS, (len(world), 4, 2))], axis=2).astype(np.float32)


def shadow_disc(segments: int = 24) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit disc (z = 0) as positions, RGBA colours (black; alpha full inside r = 0.45, fading to 0 at
    the rim, as the moderngl renderer's smoothstep) and triangle indices."""
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([np.cos(a), np.sin(a), np.zeros(segments)])
    positions = np.concatenate([np.zeros((1, 3)), 0.45 * ring, ring]).astype(np.float32)
    alpha = np.concatenate([[SHADOW_ALPHA], np.full(segments, SHADOW_ALPHA), np.zeros(segments)])
    colours = np.column_stack([np.zeros((len(positions), 3)), alpha]).astype(np.float32)
    k = np.arange(segments)
    inner, outer, nxt = 1 + k, 1 + segments + k, (k + 1) % segments
    fan = np.column_stack([np.zeros(segments, np.int64), inner, 1 + nxt])
    band = np.concatenate([np.column_stack([inner, outer, 1 + segments + nxt]),
                           np.column_stack([inner, 1 + segments + nxt, 1 + nxt])])  # fmt: skip
    return positions, colours, np.concatenate([fan, band]).astype(np.uint32)
