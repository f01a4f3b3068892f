"""A prone dying slave's forearms lie still where the master's do (authoring/slave_lying.py; issue 14:
prstow2dead's DI left forearm hovered 1.5-2.3 cm up and drifted 7 cm where his lay still)."""

from __future__ import annotations

import numpy as np

from authoring import deaths
from authoring.slave_lying import EASE_FRAMES, hold_weights, on_ground


def test_a_forearm_dragged_as_it_lifts_off_is_still_on_the_ground() -> None:
    """Constructed: a node down at 0.5 cm, then 1.5-1.9 cm up (inside the check's LIFT_OFF_CM), then 5 cm:
    on the ground until it rises past 2 cm, as the check judges its slide."""
    points = np.full((20, 1, 3), 5.0)
    points[5:10, 0, 1] = 0.5
    points[10:13, 0, 1] = (1.5, 1.7, 1.9)
    assert np.flatnonzero(on_ground(points)).tolist() == list(range(5, 13))


def test_the_hold_follows_his_stances_after_the_release_and_keeps_the_end() -> None:
    """Constructed: his forearm down over frames 0-30 and 60-79 (the clip's end), the hands letting go at
    frame 10. Nothing is held before the release; the hold eases in after it (the first stance began
    before), is full through each stance, eases out after the first, and the stance to the end takes its
    place from the last frame (the DEAD rest stays as the trunk's rest left it)."""
    down = np.zeros(80, dtype=bool)
    down[:31] = down[60:] = True
    weight, anchor = hold_weights(down, 10)
    assert not weight[:11].any()
    assert (weight[10 + EASE_FRAMES : 31] == 1.0).all() and (weight[60:] == 1.0).all()
    assert np.all(np.diff(weight[10 : 10 + EASE_FRAMES + 1]) > 0)  # eased in
    assert 0.0 < weight[31] < 1.0 and weight[31 + EASE_FRAMES] == 0.0  # eased out
    assert set(anchor[11:31]) == {10} and set(anchor[60:]) == {79}


def test_only_the_prone_deaths_slaves_lay_their_forearms() -> None:
    """prstow2dead's and prfire2dead's own setting: every other death's slaves rebuild unchanged
    (crawl2dead's DI and M16 and crawl2prstow's DI rebuilt byte-identical)."""
    assert {d.name for d in deaths.DEATHS if d.slave_forearms_lying} == {"prstow2dead", "prfire2dead"}
