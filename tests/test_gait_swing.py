"""A swinging foot (authoring/gait.py): it goes up before it goes along and comes down after it, and
landing toes first its toes bend up ahead of the footfall."""

from __future__ import annotations

import numpy as np

from authoring import gait

BALL = np.array([0.8, 0.0, -21.6])  # ball relative to heel on the flat foot (soldier.fig)
FPS = 60


def _walk(strike: float, rise: float, drop: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One foot: flat from 0, heel up at 0.3 s, off at 0.5 s, lands 60 cm ahead at 1.0 s."""
    falls = [
        gait.Footfall("left", 0.0, (0.0, 0.0), 0.0, 0.0, 0.3, 0.5, 0.0, 30.0, rise=rise, drop=drop),
        gait.Footfall("left", 1.0, (0.0, -60.0), 0.0, 1.1, 1.4, 1.6, strike, 30.0),
    ]
    t = np.arange(round(1.2 * FPS) + 1) / FPS
    heels, toes = gait.foot_track(BALL, falls, t, 9.0)
    return t, heels, toes


def test_the_swing_rises_before_it_travels_and_drops_after():
    t, heels, _ = _walk(15.0, 0.1, 0.1)
    first = (t > 0.5) & (t <= 0.55)  # the first tenth of the 0.5 s swing
    last = (t >= 0.95) & (t < 1.0)
    off = heels[np.flatnonzero(t >= 0.5)[0]]
    land = heels[np.flatnonzero(t >= 1.0)[0]]
    for sel, ref in ((first, off), (last, land)):
        travel = np.linalg.norm(heels[sel][:, [0, 2], 3] - ref[[0, 2], 3], axis=1)
        assert travel.max() < 1e-9
    assert np.all(np.diff(heels[first][:, 1, 3]) > 0)  # going up
    assert np.all(np.diff(heels[last][:, 1, 3]) < 0)  # coming down
    # without rise and drop the foot travels from the first frame of the swing
    _, heels0, _ = _walk(15.0, 0.0, 0.0)
    assert np.linalg.norm(heels0[first][-1, [0, 2], 3] - off[[0, 2], 3]) > 0.1


def test_toes_first_landing_bends_the_toes_ahead_of_the_footfall():
    t, _, toes = _walk(-10.0, 0.0, 0.0)
    land = np.flatnonzero(t >= 1.0)[0]
    assert np.degrees(toes[land]) > 9.0  # held bent up as the foot rocks flat about the ball
    near = slice(land - 6, land + 6)
    assert np.degrees(np.abs(np.diff(toes[near]))).max() < 3.0  # no snap at the footfall
