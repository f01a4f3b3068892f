"""The soldier manager's settings: one frozen, validated value (seed 002, 3.6: the start-up script's knobs).

Every setting a JCL command or a config file can change lives here once, validated once in
``__post_init__``. Changing a setting means replacing the whole value with a validated copy
(:meth:`SoldierSettings.replace`, i.e. :func:`dataclasses.replace`), so a bad value never leaves the manager
half-configured and there is no second setter to keep in step.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any


def _seconds(name: str, value: float, *, positive: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name} must be a number, not {type(value).__name__}")
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        raise ValueError(f"{name} must be {'>' if positive else '>='} 0, not {value}")


@dataclass(frozen=True, slots=True)
class SoldierSettings:
    """What ``set_ttes_*`` and ``set_channelset_parameters`` set; times in seconds, speeds in m/s."""

    throttle: float = 1 / 30  # set_ttes_soldier_throttle: at most one update per soldier per throttle
    tick_period: float = 1 / 30  # the server's tick (1 / tick_hz): the throttle is a rate cap on this grid
    walk_run_threshold: float = 2.4  # set_ttes_walk_run_threshold: a walking soldier faster than this runs
    walk_run_hysteresis: float = 0.4  # a running soldier walks below threshold - hysteresis (at most half)
    heading_offsets: tuple[float, float, float] = (0.0, 0.0, 0.0)  # set_ttes_heading_offset: compass degrees
    blend_time: float = 0.2  # set_ttes_blend_time: cross-fade when a step is cancelled
    every_frame: bool = False  # set_channelset_parameters("yes"): one stored frame per tick, not real time
    interpolate: bool = True  # sample between stored frames (False: nearest frame)
    record_clips: bool = False  # set_ttes_clip_recording: keep every clip start (report_ttes_clips)

    def __post_init__(self) -> None:
        _seconds("throttle", self.throttle)
        _seconds("tick period", self.tick_period, positive=True)
        _seconds("walk/run threshold", self.walk_run_threshold, positive=True)
        _seconds("blend time", self.blend_time)
        _seconds("walk/run hysteresis", self.walk_run_hysteresis)
        offsets = tuple(self.heading_offsets)
        if len(offsets) != 3 or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in offsets
        ):
            raise ValueError(f"heading offsets must be three finite numbers, not {self.heading_offsets!r}")
        object.__setattr__(self, "heading_offsets", tuple(float(v) for v in offsets))
        for name in ("throttle", "tick_period", "walk_run_threshold", "walk_run_hysteresis", "blend_time"):
            object.__setattr__(self, name, float(getattr(self, name)))
        for flag in ("every_frame", "interpolate", "record_clips"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"{flag} must be true or false")

    def replace(self, **changes: Any) -> SoldierSettings:
        """A validated copy with ``changes`` (ValueError names the bad setting; ``self`` is unchanged)."""
        return dataclasses.replace(self, **changes)

    @property
    def min_interval(self) -> float:
        """The shortest gap between two updates of one soldier: ``throttle - tick_period / 2``.

        The throttle is a *rate cap*, not a tick count: ticks land on a grid, so a soldier is due when its
        last update is at least this old. 0.04 s on a 30 Hz tick gives every tick (30 updates/s, seed 002
        3.6 "don't send more than 30 updates per second"), 0.1 s gives one tick in three.
        """
        return self.throttle - self.tick_period / 2
