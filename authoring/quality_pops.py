"""One-frame pops in world space (``ttes author check``'s ``pop_m_s``, issue 14).

Session 19's audit saw body parts jump for a single 60 Hz frame while no joint angle flicked past the check's
15 degrees: at the let-go of ststow2dead / stfire2dead the right hand jumps 13-17 cm in one frame (its speed
1.1 -> 10.1 -> 7.1 m/s), the prone deaths' right forearm twitches 3 cm before the release, the crawl
U-turns' belly jumps 4-5 cm. A chain of small joint turns adds up at the hand, so the joint flick misses it.

A real movement (a fall, an arm swung, a knee planted) speeds up and slows down over several frames; a pop is
one frame much faster than both its neighbours. For every body mesh node (named by the check's parts: hands,
forearms, upper arms, chest, belly, pelvis, head, thighs, knees, feet), each frame-to-frame speed
``s[t]`` that exceeds both neighbours scores its excess over their mean, ``s[t] - (s[t-1] + s[t+1]) / 2``
(m/s), and a frame knocked off the path and back (two fast intervals, the second going back) the slower of
them over the intervals either side; ``pop_m_s`` is the clip's largest, ``pop_where`` names its part and the
frame the jump lands on. A swing at a steady or smoothly changing speed scores its change of speed over one
frame (near 0); a node that jumps 15 cm in a frame and then holds scores 9 m/s.

The limit, from the library (session 19, :data:`POP_LIMIT_M_S`): the let-go hands of the standing and
kneeling deaths score 4.9-6.1 (the hand leaves the grip 13-17 cm in a frame, plain on a contact sheet), the
prone deaths' forearm twitch 1.7-1.8 (3 cm in a frame out of stillness); the fastest smooth swing,
kstow2crawl's foot at 7.5 m/s, scores 1.3, a forearm set down at the crawl's start 1.4, a knee landing at
the end of a walk or run step 1.0, a recoil 0.9. Closest under the limit: crawlarc_r180_far_low's left hand,
1.48 (1.6 cm in a frame and stops).
"""

from __future__ import annotations

from typing import Any

import numpy as np

POP_LIMIT_M_S = 1.5  # m/s: 2.5 cm in one 60 Hz frame beyond its neighbours' pace (see above)


def pop_excess(velocity: np.ndarray) -> np.ndarray:
    """Per interval of ``velocity`` ``(m, k, 3)``: how far it stands out as a pop (m/s), else 0
    ``(m, k)``.

    A part that jumps in one frame and goes on (or stays) makes one interval faster than both neighbours: its
    excess over their mean. A frame knocked off the path and back (a twitch) makes two, the second going back
    against the first: the slower of the two over the mean of the intervals either side, scored on the
    first. Two fast intervals the same way are a swing at its fastest, not a twitch."""
    speed = np.linalg.norm(velocity, axis=-1)
    out = np.zeros_like(speed)
    if len(speed) >= 3:
        mid, before, after = speed[1:-1], speed[:-2], speed[2:]
        out[1:-1] = np.where((mid > before) & (mid > after), mid - 0.5 * (before + after), 0.0)
    if len(speed) >= 4:
        lo, before, after = np.minimum(speed[1:-2], speed[2:-1]), speed[:-3], speed[3:]
        back = np.einsum("tpi,tpi->tp", velocity[1:-2], velocity[2:-1]) < 0.0
        twitch = np.where(back & (lo > before) & (lo > after), lo - 0.5 * (before + after), 0.0)
        out[1:-2] = np.maximum(out[1:-2], twitch)
    return out


def pops(points: np.ndarray, parts: np.ndarray, fps: float) -> dict[str, Any]:
    """``pop_m_s`` (the largest one-frame pop of any body mesh node, m/s) and ``pop_where`` (``part[frame]``,
    its part and the frame the jump lands on) of body mesh nodes ``points`` ``(n, k, 3)`` (cm, world) with
    parts ``parts`` ``(k,)`` at ``fps``."""
    excess = pop_excess(np.diff(points, axis=0) * fps / 100.0)
    if not excess.size or excess.max() <= 0.0:
        return {"pop_m_s": 0.0, "pop_where": None}
    at, node = (int(v) for v in np.unravel_index(int(np.argmax(excess)), excess.shape))
    # interval ``at`` runs from frame at to at + 1: the jump lands on at + 1 (a twitch's frame off its path)
    return {"pop_m_s": round(float(excess[at, node]), 3), "pop_where": f"{parts[node]}[{at + 1}]"}
