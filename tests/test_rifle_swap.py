"""Putting the M16 where the master's AK is (authoring.rifle_swap): butt on butt, aimed the same,
lifted out of the ground by a muzzle-up pitch about the butt, lowered with a released AK onto the ground."""

from __future__ import annotations

import numpy as np
import pytest

from authoring import rifle_swap as R
from authoring.quality import FigureSet
from ttes.paths import FIGURES


@pytest.fixture(scope="module")
def figs() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["AK_47.fig", "M16.fig"])


def _butt(figs: FigureSet, ptype: str, locs: np.ndarray) -> np.ndarray:
    kin = figs.kin[ptype]
    return (locs @ kin.site_globals(np.zeros(0))[kin.site_names.index("rifle.butt")])[..., :3, 3]


def _level(height: float, n: int = 30) -> np.ndarray:
    """An AK aimed along -Z, its lowest point at ``height`` minus the magazine's depth."""
    locs = np.tile(np.eye(4), (n, 1, 1))
    locs[:, 1, 3] = height
    return locs


def test_the_m16_takes_the_aks_placement_butt_on_butt(figs: FigureSet) -> None:
    ak = _level(120.0)
    m16 = R.place_swapped_rifle(ak, "AK_47.fig", "M16.fig", figs)
    np.testing.assert_allclose(_butt(figs, "M16.fig", m16), _butt(figs, "AK_47.fig", ak), atol=1e-9)
    np.testing.assert_allclose(m16[:, :3, :3], ak[:, :3, :3])  # aimed exactly as the AK


def test_a_rifle_that_would_reach_the_ground_pitches_its_muzzle_up_about_the_butt(figs: FigureSet) -> None:
    ak = _level(20.0, 40)
    ak[:, 1, 3] = np.linspace(40.0, 20.0, 40)  # coming down to the ground: the M16's end hits it
    raw = ak @ R.swap_offset(figs.figures["AK_47.fig"], figs.figures["M16.fig"])
    assert R.lowest_point(figs, "M16.fig", raw).min() < -1.0
    m16, pitch = R.clear_ground(figs, "M16.fig", raw)
    assert R.lowest_point(figs, "M16.fig", m16).min() >= R.GROUND_MARGIN_CM - 1e-6
    np.testing.assert_allclose(_butt(figs, "M16.fig", m16), _butt(figs, "M16.fig", raw), atol=1e-9)
    assert pitch[0] == 0.0 and pitch[-1] > 0.0 and np.all(np.diff(pitch) >= -1e-9)  # rises once, smoothly
    muzzle = m16[:, :3, :3] @ np.array([0.0, 0.0, -1.0])
    assert np.all(muzzle[:, 1] >= -1e-9) and muzzle[-1, 1] > 0.0  # it points up, never down
    assert np.abs(np.diff(pitch)).max() < 2.0  # degrees per frame: no twitch


def test_after_release_the_m16_comes_down_with_the_ak(figs: FigureSet) -> None:
    ak = _level(0.0, 40)
    ak_low = R.lowest_point(figs, "AK_47.fig", ak)[0]
    ak[:, 1, 3] = 60.0 - ak_low
    ak[20:, 1, 3] = np.linspace(60.0, 0.0, 20) - ak_low  # let go at frame 20, lands on the ground
    m16 = R.place_swapped_rifle(ak, "AK_47.fig", "M16.fig", figs, release_frame=20, fps=60.0)
    held = R.place_swapped_rifle(ak, "AK_47.fig", "M16.fig", figs)
    np.testing.assert_allclose(m16[:21], held[:21], atol=1e-9)  # still held, then a gentle start
    low = R.lowest_point(figs, "M16.fig", m16)
    assert low[-1] == pytest.approx(R.GROUND_MARGIN_CM, abs=1e-6)  # on the ground, not on a longer magazine
    assert np.abs(np.diff(m16[:, 1, 3])).max() < 6.0


def test_a_released_rifle_on_its_side_is_lifted_not_swung(figs: FigureSet) -> None:
    on_side = np.eye(4)
    on_side[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # rolled 90 degrees about Z
    ak = np.tile(on_side, (30, 1, 1))
    ak[:, 1, 3] = 1.0 - R.lowest_point(figs, "AK_47.fig", ak[:1])[0]  # resting 1 cm up
    m16 = R.place_swapped_rifle(ak, "AK_47.fig", "M16.fig", figs, release_frame=0, fps=60.0)
    np.testing.assert_allclose(m16[:, :3, :3], ak[:, :3, :3])  # same orientation: moved only up or down
    assert R.lowest_point(figs, "M16.fig", m16).min() >= R.GROUND_MARGIN_CM - 1e-6
    assert R.lowest_point(figs, "M16.fig", m16)[-1] == pytest.approx(1.0, abs=1e-6)  # resting as the AK
