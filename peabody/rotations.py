"""Axis-angle rotations, vectorised over leading axes: the one Rodrigues of the project.

Peabody's DOFs, the stub's scene graph, the crowd's float32 FK, the IK and the DIS dead reckoning all turn
about unit axes; they share these two functions so the formula (and its rounding) exists once. Matrices act
on column vectors. Unit quaternions live beside this in :mod:`peabody.quaternion`.

Pure numpy on purpose: the per-tick FK of server and clients calls it, and the server installs without
scipy. ``scipy.spatial.transform.Rotation`` suits new off-line code, but not the motion library's build
path: the committed channelsets print float32 round-off (``0.00000000000005684342cm``), so other rounding
rewrites them (``as_rotvec`` in place of :func:`authoring.ik.rotation_log` changed all six walk_cycle files).
"""

from __future__ import annotations

import numpy as np


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``(..., 3, 3)`` of vectors ``(..., 3)``: ``skew(a) @ b == cross(a, b)``."""
    v = np.asarray(v)
    k = np.zeros((*v.shape[:-1], 3, 3), dtype=np.result_type(v.dtype, np.float32))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return k


def axis_angle(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` about unit ``axis`` ``(..., 3)`` by ``angle`` (radians, broadcast against the
    axes' leading shape): Rodrigues, ``cos θ I + sin θ K + (1 - cos θ) a aᵀ``."""
    a = np.asarray(axis, dtype=np.float64)
    t = np.asarray(angle, dtype=np.float64)[..., None, None]
    c = np.cos(t)
    outer = a[..., :, None] * a[..., None, :]
    return c * np.eye(3) + np.sin(t) * skew(a) + (1.0 - c) * outer
