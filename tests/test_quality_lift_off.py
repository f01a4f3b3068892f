"""A part dragged just above the contact height as it lifts off still slides (issue 14): crawl2dead's M16
slave's right upper arm, on the ground, swept 1.4-2.5 cm a frame at 1.0-2.0 cm up as it rose (frames
128-131), and the check's contact (a node at most 1.25 cm up) saw two frames of it. A node that came down to
the ground is on it until it rises past ``LIFT_OFF_CM`` (not the feet: a toe leaves the ground stepping);
a fast skim at 1 cm still slides, and a part that never comes down to the ground is in the air, unless it
rests within ``LIFT_OFF_CM`` at a static end: the posture check holds a part within 2 cm as resting, and the
DI prfire_recoil slave's right elbow, lying 1.58 cm up in PRONE_FIRE, slid 3.3 cm while it dipped to
1.31 cm (a variant of pronereact-s21) and the check saw no slide."""

from __future__ import annotations

import numpy as np
import pytest
from test_quality import N, _clip, _lying, figset  # noqa: F401  (the module's figure fixture)

from authoring.body_parts import contact_runs
from authoring.quality import CONTACT_HEIGHT_CM, LIFT_OFF_CM, FigureSet, check_clip


def _lifting(n: int = 40) -> np.ndarray:
    """One node lying on the ground 20 frames, then rising 0.3 cm a frame while it sweeps 2 cm a frame."""
    pts = np.zeros((n, 1, 3))
    up = np.clip(np.arange(n) - 19, 0, None)
    pts[:, 0, 1] = 0.5 + 0.3 * up
    pts[:, 0, 0] = 2.0 * up
    return pts


def test_a_node_dragged_as_it_lifts_off_slides_until_it_is_clear() -> None:
    pts = _lifting()
    assert contact_runs(pts, CONTACT_HEIGHT_CM).slide.max() == pytest.approx(4.0)  # up to 1.1 cm: 2 frames
    runs = contact_runs(pts, CONTACT_HEIGHT_CM, LIFT_OFF_CM)
    assert runs.slide.max() == pytest.approx(10.0) and runs.last.max() == 24  # up to 2.0 cm: 5 frames


def test_a_skim_still_slides_and_a_part_in_the_air_does_not() -> None:
    n = 60
    pts = np.zeros((n, 3, 3))
    pts[:, :, 0] = np.arange(n)[:, None] * 10.0  # 6 m/s at 60 fps, every node
    pts[:, 0, 1] = 1.0  # a skim at 1 cm: on the ground
    pts[:, 1, 1] = np.linspace(1.3, 1.9, n)  # just above it but never down to it: in the air
    pts[:, 2, 1] = 5.0
    runs = contact_runs(pts, CONTACT_HEIGHT_CM, np.array([LIFT_OFF_CM] * 3))
    assert list(runs.node) == [0] and runs.slide[0] == pytest.approx(590.0)


def _resting_elbow() -> np.ndarray:
    """One node resting 1.58 cm up that dips to 1.31 cm while it slides 3.3 cm and back (the DI recoil's
    elbow), and one resting 3 cm up that slides as far (in the air). A node landing 1.9 -> 1.5 cm up as it
    moves 5 cm is on the ground once it rests."""
    t = np.sin(np.linspace(0.0, np.pi, 22))
    pts = np.zeros((22, 2, 3))
    pts[:, 0, 1] = 1.58 - 0.27 * t
    pts[:, 1, 1] = 3.0 - 0.27 * t
    pts[:, :, 0] = 3.3 * t[:, None]
    return pts


def test_a_part_resting_just_above_the_ground_at_a_posture_slides() -> None:
    pts = _resting_elbow()
    assert len(contact_runs(pts, CONTACT_HEIGHT_CM, LIFT_OFF_CM).node) == 0  # the gap: never down to 1.25
    for ends in ((True, False), (False, True), (True, True)):
        runs = contact_runs(pts, CONTACT_HEIGHT_CM, LIFT_OFF_CM, rest_ends=ends)
        assert list(runs.node) == [0] and runs.slide[0] == pytest.approx(3.3, abs=0.01)
    rising = pts.copy()
    rising[11:, 0, 1] = 2.5  # lifted clear of the ground halfway: on it until then, not after
    runs = contact_runs(rising, CONTACT_HEIGHT_CM, LIFT_OFF_CM, rest_ends=(True, True))
    assert list(runs.node) == [0] and runs.last[0] == 10
    landing = np.zeros((30, 1, 3))
    landing[:, 0, 1] = np.r_[np.linspace(1.9, 1.5, 10), np.full(20, 1.5)]  # comes down as it lands
    landing[:, 0, 0] = np.r_[np.linspace(0.0, 5.0, 10), np.full(20, 5.0)]
    runs = contact_runs(landing, CONTACT_HEIGHT_CM, LIFT_OFF_CM, rest_ends=(False, True))
    assert list(runs.node) == [0] and runs.first[0] == 7  # within REST_SLACK_CM of its rest: 1.59 cm
    assert runs.slide[0] == pytest.approx(5.0 * 2 / 9)


def test_the_check_sees_a_body_dragged_just_above_the_ground(figset: FigureSet) -> None:  # noqa: F811
    """DI lying on his back is lifted 1.6 cm and slid 6 cm sideways over 6 frames: dragged, not in the
    air; lying 1.6 cm up from the start (a resting posture, as the posture check's ``rest_contact_cm``
    holds it) and slid so, he slides too; 2.5 cm up, or 1.6 cm up between moving ends, he is in the air."""
    poses, body, rifle = _lying(figset)
    move = np.clip(np.arange(N) - 10, 0, 6).astype(float)
    body[:, 1, 3] += np.where(np.arange(N) > 10, 1.6, 0.0)
    body[:, 0, 3] += move
    row = check_clip(_clip("dragged.chset", figset, poses, body, rifle), figset)
    assert row["contact_slide_cm"] == pytest.approx(6.0, abs=0.05) and "contact_slide_cm" in row["failures"]
    poses, body, rifle = _lying(figset, lift=1.6)
    body[:, 0, 3] += move
    row = check_clip(_clip("resting.chset", figset, poses, body, rifle), figset)
    assert row["contact_slide_cm"] == pytest.approx(6.0, abs=0.05) and "contact_slide_cm" in row["failures"]
    row = check_clip(_clip("moving.chset", figset, poses, body, rifle), figset, static_ends=(False, False))
    assert row["contact_slide_cm"] == 0.0
    poses, body, rifle = _lying(figset, lift=2.5)
    body[:, 0, 3] += move
    row = check_clip(_clip("hovering.chset", figset, poses, body, rifle), figset)
    assert row["contact_slide_cm"] == 0.0
