"""The slave's held rifle kept out of his body.

Slaving copies the master's rifle unchanged, and DI.fig is shaped differently from soldier.fig: prone, with
its higher shoulders turned down by the chest to lay the forearms on the ground
(:func:`authoring.slave_contacts.rest_slave_forearms`), its right upper arm swells 1-2 cm into the stock
that only touches the master's. Where the held rifle is inside a body segment's hull (the quality check's
``rifle_in_body_cm``), it is slid out of it sideways: across its barrel and level, the way out of the hull
it is deepest in (the normal of the face nearest its deepest node, less its parts along the barrel and up),
so the butt stays at the shoulder and the palms that follow it move neither up nor down (the forearms stay
on the ground). The slide is
smoothed over the clip, and at its first and last frame it is that frame's own, so clips meeting at a
posture node agree there.
"""

from __future__ import annotations

import numpy as np

from authoring.quality_frames import FigureSet, play
from authoring.signal_shaping import gaussian, smooth_above
from server.motion.channelset import Channelset

CLEAR_CM = 0.6  # the rifle slides out until it is at most this deep in the body (the check allows 1 cm)
PUSH_PASSES = 3  # each pass slides it out of its deepest point; a slide can uncover the next one
SIDEWAYS_MIN = 0.35  # a way out this far from across the barrel (cosine) is not taken: it would slide far
PUSH_SIGMA_FRAMES = 3.0  # the slide's length is smoothed over the clip (at or above the need) ...
PUSH_EASE_FRAMES = 15  # ... and eased in and out over this many frames at a clip's ends (0.25 s)


def held_rifle(slave: Channelset, figures: FigureSet, body: str) -> tuple[str, np.ndarray, np.ndarray] | None:
    """The rifle that ``slave``'s body holds: its file type, root globals ``(n, 4, 4)`` and mesh nodes
    ``(n, k, 3)`` (world), or None for a clip without one."""
    f = play(slave, figures)
    rtype = next((t for t in f.poses if t != body), None)
    if rtype is None:
        return None
    kin = figures.kin[rtype]
    nodes, segs = figures.nodes(rtype)
    g = kin.segment_globals(f.poses[rtype], f.locations[rtype])
    return rtype, f.locations[rtype], np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes)


def rifle_slide(
    figures: FigureSet,
    body: str,
    pose: np.ndarray,
    loc: np.ndarray,
    rifle: tuple[np.ndarray, np.ndarray],
    weight: np.ndarray,
) -> np.ndarray:
    """Per frame, the slide ``(n, 3)`` (cm, world) that takes the rifle out of the body of ``pose``/``loc``
    (see the module docstring). ``rifle``: the rifle's root globals and mesh nodes (:func:`held_rifle`);
    ``weight`` ``(n,)``: how much of it is wanted (0 where the rifle may stay where it is)."""
    hulls = figures.hulls(body)
    segg = figures.kin[body].segment_globals(pose, loc)
    barrel = -rifle[0][:, :3, 2]  # the rifle points along its -Z
    total = np.zeros((len(pose), 3))
    for _ in range(PUSH_PASSES):
        depth, normal = hulls.exits(rifle[1] + total[:, None, :], segg)
        way = normal - np.sum(normal * barrel, axis=1, keepdims=True) * barrel
        way[:, 1] = 0.0
        size = np.linalg.norm(way, axis=1)
        way = np.divide(way, size[:, None], out=np.zeros_like(way), where=size[:, None] > 1e-9)
        cos = np.sum(normal * way, axis=1)
        step = np.where(cos > SIDEWAYS_MIN, np.maximum(0.0, depth - CLEAR_CM) / np.maximum(cos, 1e-9), 0.0)
        total += (weight * step)[:, None] * way
    return _smoothed(total)


def _smoothed(slide: np.ndarray) -> np.ndarray:
    """A slide ``(n, 3)`` smoothed over the clip: its length at or above the need, its direction averaged
    (each end its own frame's)."""
    size = np.linalg.norm(slide, axis=1)
    if not size.any():
        return slide
    way = np.divide(slide, size[:, None], out=np.zeros_like(slide), where=size[:, None] > 1e-9)
    mean = gaussian(way, PUSH_SIGMA_FRAMES)
    frames = np.arange(len(slide), dtype=np.float64)
    half = np.ceil(3.0 * PUSH_SIGMA_FRAMES)
    to_first, to_last = np.maximum(0.0, 1.0 - frames / half), np.maximum(0.0, 1.0 - frames[::-1] / half)
    mean += to_first[:, None] * (way[0] - mean[0]) + to_last[:, None] * (way[-1] - mean[-1])
    norm = np.linalg.norm(mean, axis=1)
    mean = np.divide(mean, norm[:, None], out=np.zeros_like(mean), where=norm[:, None] > 1e-9)
    return mean * smooth_above(size, PUSH_SIGMA_FRAMES, PUSH_EASE_FRAMES)[:, None]


def slide_rifle(slave: Channelset, rtype: str, slide: np.ndarray) -> None:
    """Move ``slave``'s channel of the rifle figure ``rtype`` by ``slide`` ``(n, 3)`` (in place)."""
    for chan in slave.figure_channels():
        if chan.protofiletype == rtype:
            slave.fig_pos[:, chan.column, :] += slide.astype(slave.fig_pos.dtype)
