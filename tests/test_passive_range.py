"""A dead body's legs go to their passive range (authoring/passive_range.py, issue 14): only a death that
rolls its legs into it is recorded so, the check holds a clip that ends in DEAD to it, and the standing
deaths' committed soldier clips lie with their heels low, nothing rising once the body is down."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from authoring import deaths
from authoring.passive_range import PASSIVE_DEG, passive_figure, passive_limits
from authoring.quality import THRESHOLDS, check_clip
from authoring.quality_frames import FigureSet, play
from authoring.quality_postures import rest_endpoint
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from server.motion.cache import load_channelset
from ttes.paths import FIGURES

CHANNELSETS = Path(__file__).resolve().parents[1] / "channelsets"
ROLLED_SOONER = sorted(d.name for d in deaths.DEATHS if d.legs_roll is not None)


@pytest.fixture(scope="module")
def figures() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["soldier.fig", "AK_47.fig"])


def test_the_passive_range_only_widens_the_legs() -> None:
    soldier = read_figure(FIGURES / "soldier.fig")
    kin, dead = FigureKinematics(soldier), FigureKinematics(passive_figure(soldier))
    assert (dead.upper == kin.upper).all() and (dead.lower <= kin.lower).all()
    wider = {j for j, sl in kin.dof_slices.items() if (dead.lower[sl] < kin.lower[sl]).any()}
    assert wider == {f"{side}_{j}" for side in ("left", "right") for j in PASSIVE_DEG}
    for side in ("left", "right"):  # pointed and turned out 60 deg, the published passive values
        assert np.degrees(dead.lower[kin.dof_slices[f"{side}_ankle"].start]) == pytest.approx(-60.0)
        assert np.degrees(dead.lower[kin.dof_slices[f"{side}_hip"].start + 2]) == pytest.approx(-60.0)
    assert (passive_limits(kin)[0] == dead.lower).all()
    assert (FigureKinematics(soldier).lower == kin.lower).all()  # the live figure keeps its own


def test_a_rolled_dead_leg_is_pulled_into_its_passive_range_and_no_further() -> None:
    soldier = read_figure(FIGURES / "soldier.fig")
    kin = FigureKinematics(soldier)
    lower, upper = passive_limits(kin)
    q = deaths.limp_pose(kin, np.zeros(kin.ndof), rolled=True, passive=True)
    assert (q >= lower - 1e-9).all() and (q <= upper + 1e-9).all()
    assert (q < kin.lower - 1e-6).any()  # past the live soldier's limits: a dead man's legs
    assert ROLLED_SOONER == ["stfire2dead", "ststow2dead"]


@pytest.mark.parametrize("clip", ROLLED_SOONER)
def test_a_standing_death_lies_with_its_heels_down(clip: str, figures: FigureSet) -> None:
    """Rolled into the passive range as he lands (heels 18.2 and 15.4 cm up on main): the heels lie at most
    15 cm up (ststow2dead; stfire2dead, whose rifle thrown clear left them 22.4 cm up, with its legs lifted
    and turned as he lands, dead_legs.LANDING_LIFTS), within the passive range, nothing rising once the body
    is down (stfire2dead's knee rebounded 3.9 cm), no foot skating."""
    cf = play(load_channelset(CHANNELSETS / f"{clip}.chset.env"), figures)
    row = check_clip(cf, figures, ends_dead=True)
    assert row["joint_limit_violations"] == 0
    assert row["rest_rise_cm"] <= THRESHOLDS["rest_rise_cm"]
    assert row["foot_skate_cm"] <= THRESHOLDS["foot_skate_cm"]
    heel = rest_endpoint(cf, cf.channelset.nframes - 1, figures, "DEAD")["rest_foot_cm"]
    assert heel <= 15.0
