"""A sample's two frames blended as one compiled loop (numba, the optional ``fast`` extra; issue 21).

:meth:`~server.motion.sampling.ClipLibrary.sample`'s numpy path gathers both frames of every soldier
(joints and figures), then blends them in place over weight arrays expanded to full rows: some ten passes
over (n, ndof) and (n, nfig, 7) float32 arrays a tick. This loop reads each row of both frames once and
writes the blend, with the same float32 operations in the same order (``a + (b - a) w`` for a joint,
``a wa + b wb`` for a figure's value), so the same values bit for bit
(``tests/test_shard_fused.py``). The slerp's sines stay in numpy (its float32 ``sin`` is its
own SIMD code, not libm's). Used where :data:`protocol.fused.AVAILABLE`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from protocol import fused

_compiled: list[Callable[..., Any]] = []


def blend_rows() -> Callable[..., Any]:
    """The compiled :func:`blend_loop` (``fused.AVAILABLE`` only)."""
    if not _compiled:
        _compiled.extend((fused.compiled(blend_loop), fused.compiled(frames_loop)))
    return _compiled[0]


def frame_rows() -> Callable[..., Any]:
    """The compiled :func:`frames_loop` (``fused.AVAILABLE`` only)."""
    blend_rows()
    return _compiled[1]


def warm() -> None:
    """Compile (or load) the loop for a library's float32 frames, before a server's first tick."""
    if fused.AVAILABLE:
        f32, figs, idx = np.zeros((2, 3), np.float32), np.zeros((2, 2, 7), np.float32), np.zeros(2, np.int64)
        w, q = np.zeros(2, np.float32), np.zeros((2, 2), np.float32)
        blend_rows()(f32, figs, idx, idx, w, q, q, f32.copy(), figs.copy())
        t = np.zeros(2)
        frame_rows()(
            idx,
            t,
            np.ones(2, np.int8),
            t,
            t,
            idx,
            t,
            idx,
            t.copy(),
            np.zeros(2, bool),
            idx.copy(),
            idx.copy(),
            w,
        )


def blend_loop(
    joint_data: np.ndarray,
    fig_data: np.ndarray,
    g0: np.ndarray,
    g1: np.ndarray,
    w: np.ndarray,
    qa: np.ndarray,
    qb: np.ndarray,
    joints: np.ndarray,
    figures: np.ndarray,
) -> None:
    """Row ``i`` of ``joints`` (n, ndof) and ``figures`` (n, nfig, 7) from frames ``g0[i]`` and ``g1[i]`` at
    float32 weight ``w[i]``: joints lerped, a figure's position by ``(1 - w, w)`` and its quaternion by the
    slerp weights ``qa[i, k], qb[i, k]``."""
    n = len(g0)
    nd = joint_data.shape[1]
    nfig = fig_data.shape[1]
    one = np.float32(1.0)
    for i in range(n):
        r0 = g0[i]
        r1 = g1[i]
        wi = w[i]
        for c in range(nd):
            a = joint_data[r0, c]
            joints[i, c] = a + (joint_data[r1, c] - a) * wi
        rest = one - wi
        for k in range(nfig):
            for c in range(3):
                figures[i, k, c] = fig_data[r0, k, c] * rest + fig_data[r1, k, c] * wi
            wa = qa[i, k]
            wb = qb[i, k]
            for c in range(3, 7):
                figures[i, k, c] = fig_data[r0, k, c] * wa + fig_data[r1, k, c] * wb


def frames_loop(
    clip: np.ndarray,
    start: np.ndarray,
    direc: np.ndarray,
    dur: np.ndarray,
    now: np.ndarray,
    nframes: np.ndarray,
    stored: np.ndarray,
    first: np.ndarray,
    position: np.ndarray,
    ended: np.ndarray,
    g0: np.ndarray,
    g1: np.ndarray,
    w: np.ndarray,
) -> None:
    """Per soldier, ``ClipLibrary.sample``'s frame arithmetic with its float64 operations in its order: the
    fractional ``position`` in clip ``clip`` played since ``start`` over ``dur`` seconds (<= 0: the clip's
    ``stored`` duration), forwards where ``direc > 0``, at ``now``; whether the play ``ended``; the two
    library rows to blend, ``g0`` and ``g1`` (the clip's ``first`` row on), and the float32 weight ``w``."""
    for i in range(len(clip)):
        c = clip[i]
        nfr = nframes[c]
        total = dur[i] if dur[i] > 0 else stored[c]
        elapsed = now[i] - start[i]
        u = min(max(elapsed / total, 0.0), 1.0) if total > 0 else 1.0
        if not direc[i] > 0:
            u = 1.0 - u
        pos = u * np.float64(nfr - 1)
        position[i] = pos
        ended[i] = elapsed >= total
        i0 = min(np.int64(np.floor(pos)), nfr - 1)
        w[i] = np.float32(pos - i0)
        g0[i] = first[c] + i0
        g1[i] = first[c] + min(i0 + 1, nfr - 1)
