"""Planted feet as the image generator shows them: world-space slide of each sole point while it touches.

Measured on what the stub draws (the server's joint updates and root offset on the dead-reckoned entity),
so a recording says in numbers what a person checks by eye: a heel or ball that touches the ground should
stay where it landed until it lifts. The same measure as the server's scenario tests
(``tests/test_root_motion.py``), taken at the other end of the wire.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from client_stub.stub.app import StubApp
from client_stub.stub.grounding import body_figure

SOLE_SITES = ("left_foot.heel", "left_foot.ball", "right_foot.heel", "right_foot.ball")
CONTACT_CM = 1.0  # a sole point this near the lowest any sole point got above the ground touches it


@dataclass(frozen=True)
class Touchdown:
    start: float  # s
    end: float
    site: str
    slide_cm: float  # farthest the point got, horizontally, from where it landed while it stayed down


def sole_points(app: StubApp, slot: int) -> np.ndarray | None:
    """``(len(SOLE_SITES), 3)`` world positions (m) of the soldier's sole points (None: no such sites)."""
    kind = app.kinds[int(app.slot_kind[slot])]
    figs = kind.layout.figures
    body = body_figure(kind.layout)
    if not all(s in figs[body].sites for s in SOLE_SITES):
        return None
    world = kind.crowd.world(np.array([slot]))
    return np.array([kind.crowd.site_world(world, body, s)[0, :3, 3] for s in SOLE_SITES])


def heights_above(points: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """``(n, sites)`` cm each sole point is above the ground: ``ground`` ``(n, sites)`` m, the ground under
    each point (on a slope the ground under the entity is not the ground under the feet), or ``(n,)``."""
    g = np.asarray(ground, np.float64)
    g = g[:, None] if g.ndim == 1 else g
    return (np.asarray(points, np.float64)[..., 2] - g) * 100.0


def touchdowns(points: np.ndarray, ground: np.ndarray, hz: float) -> list[Touchdown]:
    """Every stretch of frames a sole point touches: ``points`` ``(n, sites, 3)`` m, ``ground`` the ground
    under them (:func:`heights_above`)."""
    pts = np.asarray(points, np.float64) * 100.0
    height = heights_above(points, ground)
    down = height < height.min() + CONTACT_CM
    out = []
    for p, site in enumerate(SOLE_SITES):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], down[:, p].astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            track = pts[a:b, p, :2]
            slide = float(np.linalg.norm(track - track[0], axis=1).max())
            out.append(Touchdown(a / hz, (b - 1) / hz, site, round(slide, 2)))
    return sorted(out, key=lambda d: (d.start, d.site))


def worst_by_window(
    downs: list[Touchdown], starts: list[float], lowest: np.ndarray | None = None, hz: float = 1.0
) -> list[dict]:
    """Per window ``[starts[i], starts[i+1])``: the touchdowns beginning there and the largest slide; with
    ``lowest`` (per frame at ``hz`` the lowest sole point's height above the ground under it, cm) also its
    range over the window's frames (``sole_above_ground_cm``: ~0 when the feet stand on the ground)."""
    bounds = [*starts, np.inf]
    out = []
    for a, b in itertools.pairwise(bounds):
        mine = [d.slide_cm for d in downs if a <= d.start < b]
        w: dict = {"from_s": a, "touchdowns": len(mine), "max_slide_cm": max(mine) if mine else None}
        if lowest is not None:
            t = np.arange(len(lowest)) / hz
            seen = np.asarray(lowest)[(t >= a) & (t < b)]
            span = [round(float(seen.min()), 2), round(float(seen.max()), 2)] if len(seen) else None
            w["sole_above_ground_cm"] = span
        out.append(w)
    return out
