"""The ground holds him up (issue 14): nothing of the body hovers (``ttes author check``'s support metric).

Session 19's audit saw crawl2prstow float for half a second on its way down (nothing of the body within 2 cm
of the ground, the pelvis 27 cm up and not falling) and every stand-to-kneel drop hop 3.4-3.8 cm onto the
knee; no other metric looked at the body as a whole, so both passed.

* ``unsupported_s``: the longest run of frames (s) in which no body mesh node is within :data:`SUPPORT_CM`
  of the ground, for every clip that is not a run. A man standing, walking, kneeling, crawling, lying or
  falling keeps something on the ground (a walk has double support, never flight), so anything longer than
  a couple of frames of rounding is a hover or a hop.
* ``flight_s``: the same time for a run clip (its name has ``run``: run cycles, starts, ends, walk2run,
  run2walk), judged against a run's flight (a 3.4 m/s run at 2.9 steps/s is airborne ~0.13 s a step), so
  the run's flight phase is not taken for a hover while a run that floats still fails.

Both come with ``_where`` (the frames). The rifle never counts: a body held up by the rifle alone hovers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.body_parts import true_runs

SUPPORT_CM = 2.0  # cm: a body node this near the ground bears weight (the resting height)
UNSUPPORTED_LIMIT_S = 0.05  # s: 3 frames at 60 fps; a clip that is not a run has no flight
FLIGHT_LIMIT_S = 0.2  # s: a run's flight (the library's run cycles: 0.13)
RUN_WORD = "run"  # a clip whose name has this has a flight phase


def longest_unsupported(heights: np.ndarray) -> tuple[int, int]:
    """``[start, stop)`` of the longest run of frames in which every body node of ``heights`` ``(n, k)``
    (cm above the ground) is higher than :data:`SUPPORT_CM`; ``(0, 0)`` when something always touches."""
    runs = true_runs(heights.min(axis=1) > SUPPORT_CM)
    return max(runs, key=lambda r: r[1] - r[0], default=(0, 0))


def support(name: str, heights: np.ndarray, fps: float) -> dict[str, Any]:
    """``unsupported_s`` (or ``flight_s`` for a run clip) and where, for clip ``name`` whose body mesh nodes
    are ``heights`` ``(n, k)`` cm above the ground at ``fps``."""
    key = "flight" if RUN_WORD in name.lower() else "unsupported"
    a, b = longest_unsupported(heights)
    return {f"{key}_s": round((b - a) / fps, 4), f"{key}_where": f"frames {a}-{b - 1}" if b > a else None}
