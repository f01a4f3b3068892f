"""The key postures of seed 002 Figure 7 (authoring/postures.py), checked by forward kinematics."""

from __future__ import annotations

import numpy as np
import pytest

from authoring import postures as P
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from ttes.paths import FIGURES


@pytest.fixture(scope="module")
def solved():
    soldier = read_figure(FIGURES / "soldier.fig")
    rifle = read_figure(FIGURES / "AK_47.fig")
    kin, rkin = FigureKinematics(soldier), FigureKinematics(rifle)
    keys = P.build_postures(soldier, rifle, list(P.POSTURES))
    return kin, rkin, keys


def _sites(kin, key):
    return kin.site_globals(key.poses[P.SOLDIER], key.locations[P.SOLDIER])


def _site(kin, g, name):
    return g[kin.site_names.index(name), :3, 3]


def test_the_eight_graph_postures_are_specified():
    assert set(P.POSTURES) <= set(P.specs())
    assert len(P.POSTURES) == 8


def test_palm_centres_hold_the_rifle(solved):
    kin, rkin, keys = solved
    rsite = {n: g for n, g in zip(rkin.site_names, rkin.site_globals(np.zeros(0)), strict=True)}
    for name, key in keys.items():
        g = _sites(kin, key)
        rifle = key.locations[P.RIFLE]
        for palm, handle in (
            ("right_palm.palmcenter", "rifle.grip"),
            ("left_palm.palmcenter", "rifle.handguard"),
        ):
            target = (rifle @ rsite[handle])[:3, 3]
            assert np.linalg.norm(_site(kin, g, palm) - target) < 1.0, (name, palm)


def test_no_body_part_sinks_into_the_ground_and_limits_hold(solved):
    kin, _, keys = solved
    for name, key in keys.items():
        q = key.poses[P.SOLDIER]
        assert P.lowest_point(kin, q, key.locations[P.SOLDIER]) > -1.0, name
        assert np.all(q >= kin.lower - 1e-9) and np.all(q <= kin.upper + 1e-9), name


def test_fire_postures_aim_along_the_heading_from_the_shoulder(solved):
    kin, rkin, keys = solved
    butt = rkin.site_globals(np.zeros(0))[rkin.site_names.index("rifle.butt")]
    for name in ("STAND_FIRE", "KNEEL_FIRE", "PRONE_FIRE"):
        key = keys[name]
        rifle = key.locations[P.RIFLE]
        barrel = rifle[:3, :3] @ np.array([0.0, 0.0, -1.0])
        assert np.degrees(np.arccos(np.clip(barrel @ [0.0, 0.0, -1.0], -1, 1))) < 0.01, name
        pocket = P.shoulder_pocket(kin, key.poses[P.SOLDIER], key.locations[P.SOLDIER], P.SPECS[name].pocket)
        # prone, the elbows going down to the ground turn the right clavicle after the rifle is slid there
        assert np.linalg.norm((rifle @ butt)[:3, 3] - pocket) < (3.5 if name == "PRONE_FIRE" else 2.0), name
    # standing and kneeling shooters have the right eye on the line of sight
    sight = rkin.site_globals(np.zeros(0))[rkin.site_names.index("rifle.sight")]
    for name in ("STAND_FIRE", "KNEEL_FIRE"):
        key = keys[name]
        eye = _site(kin, _sites(kin, key), "bottom_head.right_eye")
        line = (key.locations[P.RIFLE] @ sight)[:3, 3]
        off = eye - line
        assert abs(off[0]) < 1.0 and 0.0 < off[1] < 3.0, (name, off)


def test_stowed_rifle_is_lowered_and_firing_moves_only_arms_head_and_rifle(solved):
    kin, _, keys = solved
    for stowed, fire in (("STAND_STOWED", "STAND_FIRE"), ("KNEEL_STOWED", "KNEEL_FIRE")):
        barrel = keys[stowed].locations[P.RIFLE][:3, :3] @ np.array([0.0, 0.0, -1.0])
        assert barrel[1] < -0.3  # muzzle down: at the ready
        np.testing.assert_allclose(keys[stowed].locations[P.SOLDIER], keys[fire].locations[P.SOLDIER])
        for side in ("left", "right"):
            a = _site(kin, _sites(kin, keys[stowed]), f"{side}_foot.heel")
            b = _site(kin, _sites(kin, keys[fire]), f"{side}_foot.heel")
            assert np.linalg.norm(a - b) < 0.5


def test_standing_feet_are_flat_and_lying_postures_are_low(solved):
    kin, _, keys = solved
    for name in ("STAND_STOWED", "STAND_FIRE"):
        g = _sites(kin, keys[name])
        for side in ("left", "right"):
            for site in ("heel", "ball"):
                assert abs(_site(kin, g, f"{side}_foot.{site}")[1]) < 0.6, (name, side, site)
    for name in ("PRONE_STOWED", "PRONE_FIRE", "DEAD"):
        assert keys[name].locations[P.SOLDIER][1, 3] < 25.0, name
    # kneeling: the right kneecap is down, the left foot flat
    g = _sites(kin, keys["KNEEL_STOWED"])
    assert _site(kin, g, "right_lower_leg.knee")[1] < 3.0
    assert abs(_site(kin, g, "left_foot.heel")[1]) < 1.0


def test_spine_angles_spread_a_bend_over_the_vertebrae():
    kin = FigureKinematics(read_figure(FIGURES / "soldier.fig"))
    sp = P.spine_angles(kin, -3.0, 16.0, -5.0)
    assert sp.shape == (17, 3)
    np.testing.assert_allclose(np.degrees(sp.sum(axis=0)), [-3.0, 16.0, -5.0])
    idx = np.array([np.arange(kin.dof_slices[j].start, kin.dof_slices[j].stop) for j in P.SPINE])
    assert np.all(sp >= kin.lower[idx]) and np.all(sp <= kin.upper[idx])


def test_placement_is_jack_xyz_then_translation():
    m = P.Placement((1.0, 2.0, 3.0), (0.0, 90.0, 0.0)).matrix()
    np.testing.assert_allclose(m[:3, 3], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(m[:3, :3] @ [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], atol=1e-12)


def test_kneeling_kneecap_rests_and_the_rifle_clears_the_body(solved):
    """The kneeling knee carries weight (its kneecap mesh is the body's lowest point, within a centimetre)
    and the rifle at the ready or aimed stays out of the raised left thigh and every other segment."""
    pytest.importorskip("scipy")
    from authoring.quality_frames import FigureSet

    kin, rkin, keys = solved
    figs = FigureSet({"soldier.fig": kin.figure, "AK_47.fig": rkin.figure})
    nodes, segs = figs.nodes("soldier.fig")
    kneecap = figs.node_parts("soldier.fig") == "right_kneecap"
    rnodes, rsegs = figs.nodes("AK_47.fig")
    for name in ("KNEEL_STOWED", "KNEEL_FIRE"):
        key = keys[name]
        g = kin.segment_globals(key.poses[P.SOLDIER][None], key.locations[P.SOLDIER][None])
        y = np.einsum("kj,kj->k", g[0, segs, 1, :], nodes)
        assert y[kneecap].min() - y.min() < 1.0, name
        rg = rkin.segment_globals(np.zeros((1, 0)), key.locations[P.RIFLE][None])
        rpts = np.einsum("fkij,kj->fki", rg[:, rsegs, :3, :], rnodes)
        depth, _, _ = figs.hulls("soldier.fig").depth(rpts, g)
        assert depth == 0.0, name
