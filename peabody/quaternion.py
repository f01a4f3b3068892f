"""Vectorised unit quaternions: figure channels, the wire's figure entries, the stubs' placements.

The one quaternion <-> matrix conversion of the project (server, clients, codecs and authoring call it).
Layout ``(..., 4) = (w, x, y, z)``; rotation matrices act on column vectors like every transform in the
project (:mod:`peabody.model`). Figure locations are stored as position + quaternion rather than 4x4
matrices because that is what gets interpolated (lerp + slerp) and what the update packet carries (7 floats).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Rotation part of ``(..., 3|4, 3|4)`` matrices → ``(..., 4)`` unit quaternions with ``w >= 0``.

    Shepperd's method, branch chosen per element so it stays accurate near 180° turns.
    """
    r = np.asarray(m, dtype=np.float64)[..., :3, :3]
    shape = r.shape[:-2]
    r = r.reshape(-1, 3, 3)
    m00, m11, m22 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    trace = m00 + m11 + m22
    q = np.empty((r.shape[0], 4))
    diag = np.stack([trace, m00, m11, m22], axis=1)
    case = np.argmax(diag, axis=1)
    # case 0: w largest
    s = np.sqrt(
        np.maximum(1.0 + np.stack([trace, m00 - m11 - m22, m11 - m00 - m22, m22 - m00 - m11], 1), 0.0)
    )
    s = np.maximum(s, 1e-12)
    for k in range(4):  # four branches, each vectorised over all matrices
        sel = case == k
        if not np.any(sel):
            continue
        rr = r[sel]
        sk = s[sel, k] * 2.0
        if k == 0:
            q[sel] = np.stack(
                [
                    0.25 * sk,
                    (rr[:, 2, 1] - rr[:, 1, 2]) / sk,
                    (rr[:, 0, 2] - rr[:, 2, 0]) / sk,
                    (rr[:, 1, 0] - rr[:, 0, 1]) / sk,
                ],
                1,
            )
        elif k == 1:
            q[sel] = np.stack(
                [
                    (rr[:, 2, 1] - rr[:, 1, 2]) / sk,
                    0.25 * sk,
                    (rr[:, 0, 1] + rr[:, 1, 0]) / sk,
                    (rr[:, 0, 2] + rr[:, 2, 0]) / sk,
                ],
                1,
            )
        elif k == 2:
            q[sel] = np.stack(
                [
                    (rr[:, 0, 2] - rr[:, 2, 0]) / sk,
                    (rr[:, 0, 1] + rr[:, 1, 0]) / sk,
                    0.25 * sk,
                    (rr[:, 1, 2] + rr[:, 2, 1]) / sk,
                ],
                1,
            )
        else:
            q[sel] = np.stack(
                [
                    (rr[:, 1, 0] - rr[:, 0, 1]) / sk,
                    (rr[:, 0, 2] + rr[:, 2, 0]) / sk,
                    (rr[:, 1, 2] + rr[:, 2, 1]) / sk,
                    0.25 * sk,
                ],
                1,
            )
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    return q.reshape(*shape, 4)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """``(..., 4)`` quaternions (normalised here) → ``(..., 3, 3)`` rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty((*q.shape[:-1], 3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - w * z)
    out[..., 0, 2] = 2 * (x * z + w * y)
    out[..., 1, 0] = 2 * (x * y + w * z)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - w * x)
    out[..., 2, 0] = 2 * (x * z - w * y)
    out[..., 2, 1] = 2 * (y * z + w * x)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def to_transform(pos: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Position ``(..., 3)`` + quaternion ``(..., 4)`` → ``(..., 4, 4)`` rigid transforms."""
    q = np.asarray(q, dtype=np.float64)
    out = np.zeros((*q.shape[:-1], 4, 4))
    out[..., :3, :3] = to_matrix(q)
    out[..., :3, 3] = pos
    out[..., 3, 3] = 1.0
    return out


def from_transform(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(..., 4, 4)`` rigid transforms → position ``(..., 3)`` + quaternion ``(..., 4)``: a figure's 7
    values."""
    t = np.asarray(t, dtype=np.float64)
    return t[..., :3, 3].copy(), from_matrix(t)


def make_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` so neighbours lie in the same hemisphere (q and -q are one rotation).

    Stored channels are made continuous once so interpolation never takes the long way round.
    """
    q = np.array(q, dtype=np.float64, copy=True)
    q = np.moveaxis(q, axis, 0)
    if q.shape[0] > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        flips = np.cumsum(dots < 0, axis=0) % 2  # parity of sign flips up to each frame
        q[1:] *= np.where(flips[..., None] == 1, -1.0, 1.0)
    return np.moveaxis(q, 0, axis)


def slerp(
    a: np.ndarray, b: np.ndarray, t: ArrayLike, out: np.ndarray | None = None
) -> np.ndarray:
    """Spherical interpolation of ``(..., 4)`` unit quaternions with weights ``t`` broadcast to ``(...)``.

    Takes the short arc; nearly equal rotations fall back to normalised lerp (sin θ → 0).
    """
    a = np.asarray(a)
    b = np.asarray(b)
    dtype = np.result_type(a.dtype, b.dtype, np.float32)
    t = np.asarray(t, dtype=dtype)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    sign = np.where(dot < 0, -1.0, 1.0).astype(dtype)
    dot = np.minimum(np.abs(dot), 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-4
    safe = np.where(near, 1.0, sin_theta)
    wa = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(near, t, np.sin(t * theta) / safe) * sign
    res = a * wa + b * wb
    res /= np.linalg.norm(res, axis=-1, keepdims=True)
    if out is not None:
        out[...] = res
        return out
    return res.astype(dtype, copy=False)
