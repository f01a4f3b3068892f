"""A reaction a trainee can see (``reaction_*_cm``, issue 14): constructed clips. Session 19's audit saw the
standing recoil kick the shoulders 1.7 cm (a slow nod) and the prone and crawl flinches move the head alone;
every limit passed."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from authoring.quality import FigureSet, check_clip, summarise
from authoring.quality_reactions import REACTION_LIMITS, reaction_kind
from peabody.loader import read_figure
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset

ROOT = Path(__file__).resolve().parents[1]
N = 19  # frames: 0.3 s at 60 fps, a recoil's length
BUMP = np.sin(np.pi * np.arange(N) / (N - 1)) ** 2  # out and back, still at both ends


@cache
def _figures() -> FigureSet:
    return FigureSet({n: read_figure(ROOT / "figures" / n) for n in ("DI.fig", "AK_47.fig")})


def _clip(name: str, body: np.ndarray, rifle: np.ndarray) -> Channelset:
    """DI standing still but moved by ``body[k]`` (cm, x y z) at frame ``k``, the rifle in front of him
    moved by ``rifle[k]``."""
    figset = _figures()
    di, ak = figset.figures["DI.fig"], figset.figures["AK_47.fig"]
    q = figset.kin["DI.fig"].neutral_pose()
    rec = Recording([di, ak])
    for k in range(N):
        at, gun = np.eye(4), np.eye(4)
        at[:3, 3] = body[k]
        gun[:3, 3] = np.array([12.0, 110.0, -55.0]) + rifle[k]
        rec.append("DI", q, "lower_torso.proximal", at @ di.location)
        rec.append("AK_47", np.zeros(0), "rifle.proximal", gun)
    return recording_to_channelset(name, rec, 0, N - 1, 60.0)


def _back(cm: float) -> np.ndarray:
    return np.outer(BUMP, [0.0, 0.0, cm])  # +Z: back, away from the line of fire


def test_reaction_clips_are_named_by_kind() -> None:
    assert reaction_kind("stfire_recoil_m16_low") == "recoil"
    assert reaction_kind("crawl_flinch_low") == "flinch"
    assert reaction_kind("prstow2prfire_low") is None and reaction_kind("kfire2dead") is None


@pytest.mark.parametrize(
    ("body", "rifle", "fails"),
    [
        (1.7, 3.0, ["reaction_shoulders_cm", "reaction_head_cm", "reaction_muzzle_cm"]),  # session 19: a nod
        (3.5, 6.0, []),  # a kick: the shoulder 3.5 cm back, the rifle with it and climbing
        (3.5, 3.5, ["reaction_muzzle_cm"]),  # the rifle held level: no muzzle climb to see
        (12.0, 12.0, ["reaction_shoulders_cm", "reaction_head_cm"]),  # thrown back, not kicked
    ],
)
def test_a_recoil_must_kick_the_shoulders_head_and_muzzle_visibly(body: float, rifle: float, fails) -> None:
    row = check_clip(_clip("stfire_recoil.chset", _back(body), _back(rifle)), _figures())
    assert row["reaction"] == "recoil"
    assert row["reaction_shoulders_cm"] == pytest.approx(body, abs=0.01)
    assert row["reaction_head_cm"] == pytest.approx(body, abs=0.01)
    assert row["reaction_muzzle_cm"] == pytest.approx(rifle, abs=0.01)
    assert row["reaction_peak_s"] == pytest.approx((N - 1) / 2 / 60.0)
    assert [f for f in row["failures"] if f.startswith("reaction")] == fails


def test_a_flinch_must_duck_the_head_and_the_shoulders_not_only_move_the_rifle() -> None:
    still = np.zeros((N, 3))
    rifle_only = check_clip(_clip("crawl_flinch.chset", still, _back(10.0)), _figures())
    assert rifle_only["reaction_shoulders_cm"] == 0.0 == rifle_only["reaction_head_cm"]
    assert rifle_only["reaction_muzzle_cm"] == pytest.approx(10.0)
    assert {"reaction_shoulders_cm", "reaction_head_cm"} <= set(rifle_only["failures"])
    duck = np.outer(BUMP, [0.0, -9.0, 0.0])  # the whole upper body 9 cm down (the muzzle is not judged)
    row = check_clip(_clip("crawl_flinch.chset", duck, still), _figures())
    assert row["reaction_head_cm"] == pytest.approx(9.0, abs=0.01)
    assert not [f for f in row["failures"] if f.startswith("reaction")]
    other = check_clip(_clip("prstow2prfire.chset", still, still), _figures())
    assert "reaction" not in other and "reaction_head_cm" not in other
    rows = summarise([rifle_only, row, other], [])["thresholds"]
    assert rows["reaction_head_cm"]["limit"] == {k: v["reaction_head_cm"] for k, v in REACTION_LIMITS.items()}
    assert rows["reaction_shoulders_cm"]["failing"] == 1 and not rows["reaction_shoulders_cm"]["pass"]
    assert rows["reaction_muzzle_cm"]["failing"] == 0  # judged only for a recoil
