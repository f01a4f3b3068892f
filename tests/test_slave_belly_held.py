"""A prone dying slave's root takes back a share of its belly's slide (authoring/slave_belly_held.py; issue
14: prfire2dead's DI belly node, 0.6-1 cm up, slid 3.83 cm as the trunk turned, frames 25-96)."""

from __future__ import annotations

import numpy as np

from authoring import deaths
from authoring.slave_belly_held import EASE_FRAMES, held_weights


def test_the_hold_is_full_over_the_run_and_eased_either_side() -> None:
    """Constructed: a belly run over frames 20-40 of 80: held fully there, rising smoothly over the frames
    before it and falling after, nothing far from it (the start and the rest of the clip untouched)."""
    w = held_weights(80, 20, 40)
    assert (w[20:41] == 1.0).all()
    assert not w[: 20 - EASE_FRAMES + 1].any() and not w[40 + EASE_FRAMES :].any()
    assert np.all(np.diff(w[20 - EASE_FRAMES : 21]) > 0) and np.all(np.diff(w[40 : 40 + EASE_FRAMES + 1]) < 0)


def test_a_run_to_the_end_is_held_to_the_end() -> None:
    """A run to the clip's last frame (the DEAD rest, where the hold takes its place from) is held there."""
    w = held_weights(97, 25, 96)
    assert w[96] == 1.0 and w[25] == 1.0 and w[18] == 0.0


def test_only_prfire2dead_slaves_hold_their_belly() -> None:
    """prfire2dead's own setting: every other death's slaves rebuild unchanged."""
    held = {d.name: d.slave_belly_held for d in deaths.DEATHS if d.slave_belly_held}
    assert set(held) == {"prfire2dead"} and 0.0 < held["prfire2dead"] < 1.0
