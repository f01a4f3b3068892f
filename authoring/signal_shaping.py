"""Curves along a clip's frames that the authoring stages share: easing between values and smoothing.

Each stage that blends, fades or smooths a per-frame signal ``(n,)`` or ``(n, k)`` takes its curve from
here, so two stages that ease the same way give the same numbers.
"""

from __future__ import annotations

import itertools

import numpy as np


def smoothstep(x: np.ndarray) -> np.ndarray:
    """``x`` clipped to 0..1 and eased (``3x² - 2x³``): a blend that starts and stops at rest, no jump."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def keyed(keys: list[tuple[float, float]], t: np.ndarray) -> np.ndarray:
    """Piecewise smoothstep between (time, value) keys."""
    out = np.full(len(t), float(keys[0][1]))
    for (t0, a), (t1, b) in itertools.pairwise(keys):
        sel = (t >= t0) & (t <= t1)
        if t1 > t0 and sel.any():
            out[sel] = a + (b - a) * smoothstep((t[sel] - t0) / (t1 - t0))
    out[t > keys[-1][0]] = keys[-1][1]
    return out


def gaussian(values: np.ndarray, sigma: float) -> np.ndarray:
    """``values`` ``(n, k)`` smoothed along the frames by a Gaussian of ``sigma`` frames (ends held; also the
    slaving's smoothing of a clip, :mod:`authoring.slaving`)."""
    half = int(np.ceil(3.0 * sigma))
    k = np.arange(-half, half + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (k / sigma) ** 2)
    kernel /= kernel.sum()
    padded = np.concatenate([np.repeat(values[:1], half, 0), values, np.repeat(values[-1:], half, 0)])
    return np.stack([np.convolve(padded[:, j], kernel, mode="valid") for j in range(values.shape[1])], 1)


def hann_smooth(offset: np.ndarray, half: int) -> np.ndarray:
    """``offset`` ``(n, ndof)`` smoothed along the frames (a Hann window ``half`` frames either side, the ends
    held): a solve's frame-to-frame change spread out so it never flicks."""
    k = np.hanning(2 * half + 3)[1:-1]
    k /= k.sum()
    pad = np.concatenate([np.repeat(offset[:1], half, 0), offset, np.repeat(offset[-1:], half, 0)])
    return np.stack([np.convolve(pad[:, j], k, mode="valid") for j in range(offset.shape[1])], axis=1)


def smooth_above(need: np.ndarray, sigma: float, ease: int | None = None) -> np.ndarray:
    """A smooth curve at or above ``need``: a running maximum, then Gaussian, so it rises ahead of a rifle
    that comes down fast. Its first and last values are ``need``'s (the difference fades in linearly over
    the ends' ``3 sigma`` frames; given ``ease``, smoothly over that many, so it starts and ends at rest): a
    posture node's pitch depends on its pose alone, so every clip meeting there agrees and none starts with
    a jump."""
    n = len(need)
    half = int(np.ceil(3.0 * sigma))
    if n < 3 or not need.any():
        return need.copy()
    padded = np.pad(need, half, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    runmax = np.pad(windows.max(axis=-1), half, mode="edge")
    k = np.arange(-half, half + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (k / sigma) ** 2)
    smooth = np.convolve(runmax, kernel / kernel.sum(), mode="valid")
    frames = np.arange(n, dtype=np.float64)
    to_first = np.maximum(0.0, 1.0 - frames / (ease or half))
    to_last = to_first[::-1]
    if ease:
        to_first, to_last = (1.0 - (1.0 - u) ** 2 * (1.0 + 2.0 * u) for u in (to_first, to_last))
    smooth += to_first * (need[0] - smooth[0]) + to_last * (need[-1] - smooth[-1])
    return np.maximum(need, smooth)
