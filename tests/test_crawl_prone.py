"""crawl2prstow's planned contacts: a limb stays planted outside its move and clears the ground during it."""

import numpy as np

from authoring import crawl_prone
from authoring.transitions import transition_specs


def test_contact_is_planted_outside_its_move_and_lifted_during_it() -> None:
    t = np.arange(0, 1.6, 1 / 60)
    p0, p1 = np.array([0.0, 0.0, 0.0]), np.array([30.0, 0.0, -40.0])
    track = crawl_prone.move_track(p0, p1, t, 0.5, 0.4, 5.0)
    before, after, during = t < 0.5, t > 0.9, (t > 0.55) & (t < 0.85)
    assert np.allclose(track[before], p0)
    assert np.allclose(track[after], p1)
    assert track[during, 1].min() > 1.25  # off the ground (the checker's contact height) while it moves


def test_graph_arc_time_is_the_recorded_clip_length() -> None:
    assert transition_specs()["crawl2prstow"].duration == crawl_prone.DURATION
