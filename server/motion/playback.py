"""The frame arithmetic of playing a clip (seed 002, 3.4.1-3.4.2), the scalar reference of the vectorised
:meth:`~server.motion.sampling.ClipLibrary.sample` (which the soldier manager plays everything through).

Real time: at every call the elapsed time since the start is recomputed from the clock and mapped to a
fractional frame, so frames are skipped to keep wall-clock time, and a non-uniform tick rate is harmless: a
2 s clip at 60 fps (frames 0..120) sampled at 20 Hz shows frames 0, 3, 6, ... 120. The seed's other mode,
``set_channelset_parameters("yes")`` (every stored frame once), is a soldier manager setting
(:class:`~server.soldier.settings.SoldierSettings`), not a global here.

An arc time different from the stored duration (``size / fps``) stretches or squeezes the clip; ``-1`` (any
value <= 0) means the stored time. Backwards play mirrors the frame position. Without interpolation the
nearest stored frame is shown (``floor(position + 0.5)``).
"""

from __future__ import annotations

import math


def play_time(nframes: int, fps: float, duration: float | None) -> float:
    """Seconds a play takes: ``duration`` when > 0, else the stored ``(nframes - 1) / fps``."""
    if duration is not None and duration > 0:
        return float(duration)
    return (nframes - 1) / fps


def frame_position(
    nframes: int, fps: float, forward: bool, duration: float | None, elapsed: float
) -> tuple[float, bool]:
    """Fractional frame shown ``elapsed`` seconds into a play, and whether the play has ended.

    This is the scalar reference of the vectorised :meth:`ClipLibrary.sample`; both use the same float64
    arithmetic so they agree exactly.
    """
    total = play_time(nframes, fps, duration)
    last = nframes - 1
    u = min(max(elapsed / total, 0.0), 1.0) if total > 0 else 1.0
    if not forward:
        u = 1.0 - u
    return u * last, elapsed >= total


def nearest_frame(position: float, nframes: int) -> int:
    return min(max(math.floor(position + 0.5), 0), nframes - 1)
