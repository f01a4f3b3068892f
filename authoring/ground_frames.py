"""Rigid frames of a figure on the ground (+Y up, degrees): turned about the vertical and pitched, and turns
about the vertical through a ground point, so a walk, a turn on the spot and a crawl's turn place the body
and the feet the same way.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

DEG = math.pi / 180.0


def turned_frames(pos: np.ndarray, yaw: ArrayLike, pitch: ArrayLike) -> np.ndarray:
    """``(n, 4, 4)`` frames at ``pos`` turned ``Ry(yaw) Rx(pitch)`` (degrees)."""
    a, b = np.asarray(yaw) * DEG, np.asarray(pitch) * DEG
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    out = np.zeros((len(a), 4, 4))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = ca, sa * sb, sa * cb
    out[:, 1, 1], out[:, 1, 2] = cb, -sb
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -sa, ca * sb, ca * cb
    out[:, :3, 3] = pos
    out[:, 3, 3] = 1.0
    return out


def turned_about(pivot: tuple[float, float], yaw: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` turns by ``yaw`` degrees about the vertical through ground point ``pivot``."""
    c = np.array([pivot[0], 0.0, pivot[1]])
    r = turned_frames(np.zeros((len(yaw), 3)), yaw, np.zeros(len(yaw)))
    r[:, :3, 3] = c - r[:, :3, :3] @ c
    return r
