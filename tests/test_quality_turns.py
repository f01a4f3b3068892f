"""Turning in place in the quality check (issue 14, :mod:`authoring.quality_turns`), on constructed clips: a
turn in place that ends away from where it started fails ``turn_travel_cm``; a foot pivoting on its ball is
not a skating foot, but a heel left on the ground while it pivots is, and so is a pivot point that moves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from authoring.body_parts import contact_runs
from authoring.quality import CONTACT_HEIGHT_CM, THRESHOLDS, FigureSet, check_clip
from authoring.quality_postures import offset_transform
from authoring.quality_turns import TRAVEL_LIMIT_CM, foot_pivots, pivot_slides, turn_travel
from tests.test_quality import _clip, _standing, figset, holding  # noqa: F401 (fixtures)

N = 31
# a left foot in its own frame (cm, -Z ahead, the ball at the origin): the forefoot round the ball, the toe
# tip 6.5 cm ahead, and the heel 21 cm behind
FOREFOOT = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [-4.0, 0.0, 0.0], [3.0, 0.0, -4.0], [0.0, 0.0, -6.5]])


def _foot(heel_up: float, about_z: float = 0.0, turn_deg: float = 90.0):
    """A foot turning ``turn_deg`` to the left over ``N`` frames about the point ``about_z`` cm behind its
    ball (0: the ball), its heel ``heel_up`` cm up: its nodes ``(N, k, 3)``, their parts and yaws."""
    nodes = np.vstack([FOREFOOT, [[0.0, heel_up, 21.0]]]) - [0.0, 0.0, about_z]
    yaw = np.radians(np.linspace(0.0, turn_deg, N))
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x, z = nodes[None, :, 0], nodes[None, :, 2]
    pts = np.stack([x * c + z * s, np.broadcast_to(nodes[:, 1], (N, len(nodes))), -x * s + z * c], axis=-1)
    parts = np.array(["left_foot"] * len(nodes))
    return pts, parts, np.broadcast_to(yaw[:, None], (N, len(nodes)))


def _foot_skate(pts: np.ndarray, parts: np.ndarray, yaw: np.ndarray) -> tuple[float, float]:
    """(as measured node by node, judged about the pivot) worst foot slide, cm."""
    runs = contact_runs(pts, CONTACT_HEIGHT_CM)
    return float(runs.slide.max()), float(pivot_slides(runs, pts, parts, yaw, CONTACT_HEIGHT_CM).max())


def test_a_foot_pivoting_on_its_ball_with_the_heel_up_does_not_skate() -> None:
    pts, parts, yaw = _foot(heel_up=3.0)
    raw, judged = _foot_skate(pts, parts, yaw)
    assert raw == pytest.approx(2 * 6.5 * math.sin(math.radians(45)), abs=0.1)  # the toe tip sweeps 9 cm
    assert judged < 0.01
    pivot = foot_pivots(pts, parts, {"left_foot": yaw[:, 0]}, CONTACT_HEIGHT_CM)
    assert pivot == {"pivot_deg": pytest.approx(90.0), "pivot_where": f"left_foot[0-{N - 1}]"}


def test_a_heel_left_on_the_ground_while_the_foot_pivots_skates() -> None:
    pts, parts, yaw = _foot(heel_up=0.0)
    _, judged = _foot_skate(pts, parts, yaw)
    assert judged == pytest.approx(2 * 21.0 * math.sin(math.radians(45)), abs=0.2)  # the heel's arc: 30 cm


def test_a_forefoot_swung_about_the_raised_heel_skates() -> None:
    """Turned about a point off the ground (the raised heel), no point of the forefoot stays put."""
    pts, parts, yaw = _foot(heel_up=3.0, about_z=21.0)
    _, judged = _foot_skate(pts, parts, yaw)
    assert judged == pytest.approx(2 * 21.0 * math.sin(math.radians(45)), abs=0.2)  # the ball's own arc
    assert judged > THRESHOLDS["foot_skate_cm"]


def _spun(figset: FigureSet, holding, name: str, end: tuple[float, float, float]):  # noqa: F811
    """A standing DI figure carried by the ground move ``end`` (x cm, z cm, yaw deg) over the clip, both
    feet flat on the ground, recorded with that ``end_offset``."""
    poses, body, rifle = _standing(figset, holding, N)
    for k, f in enumerate(np.linspace(0.0, 1.0, N)):
        move = offset_transform(tuple(v * f for v in end))
        body[k], rifle[k] = move @ body[k], move @ rifle[k]
    cs = _clip(name, figset, poses, body, rifle)
    cs.end_offset = end
    return cs


def test_a_turn_in_place_that_ends_away_from_where_it_started_fails(figset: FigureSet, holding) -> None:  # noqa: F811
    far = check_clip(_spun(figset, holding, "turn_l90.chset", (30.0, -40.0, 90.0)), figset)
    assert far["turn_travel_cm"] == pytest.approx(50.0) and "turn_travel_cm" in far["failures"]
    assert TRAVEL_LIMIT_CM == THRESHOLDS["turn_travel_cm"] == 10.0
    # a side-step moves the soldier on purpose: no travel is judged
    side = _spun(figset, holding, "sidestep_l.chset", (-45.0, 0.0, 0.0))
    assert turn_travel(side) == {"turn_travel_cm": None}


def test_feet_spun_flat_on_the_ground_about_the_body_skate(figset: FigureSet, holding) -> None:  # noqa: F811
    """Turning on the spot with both feet flat on the ground: each foot turns (pivot_deg 90) about the
    body's axis, not about a point of its own, so its every node slides."""
    row = check_clip(_spun(figset, holding, "turn_l90.chset", (0.0, 0.0, 90.0)), figset)
    assert row["turn_travel_cm"] == 0.0 and "turn_travel_cm" not in row["failures"]
    assert row["pivot_deg"] == pytest.approx(90.0, abs=0.5)
    assert row["foot_skate_cm"] > 10.0 and "foot_skate_cm" in row["failures"]


def test_a_coarse_foot_pivots_about_its_ball_site() -> None:
    """DI.fig's foot has no mesh node at the ball: its pivot may be the ball site (``sole``)."""
    pts, parts, yaw = _foot(heel_up=3.0)
    coarse, cparts, cyaw = pts[:, 1:], parts[1:], yaw[:, 1:]  # no node at the ball
    runs = contact_runs(coarse, CONTACT_HEIGHT_CM)
    alone = pivot_slides(runs, coarse, cparts, cyaw, CONTACT_HEIGHT_CM).max()
    assert alone > 2 * 3.0 * math.sin(math.radians(45))  # about a node 3-4 cm from the ball
    sole = {"left_foot": pts[:, :1]}  # the ball site
    assert pivot_slides(runs, coarse, cparts, cyaw, CONTACT_HEIGHT_CM, sole).max() < 0.01


@pytest.mark.parametrize("suffix", ["", "_low", "_m16_low"])
@pytest.mark.parametrize("name", [f"turn_{d}{a}" for d in "lr" for a in (45, 90, 180)])
def test_the_shipped_turns_in_place_end_where_they_started(name: str, suffix: str) -> None:
    from server.motion.cache import load_channelset
    from ttes.paths import CHANNELSETS

    cs = load_channelset(CHANNELSETS / f"{name}{suffix}.chset.env")
    assert turn_travel(cs)["turn_travel_cm"] <= TRAVEL_LIMIT_CM
