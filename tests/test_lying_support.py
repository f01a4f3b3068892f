"""A soldier on the ground is held up by the ground (issue 14: prone stowed and prone fire rest on the belly,
the thighs and both forearms; nothing hovers). ``ttes author check`` judges a prone rest by the chest or belly
and the forearms only, and never asks whether anything touches the ground *during* a clip, so session 19's
audit (measured here on the committed clips, independently of authoring/quality*.py) found:

* every prone posture's thighs 2.6-2.9 cm and shins 8.1-9.5 cm off the ground, daylight under both shins
  from the side and the front;
* crawl2prstow (all three sets) with nothing of the body within 2 cm of the ground for 0.52-0.55 s (frames
  26-57), the lowest point up to 6 cm up while the pelvis stays ~27 cm up: he hovered on his way down (mended
  in session 20: forearms down, then the belly, then the turn on it)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from server.motion.binding import bind_channelset
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES

REST_CM = 2.0  # the limit for a resting part on the ground
UNSUPPORTED_S = 0.2  # longer than a hop with nothing on the ground, the pelvis not falling, is hovering
LEGS = ("left_upper_leg", "right_upper_leg", "left_lower_leg", "right_lower_leg")
SETS = {"soldier": ("", "soldier.fig", "AK_47.fig"), "DI": ("_low", "DI.fig", "AK_47.fig"),
        "M16": ("_m16_low", "DI.fig", "M16.fig")}  # fmt: skip
PRONE_ENDS = {"PRONE_STOWED": "crawl2prstow", "PRONE_FIRE": "prstow2prfire"}  # clips whose last frame it is


@cache
def _kinematics(name: str) -> FigureKinematics:
    return FigureKinematics(read_figure(FIGURES / name))


@cache
def lowest_heights(clip: str, body: str, rifle: str) -> tuple[float, dict[str, np.ndarray]]:
    """Frames per second of channelset ``clip`` and, per body segment with a mesh, the height (cm) of its
    lowest node in every frame."""
    cs = load_channelset(CHANNELSETS / f"{clip}.chset.env")
    kin = _kinematics(body)
    bound = bind_channelset(cs, [kin.figure, _kinematics(rifle).figure])
    bf = next(f for f in bound.figures if f.protofiletype == body)
    q = np.empty((cs.nframes, kin.ndof))
    places = np.empty((cs.nframes, 4, 4))
    roots = []
    for i in range(cs.nframes):
        sample = bound.sample(i, interpolate=False)
        placement = sample.placements[bf.figure]
        assert placement is not None
        q[i] = sample.poses[bf.figure]
        places[i] = placement.matrix()
        roots.append(kin.site_names.index(placement.root))
    eye = np.broadcast_to(np.eye(4), (cs.nframes, 4, 4))
    local = kin.segment_globals(q, eye)
    root = kin.site_globals(q, eye)[np.arange(cs.nframes), roots]
    world = places @ np.linalg.inv(root)
    out = {}
    for i, name in enumerate(kin.segment_names):
        seg = kin.figure.segments[name]
        if seg.psurf is None or not len(seg.psurf.nodes):
            continue
        nodes = np.c_[np.asarray(seg.psurf.nodes, np.float64).reshape(-1, 3), np.ones(len(seg.psurf.nodes))]
        if seg.psurf_transform is not None:
            nodes = nodes @ np.asarray(seg.psurf_transform).T
        g = world @ local[:, i]
        out[name] = np.einsum("nj,kj->nk", g[:, 1], nodes).min(axis=1)
    return cs.fps, out


def longest_unsupported_s(fps: float, heights: dict[str, np.ndarray]) -> float:
    """The longest time (s) nothing of the body is within REST_CM of the ground."""
    free = np.min(np.stack(list(heights.values())), axis=0) > REST_CM
    edges = np.diff(np.r_[0, free.astype(np.int8), 0])
    lengths = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    return float(lengths.max(initial=0)) / fps


def test_the_measures_see_a_standing_soldier_on_his_feet_and_a_runner_in_flight() -> None:
    """The measures themselves: standing, the feet touch the ground and the thighs are half a metre up; a run
    cycle's flight phase (both feet up, ~0.13 s) is unsupported but short."""
    fps, h = lowest_heights("ststow2stfire_low", "DI.fig", "AK_47.fig")
    assert min(h["left_foot"][0], h["left_toes"][0], h["right_foot"][0], h["right_toes"][0]) <= REST_CM
    assert h["left_upper_leg"][0] > 40.0 and h["right_upper_leg"][0] > 40.0
    assert longest_unsupported_s(fps, h) == 0.0
    fps, h = lowest_heights("run_cycle_l_low", "DI.fig", "AK_47.fig")
    assert 0.05 < longest_unsupported_s(fps, h) < UNSUPPORTED_S


@pytest.mark.xfail(
    strict=True,
    reason="seen from the side and the front, his shins are held up (knees ~9 cm), daylight under them",
)
@pytest.mark.parametrize("posture", sorted(PRONE_ENDS))
@pytest.mark.parametrize("figure", sorted(SETS))
def test_prone_thighs_and_shins_lie_on_the_ground(figure: str, posture: str) -> None:
    suffix, body, rifle = SETS[figure]
    _, h = lowest_heights(PRONE_ENDS[posture] + suffix, body, rifle)
    assert h["lower_torso"][-1] <= REST_CM  # he is lying: the pelvis is down (this part passes today)
    up = {leg: round(float(h[leg][-1]), 1) for leg in LEGS if h[leg][-1] > REST_CM}
    assert not up, f"{posture} ({figure}): legs off the ground (cm): {up}"


@pytest.mark.parametrize("figure", sorted(SETS))
def test_going_prone_from_the_crawl_keeps_him_on_the_ground(figure: str) -> None:
    suffix, body, rifle = SETS[figure]
    fps, h = lowest_heights("crawl2prstow" + suffix, body, rifle)
    assert longest_unsupported_s(fps, h) <= UNSUPPORTED_S
