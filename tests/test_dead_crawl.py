"""A dead crawler's trunk comes down about his thighs (authoring/dead_crawl.py, issue 14): on a constructed
body bridged over his thighs, the pelvis and belly come down to the ground while the upper trunk stays where
it lies and nothing on the ground slides."""

from __future__ import annotations

import numpy as np
import pytest

from authoring import dead_crawl, dead_settle
from authoring.body_parts import contact_runs
from authoring.ik import axis_angle
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.loader import read_figure
from ttes.paths import FIGURES

TRUNK_DOWN_CM = 1.0  # the check's rest_contact_cm limit is 2


@pytest.fixture(scope="module")
def figs() -> FigureSet:
    return FigureSet(
        {"body": read_figure(FIGURES / "soldier.fig"), "rifle": read_figure(FIGURES / "AK_47.fig")}
    )


def _bridged(figs: FigureSet) -> ClipFrames:
    """soldier.fig face down, straight but for his knees (15 deg) and pointed feet, pitched 10 deg head up:
    he lies on his thighs near the knees, the hips higher, the pelvis and belly 4 cm over the ground (as
    crawl2dead's ragdoll left him, propped on his forearms: 4.2-4.5 cm)."""
    kin = figs.kin["body"]
    q = np.zeros(kin.ndof)
    for side in ("left", "right"):
        q[kin.dof_slices[f"{side}_ankle"]] = np.radians([-50.0, 0.0])
        q[kin.dof_slices[f"{side}_knee"]] = np.radians([15.0])
    root = np.eye(4)
    face_down = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    root[:3, :3] = axis_angle(np.array([1.0, 0.0, 0.0]), np.radians(10.0)) @ face_down
    nodes, segs = figs.nodes("body")
    arms = np.array([str(p).endswith(dead_settle.ARM_PARTS) for p in figs.node_parts("body")])
    root[1, 3] -= np.einsum("kj,kj->k", kin.segment_globals(q, root)[segs, 1, :], nodes)[~arms].min()
    rifle = np.eye(4)
    rifle[0, 3] = 300.0  # out of the way
    return ClipFrames(q[None], root[None], rifle[None])


@pytest.fixture(scope="module")
def sunk(figs: FigureSet) -> ClipFrames:
    return dead_crawl.sunk(figs, _bridged(figs))


def _points(figs: FigureSet, frames: ClipFrames) -> np.ndarray:
    kin = figs.kin["body"]
    nodes, segs = figs.nodes("body")
    g = kin.segment_globals(frames.poses, frames.roots)
    return np.einsum("fkij,kj->fki", g[:, segs, :3, :], nodes)


def test_a_bridged_crawlers_pelvis_and_belly_come_down(figs: FigureSet, sunk: ClipFrames) -> None:
    """Issue 14: crawl2dead's pelvis and belly rested 4.2-4.5 cm up (rest_contact_cm, limit 2), the body
    bridged between its thighs and its forearms."""
    start = _bridged(figs)
    parts = figs.node_parts("body")
    before = _points(figs, start)[0]
    assert min(before[parts == p, 1].min() for p in ("pelvis", "belly")) > 3.0  # the case: bridged
    out = sunk
    assert len(out.poses) == 1 + round(dead_crawl.SINK_SECONDS * out.fps)
    after = _points(figs, out)
    for part in ("pelvis", "belly"):
        assert after[-1, parts == part, 1].min() <= TRUNK_DOWN_CM


def test_the_upper_trunk_stays_and_nothing_on_the_ground_slides(figs: FigureSet, sunk: ClipFrames) -> None:
    """The spine holds the upper trunk (and with it the arms and head) where it lies at every frame; the
    thighs turn about their contacts, the feet stay; nothing sinks into the ground."""
    kin, out = figs.kin["body"], sunk
    held = kin.segment_globals(out.poses, out.roots)[:, kin.segment_names.index(dead_crawl.HELD), :3, 3]
    assert np.linalg.norm(held - held[0], axis=1).max() < 1.0
    parts = figs.node_parts("body")
    body = ~np.array([str(p).endswith(dead_settle.ARM_PARTS) for p in parts])
    points = _points(figs, out)[:, body]
    assert points[..., 1].min() > -0.5
    assert contact_runs(points, CONTACT_HEIGHT_CM).slide.max(initial=0.0) < 1.0
    feet = np.isin(parts[body], ("left_foot", "right_foot"))
    assert (points[:, feet, 1].min(axis=1) - points[0, feet, 1].min()).max() < 2.0  # the feet stay down


def test_a_body_on_the_ground_or_off_its_thighs_does_not_sink(figs: FigureSet, sunk: ClipFrames) -> None:
    down = ClipFrames(sunk.poses[-1:], sunk.roots[-1:], sunk.rifles[-1:])
    assert dead_crawl.sunk(figs, down) is down  # the trunk lies down already
    up = ClipFrames(down.poses, down.roots.copy(), down.rifles)
    up.roots[0, 1, 3] += 5.0  # the thighs off the ground
    assert dead_crawl.sunk(figs, up) is up
