"""Figures stood on the ground under their feet, not under their entity (issue 16, slopes).

The server places a figure up to a metre or more from its entity (the root offset: the figure trails its
entity through a step). The entity's Position DCS sits on the ground under the *entity*; on a slope the ground
under the figure is higher or lower by the slope times that offset, so uphill the feet sank into the terrain
(and its blob shadow with them) and downhill they floated. Here the figure's height is the ground under the
sole point carrying its weight: the entity is raised by how much higher the ground is under the feet (per
foot under its sole point nearest the ground, weighted by how near the foot is to being the lower one,
FOOT_BLEND_CM) than under the entity, so a pose's own height (a run's flight) is kept. While one foot
alone is down its xy is still, so the figure's height is too and the planted foot does not move up or down
with the terrain under the travelling root (grounding at the root's xy did: the slope times the stride);
the weight shifts to the other foot while the swing foot lands (the planted foot then moves by the slope
times half a step, smoothly). On flat ground the height is the entity's, whatever the pose.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from client_stub.stub.scene_graph import Crowd, EntityLayout

# the soldier's sole points, per foot (the same sites the recorder measures, client_stub.stub.feet)
FEET: tuple[tuple[str, str], ...] = (
    ("left_foot.heel", "left_foot.ball"),
    ("right_foot.heel", "right_foot.ball"),
)
FOOT_BLEND_CM = 1.5  # a foot this much higher than the lower one carries 1/e of the other's weight

RAY_START = 2.0  # metres above the entity the ground rays start (as SimSoldiers': under roofs, onto steps)
# (n, 2) xy, (n,) ray start heights (m) -> (n,) the ground heights under them (m)
Heights = Callable[[np.ndarray, np.ndarray], np.ndarray]


def body_figure(layout: EntityLayout) -> int:
    """The figure of an entity that is the soldier (the one with the most DOFs), not his rifle."""
    figs = layout.figures
    return max(range(len(figs)), key=lambda f: figs[f].ndof)


def has_soles(crowd: Crowd, body: int) -> bool:
    """Whether figure ``body`` of the crowd's layout has the sole sites the grounding reads."""
    sites = crowd.layout.figures[body].sites
    return all(s in sites for foot in FEET for s in foot)


def sole_world(crowd: Crowd, rows: np.ndarray, body: int) -> np.ndarray:
    """``(n, feet, points, 3)`` world positions (m) of the sole points of ``rows`` as the crowd shows them."""
    world = crowd.world(rows)
    feet = [np.stack([crowd.site_world(world, body, s)[:, :3, 3] for s in foot], axis=1) for foot in FEET]
    return np.stack(feet, axis=1)


def feet_ground(soles: np.ndarray, entity: np.ndarray, heights: Heights) -> np.ndarray:
    """``(n,)`` the entity height (m) that stands each figure on the ground under its feet.

    ``soles`` ``(n, feet, points, 3)`` are the sole points placed on entities at ``entity`` ``(n, 3)``. Per
    foot the point nearest the ground under it (the ball of a flat foot facing uphill, its heel downhill) says
    how much higher the ground is there than under the entity; the feet are blended by
    ``exp(-(a foot's height above the ground - the lower foot's) / FOOT_BLEND_CM)`` and the entity raised by
    that much, so the pose's own height above the ground (a run's flight, a kneel) is kept."""
    soles = np.asarray(soles, np.float64)
    entity = np.asarray(entity, np.float64).reshape(-1, 3)
    n = len(soles)
    if n == 0:
        return np.zeros(0)
    nfeet, npts = soles.shape[1], soles.shape[2]
    xy = np.concatenate([soles[..., :2].reshape(n, -1, 2), entity[:, None, :2]], axis=1).reshape(-1, 2)
    top = np.repeat(entity[:, 2] + RAY_START, nfeet * npts + 1)
    g = np.asarray(heights(xy, top), np.float64).reshape(n, -1)
    under, ground_e = g[:, :-1].reshape(n, nfeet, npts), g[:, -1]
    above = soles[..., 2] - under  # (n, feet, points): each sole point's height above the ground under it
    near = np.argmin(above, axis=2)[..., None]
    lift = np.take_along_axis(above, near, axis=2)[..., 0]  # (n, feet)
    rise = np.take_along_axis(under, near, axis=2)[..., 0] - ground_e[:, None]
    w = np.exp(-(lift - lift.min(axis=1, keepdims=True)) * 100.0 / FOOT_BLEND_CM)
    return entity[:, 2] + (rise * w).sum(axis=1) / w.sum(axis=1)


def ground_figures(crowd: Crowd, rows: np.ndarray, body: int, heights: Heights) -> np.ndarray:
    """Stand the figures of ``rows`` (their entity matrices already set) on the ground under their feet:
    their entity matrices' heights are replaced by :func:`feet_ground`. Returns the heights (m)."""
    rows = np.asarray(rows, np.int64)
    if not len(rows) or not has_soles(crowd, body):
        return crowd.entity[rows, 2, 3].copy()
    z = feet_ground(sole_world(crowd, rows, body), crowd.entity[rows, :3, 3], heights)
    matrices = crowd.entity[rows].copy()
    matrices[:, 2, 3] = z
    crowd.set_entity(rows, matrices)
    return z
