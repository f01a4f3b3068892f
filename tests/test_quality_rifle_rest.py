"""A dropped rifle at rest lies on something (issue 14): ``rifle_rest_overhang_cm`` on constructed deaths,
a rifle lying flat, one balanced on its muzzle with the butt up, one lying across the dead man."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_quality import FIGURES, _clip, _lying, _rifle_verdict

from authoring.quality import THRESHOLDS, FigureSet, check_clip
from authoring.quality_rifle_rest import OVERHANG_LIMIT_CM
from peabody.loader import read_figure


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


def _rot(axis: int, deg: float) -> np.ndarray:
    a, b = [i for i in range(3) if i != axis]
    m = np.eye(4)
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    m[[a, a, b, b], [a, b, a, b]] = [c, -s, s, c]
    return m


def _rifle_points(figset: FigureSet, loc: np.ndarray) -> np.ndarray:
    nodes, _ = figset.nodes("AK_47.fig")  # one segment: the rifle
    return (loc @ nodes.T).T[:, :3]


def _dead(figset: FigureSet, rifle: np.ndarray, name: str) -> dict:
    """DI lying on his back, the rifle at ``rifle`` (one location, every frame), let go at frame 0."""
    poses, body, _ = _lying(figset)
    cs = _clip(name, figset, poses, body, np.tile(rifle, (len(poses), 1, 1)))
    return _rifle_verdict(check_clip(dataclasses.replace(cs, release_frame=0), figset, ends_dead=True))


def _on_ground(figset: FigureSet, loc: np.ndarray) -> np.ndarray:
    loc = loc.copy()
    loc[1, 3] += 0.5 - _rifle_points(figset, loc)[:, 1].min()  # its lowest node 0.5 cm up
    return loc


def test_a_rifle_lying_on_the_ground_rests(figset: FigureSet) -> None:
    side = np.eye(4)
    side[:3, 3] = (70.0, 0.0, 0.0)  # beside him
    flat = _dead(figset, _on_ground(figset, side @ _rot(2, 90.0)), "flat.chset")  # on its side
    assert flat["rifle_rest_overhang_cm"] == 0.0 and "nodes on the ground" in flat["rifle_rest_where"]
    assert THRESHOLDS["rifle_rest_overhang_cm"] == OVERHANG_LIMIT_CM == 2.0 and flat["pass"]


def test_a_rifle_balanced_on_its_muzzle_does_not_rest(figset: FigureSet) -> None:
    """prfire2dead (M16) ended with the rifle on its muzzle, the butt 36 cm up and nothing under it: 60 cm."""
    side = np.eye(4)
    side[:3, 3] = (70.0, 0.0, 0.0)
    tilted = side @ _rot(0, -25.0) @ _rot(2, 90.0)  # muzzle (-Z) down, butt up 25 degrees
    row = _dead(figset, _on_ground(figset, tilted), "tilted.chset")
    assert row["rifle_rest_overhang_cm"] > 20.0
    assert not row["pass"] and "rifle_rest_overhang_cm" in row["failures"]
    up = side.copy()
    up[1, 3] = 50.0  # in the air, touching nothing: its centre's height
    row = _dead(figset, up, "floating.chset")
    assert row["rifle_rest_overhang_cm"] == pytest.approx(up[1, 3] + _grip_height(figset), abs=0.01)


def _grip_height(figset: FigureSet) -> float:
    return float(figset.figures["AK_47.fig"].site("rifle.grip").location[1, 3])


def test_a_rifle_lying_across_him_rests_on_the_body(figset: FigureSet) -> None:
    poses, body, _ = _lying(figset, n=1)
    kin = figset.kin["DI.fig"]
    segg = kin.segment_globals(poses, body)[0]
    hulls = figset.hulls("DI.fig", hands=True)
    loc = _rot(1, 90.0) @ _rot(2, 90.0)  # on its side, across his belly (along X), its grip over the belly
    grip = figset.figures["AK_47.fig"].site("rifle.grip").location[:, 3]
    belly = segg[kin.segment_names.index("lower_torso"), :3, 3]
    loc[:3, 3] = np.r_[belly[0], 60.0, belly[2]] - (loc @ grip)[:3]
    for _ in range(60):  # lower it until it touches him
        pts = _rifle_points(figset, loc)
        gap = min(hulls.clearance(pts, segg).min(), pts[:, 1].min())
        if gap <= 0.5:
            break
        loc[1, 3] -= gap - 0.25
    row = _dead(figset, loc, "across.chset")
    assert row["rifle_rest_overhang_cm"] < OVERHANG_LIMIT_CM / 2  # its grip over the patch it lies on
    assert row["rifle_rest_where"].startswith("frame 30: 0 nodes on the ground")
    assert "0 on the body" not in row["rifle_rest_where"]


def test_only_a_dropped_rifle_at_dead_is_judged(figset: FigureSet) -> None:
    poses, body, _ = _lying(figset)
    up = np.eye(4)
    up[:3, 3] = (70.0, 50.0, 0.0)
    cs = _clip("held.chset", figset, poses, body, np.tile(up, (len(poses), 1, 1)))
    assert "rifle_rest_overhang_cm" not in check_clip(cs, figset, ends_dead=True)  # never let go
    dropped = dataclasses.replace(cs, release_frame=0)
    assert "rifle_rest_overhang_cm" not in check_clip(dropped, figset)  # not a death
