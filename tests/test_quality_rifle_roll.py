"""A let-go rifle lies on its side, not on its top (issue 14): ``rifle_rest_roll_deg`` and
``rifle_top_down_s`` on constructed deaths: a rifle lying on its side, one on its top (sights down, magazine
up, as kfire2dead's lay 0.58 s), one rolling over its top in a few frames, one stood on its butt."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_quality import FIGURES, N
from test_quality_rifle_drop import _dead, _flat
from test_quality_rifle_rest import _on_ground, _rot

from authoring.quality import THRESHOLDS, FigureSet
from authoring.quality_frames import play
from authoring.quality_rifle_roll import ROLL_LIMIT_DEG, TOP_DOWN_LIMIT_S, rifle_lie, rifle_roll
from peabody.loader import read_figure
from server.motion.cache import load_channelset

CHANNELSETS = Path(__file__).resolve().parents[1] / "channelsets"
DEATHS = sorted(p.name.split(".")[0] for p in CHANNELSETS.glob("*2dead*.chset.env"))


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


def _rolled(figset: FigureSet, deg: float) -> np.ndarray:
    """The rifle beside him, its barrel level, rolled ``deg`` about it (0: top up), on the ground."""
    at = np.eye(4)
    at[:3, 3] = (70.0, 0.0, 0.0)
    return _on_ground(figset, at @ _rot(2, deg))


def test_roll_is_the_turn_about_the_barrel_of_the_rifles_up() -> None:
    tilted = _rot(0, 20.0) @ _rot(2, 90.0)  # on its side, the muzzle raised 20 degrees: still on its side
    rots = np.array([np.eye(4), _rot(2, 90.0), _rot(2, -90.0), _rot(2, 180.0), tilted, _rot(0, 85.0)])
    roll = rifle_roll(rots[:, :3, :3])
    assert roll[:5] == pytest.approx([0.0, 90.0, 90.0, 180.0, 90.0], abs=1e-6)
    assert np.isnan(roll[5])  # stood on its muzzle: no roll


def test_a_rifle_on_its_side_passes_and_one_on_its_top_fails(figset: FigureSet) -> None:
    side = _dead(figset, np.tile(_flat(figset, 70.0, 0.0), (N, 1, 1)), "side.chset")
    assert side["rifle_rest_roll_deg"] == pytest.approx(90.0, abs=1e-3)
    assert side["rifle_top_down_s"] == 0.0 and side["rifle_top_down_where"] is None and side["pass"]
    top = _dead(figset, np.tile(_rolled(figset, 180.0), (N, 1, 1)), "top.chset")
    assert top["rifle_rest_roll_deg"] == pytest.approx(180.0, abs=1e-3)
    assert top["rifle_top_down_s"] == pytest.approx(N / 60.0, abs=1e-3)
    assert {"rifle_rest_roll_deg", "rifle_top_down_s"} <= set(top["failures"])
    assert THRESHOLDS["rifle_rest_roll_deg"] == ROLL_LIMIT_DEG == 120.0
    assert THRESHOLDS["rifle_top_down_s"] == TOP_DOWN_LIMIT_S == 0.2


def test_a_rifle_rolling_over_its_top_passes_and_one_lying_there_fails(figset: FigureSet) -> None:
    """Rolling from one side over its top to the other in 6 frames (0.1 s) it is on its top 3: it passes;
    lying top down 24 frames (0.4 s) before it rolls on, it fails, however it ends."""
    quick = np.clip((np.arange(N) - 12) / 6.0, 0.0, 1.0)  # 0 .. 1 over frames 12-18
    rolls = 90.0 + 180.0 * quick
    row = _dead(figset, np.array([_rolled(figset, r) for r in rolls]), "rolling.chset")
    assert row["rifle_top_down_s"] == pytest.approx(3 / 60.0, abs=1e-3) and row["pass"], row["failures"]
    assert row["rifle_top_down_where"] == "frames 14-16"
    assert row["rifle_rest_roll_deg"] == pytest.approx(90.0, abs=1e-3)  # on its other side
    lying = np.where(np.arange(N) < 24, 180.0, 90.0)
    row = _dead(figset, np.array([_rolled(figset, r) for r in lying]), "lying.chset")
    assert row["rifle_top_down_s"] == pytest.approx(24 / 60.0, abs=1e-3)
    assert row["rifle_top_down_where"] == "frames 0-23"
    assert row["failures"] == ["rifle_top_down_s"]


def test_a_rifle_stood_on_its_butt_has_no_roll_and_is_not_top_down(figset: FigureSet) -> None:
    up = _on_ground(figset, _rot(0, 80.0) @ _rot(2, 180.0))  # muzzle up 80 degrees, its top facing down
    row = _dead(figset, np.tile(up, (N, 1, 1)), "stood.chset")
    assert row["rifle_rest_roll_deg"] is None and row["rifle_top_down_s"] == 0.0


@pytest.fixture(scope="module")
def library() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["soldier.fig", "DI.fig", "M16.fig", "AK_47.fig"])


@pytest.mark.parametrize("clip", DEATHS)
def test_every_death_s_rifle_lies_on_its_side(clip: str, library: FigureSet) -> None:
    """kfire2dead's let-go rifle lay on its top 0.53 s (frames 74-105) and ststow2dead's 0.48 s (47-75),
    on every figure, before rolling onto a side: flung a little ahead as it falls again, neither does."""
    frames = play(load_channelset(CHANNELSETS / f"{clip}.chset.env"), library)
    rifle = next(t for t in frames.poses if t in ("AK_47.fig", "M16.fig"))
    kin = library.kin[rifle]
    g = kin.segment_globals(frames.poses[rifle], frames.locations[rifle])
    nodes, segs = library.nodes(rifle)
    points = np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes)
    row = rifle_lie(frames.channelset, True, g[:, 0, :3, :3], points)
    assert row["rifle_top_down_s"] <= TOP_DOWN_LIMIT_S, row["rifle_top_down_where"]
    assert row["rifle_rest_roll_deg"] <= ROLL_LIMIT_DEG
