"""A dropped rifle falls by him and lies down (issue 14): ``rifle_throw_m`` and ``rifle_upright_s`` on
constructed deaths: a rifle thrown 1.5 m and one dropped 30 cm from where it was let go, one standing on its
butt beside him (on the ground and 4.7 cm above it, as kfire2dead's DI slave's stood) and one lying flat."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_quality import FIGURES, N, _clip, _lying, _rifle_verdict
from test_quality_rifle_rest import _on_ground, _rifle_points, _rot

from authoring.quality import THRESHOLDS, FigureSet, check_clip
from authoring.quality_rifle_drop import THROW_LIMIT_M, UPRIGHT_LIMIT_S
from peabody.loader import read_figure


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


def _dead(figset: FigureSet, rifles: np.ndarray, name: str) -> dict:
    """DI lying on his back, the rifle at ``rifles`` (one location per frame), let go at frame 0."""
    poses, body, _ = _lying(figset)
    cs = _clip(name, figset, poses, body, rifles)
    return _rifle_verdict(check_clip(dataclasses.replace(cs, release_frame=0), figset, ends_dead=True))


def _flat(figset: FigureSet, x: float, z: float) -> np.ndarray:
    """The rifle lying on its side on the ground at (``x``, ``z``)."""
    at = np.eye(4)
    at[:3, 3] = (x, 0.0, z)
    return _on_ground(figset, at @ _rot(2, 90.0))


def _falling(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Every frame's location: from ``start`` (the hands let go) to ``end`` over the first half, lying
    still there over the second."""
    u = np.clip(np.linspace(0.0, 2.0, N), 0.0, 1.0)
    out = np.tile(end, (N, 1, 1))
    out[:, :3, 3] = (1.0 - u)[:, None] * start[:3, 3] + u[:, None] * end[:3, 3]
    return out


def test_a_rifle_thrown_far_fails_and_one_dropped_by_him_passes(figset: FigureSet) -> None:
    """ststow2dead's rifle landed 1.47 m from where his hands let it go: thrown, not dropped."""
    held = _flat(figset, 70.0, 0.0)
    held[1, 3] += 60.0  # in his hands, 60 cm up
    thrown = _dead(figset, _falling(held, _flat(figset, 70.0, -150.0)), "thrown.chset")
    assert thrown["rifle_throw_m"] == pytest.approx(1.5, abs=0.01)
    assert not thrown["pass"] and "rifle_throw_m" in thrown["failures"]
    dropped = _dead(figset, _falling(held, _flat(figset, 70.0, -30.0)), "dropped.chset")
    assert dropped["rifle_throw_m"] == pytest.approx(0.3, abs=0.01)
    assert "rifle_throw_m" not in dropped["failures"]
    assert THRESHOLDS["rifle_throw_m"] == THROW_LIMIT_M == 1.0


def test_a_rifle_standing_on_its_butt_fails(figset: FigureSet) -> None:
    """kfire2dead's rifle stood on its butt by his boot, leaning 33-45 degrees off vertical on nothing."""
    side = np.eye(4)
    side[:3, 3] = (80.0, 0.0, 0.0)  # beside him, clear of the body
    up = _on_ground(figset, side @ _rot(0, 55.0))  # the muzzle up 55 degrees, the butt on the ground
    assert _rifle_points(figset, up)[:, 1].max() > 40.0
    row = _dead(figset, np.tile(up, (N, 1, 1)), "standing.chset")
    assert row["rifle_upright_s"] == pytest.approx(N / 60.0, abs=1e-3)  # every frame: 0.52 s
    assert N / 60.0 > UPRIGHT_LIMIT_S
    assert row["rifle_upright_where"] == f"frames 0-{N - 1}"
    assert not row["pass"] and "rifle_upright_s" in row["failures"]
    up[1, 3] += 4.7  # kfire2dead's DI slave's stood 4.7 cm above the ground, on nothing: the same
    assert _dead(figset, np.tile(up, (N, 1, 1)), "hovering.chset")["rifle_upright_s"] > UPRIGHT_LIMIT_S


def test_a_rifle_lying_flat_does_not_stand(figset: FigureSet) -> None:
    row = _dead(figset, np.tile(_flat(figset, 70.0, 0.0), (N, 1, 1)), "flat.chset")
    assert row["rifle_upright_s"] == 0.0 and row["rifle_upright_where"] is None
    assert row["rifle_throw_m"] == 0.0 and row["pass"], row["failures"]
