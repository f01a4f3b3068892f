"""Cross-fades and heading offsets on sampled poses, vectorised over soldiers.

Beyond the seed: when a step is cancelled by a posture change the new clip starts from a different pose; the
manager freezes the pose shown at the interrupt and fades from it into the new clip over ``blend_time``
(smoothstep weights, so the fade starts and ends with zero slope): joint angles and figure positions are
lerped, figure orientations nlerped along the short arc.

Heading offsets (``set_ttes_heading_offset(static, loco, crawl)``, seed 3.6) turn each graph's recorded figure
placements about the vertical (Jack +Y) axis through the feet; they are compass degrees like request headings
(clockwise seen from above), i.e. a Jack rotation of ``-radians(offset)``.
"""

from __future__ import annotations

import numpy as np


def smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def blend_into(
    joints: np.ndarray, figures: np.ndarray, src_joints: np.ndarray, src_figures: np.ndarray, w: np.ndarray
) -> None:
    """In place: ``joints``/``figures`` (n, ...) become ``src + (dst - src) * w`` (w: the new pose's weight).

    Figures are ``(n, nfig, 7)`` rows of position + quaternion (w, x, y, z).
    """
    w32 = np.asarray(w, np.float32)
    joints -= src_joints
    joints *= w32[:, None]
    joints += src_joints
    if figures.shape[1] == 0:
        return
    fp, sp = figures[..., :3], src_figures[..., :3]
    fp -= sp
    fp *= w32[:, None, None]
    fp += sp
    q, sq = figures[..., 3:], src_figures[..., 3:]
    sign = np.where(np.sum(q * sq, axis=-1, keepdims=True) < 0, -1.0, 1.0).astype(np.float32)
    q *= sign * w32[:, None, None]
    q += sq * (1.0 - w32)[:, None, None]
    q /= np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)


def yaw_rotate(figures: np.ndarray, compass_deg: np.ndarray) -> None:
    """In place: turn figure placements ``(n, nfig, 7)`` by per-soldier compass offsets ``(n,)`` about +Y."""
    a = -np.radians(np.asarray(compass_deg, np.float64))
    c, s = np.cos(a).astype(np.float32), np.sin(a).astype(np.float32)
    ch, sh = np.cos(a / 2).astype(np.float32), np.sin(a / 2).astype(np.float32)
    for f in (figures[:, k] for k in range(figures.shape[1])):  # a figure at a time: (n,) passes, not an
        x, z = f[:, 0].copy(), f[:, 2].copy()  # (n, 1) broadcast over nfig (an inner loop per row)
        f[:, 0] = c * x + s * z
        f[:, 2] = c * z - s * x
        qw, qx, qy, qz = (f[:, k].copy() for k in range(3, 7))
        f[:, 3] = ch * qw - sh * qy
        f[:, 4] = ch * qx + sh * qz
        f[:, 5] = ch * qy + sh * qw
        f[:, 6] = ch * qz - sh * qx
