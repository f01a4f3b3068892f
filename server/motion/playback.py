"""Playing one bound channelset (seed 002: play_bound_channelset, step_bound_channelset,
set_channelset_parameters).

Two modes, chosen by the one global parameter ``set_channelset_parameters``:

* ``"no"`` (default, what TTES uses): real time. At every call the elapsed time since the start is recomputed
  from the clock and mapped to a fractional frame, so frames are skipped to keep wall-clock time, and a
  non-uniform tick rate is harmless: a 2 s clip at 60 fps (frames 0..120) sampled at 20 Hz shows frames
  0, 3, 6, ... 120.
* ``"yes"``: every frame. Call *k* shows frame *k* (as fast as the caller draws), whatever the clock says.

An arc time different from the stored duration (``size / fps``) stretches or squeezes the clip; ``-1`` (any
value <= 0) means the stored time. Backwards play mirrors the frame position. Without interpolation the
nearest stored frame is shown (``floor(position + 0.5)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from server.motion.binding import BoundChannelset, BoundSample


@dataclass
class PlaybackParameters:
    every_frame: bool = False


PARAMETERS = PlaybackParameters()


def set_channelset_parameters(every_frame: str | bool) -> None:
    """The global playback mode: ``"yes"`` = every frame, ``"no"`` = real time with frame skipping."""
    if isinstance(every_frame, str):
        word = every_frame.strip().lower()
        if word not in ("yes", "no"):
            raise ValueError(f'set_channelset_parameters takes "yes" or "no", not {every_frame!r}')
        every_frame = word == "yes"
    PARAMETERS.every_frame = bool(every_frame)


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


class ChannelsetPlayer:
    """Plays a bound channelset forwards or backwards over a transition time.

    ``start(now)`` then ``sample(now)`` per tick; ``step()`` moves one stored frame for debugging.
    """

    def __init__(
        self,
        bound: BoundChannelset,
        forward: bool = True,
        duration: float = -1.0,
        *,
        every_frame: bool | None = None,
        interpolate: bool = True,
    ) -> None:
        self.bound = bound
        self.forward = forward
        self.duration = play_time(bound.channelset.nframes, bound.channelset.fps, duration)
        self.every_frame = PARAMETERS.every_frame if every_frame is None else every_frame
        self.interpolate = interpolate
        self.start_time = 0.0
        self.calls = 0
        self.position = 0.0 if forward else float(bound.channelset.nframes - 1)
        self.done = False

    @property
    def nframes(self) -> int:
        return self.bound.channelset.nframes

    def start(self, now: float) -> None:
        self.start_time = float(now)
        self.calls = 0
        self.position = 0.0 if self.forward else float(self.nframes - 1)
        self.done = self.nframes == 1

    def advance(self, now: float) -> float:
        """Move to the frame for this call and return its (fractional) position."""
        last = self.nframes - 1
        if self.every_frame:
            k = min(self.calls, last)
            self.position = float(k if self.forward else last - k)
            self.done = self.calls >= last
            self.calls += 1
        else:
            cs = self.bound.channelset
            self.position, self.done = frame_position(
                cs.nframes, cs.fps, self.forward, self.duration, now - self.start_time
            )
            if not self.interpolate:
                self.position = float(nearest_frame(self.position, self.nframes))
        return self.position

    def sample(self, now: float) -> BoundSample:
        """Advance to ``now`` (or to the next frame in every-frame mode) and sample the figures there."""
        return self.bound.sample(self.advance(now), self.interpolate)

    def step(self, frames: int = 1) -> BoundSample:
        """Single-step ``frames`` stored frames in the play direction (negative goes back); clamps at ends."""
        last = self.nframes - 1
        k = nearest_frame(self.position, self.nframes) + (frames if self.forward else -frames)
        k = min(max(k, 0), last)
        self.position = float(k)
        self.done = k == (last if self.forward else 0)
        return self.bound.sample(self.position, interpolate=False)
