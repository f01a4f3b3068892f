"""MotionLibrary: the three graphs bound into ClipLibraries, loco clip lookup, ground speeds, rest poses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from protocol.entity import Appearance, make_entity_requests
from server.motion import load_posture_graph
from server.motion.posture_change import LoadedPostureGraph
from server.motion.posture_graph import PostureGraph
from server.motion.synthetic import make_figure, make_soldier
from server.soldier.library import DEFAULT_GROUND_SPEED, MotionLibrary, clip_stem
from server.soldier.manager import SoldierManager
from server.soldier.state import LocoState
from server.soldier.synthetic import synthetic_figures, synthetic_graphs, write_synthetic_library


@pytest.fixture(scope="module")
def graphs():
    return synthetic_graphs()


def subset(loaded: LoadedPostureGraph, keep) -> LoadedPostureGraph:
    pairs = [(f, c) for f, c in zip(loaded.graph.files, loaded.channelsets, strict=True) if keep(f)]
    g = PostureGraph(list(loaded.graph.postures), [f for f, _ in pairs], [], loaded.graph.filename)
    return LoadedPostureGraph(loaded.name, g, [c for _, c in pairs])


def test_clip_names_graphs_and_loco_table(graphs) -> None:
    static, loco, crawl = graphs
    lib = MotionLibrary(static, [synthetic_figures()], loco, crawl)
    assert lib.nclips == 17 + 20 + 2 and lib.can_walk and lib.can_run and lib.can_crawl
    assert lib.clip_names[0] == "soldier_low/ststow2stfire_low"
    assert lib.clip_id("walk2run") == lib.clip_names.index("soldier_loco/walk2run")
    assert lib.clip_id("ststow2kstow") == 1  # the "_low" quality suffix is optional
    assert set(lib.clip_graph[:17].tolist()) == {0} and set(lib.clip_graph[17:37].tolist()) == {1}
    for state, foot, name in [
        (LocoState.WALK_START, 0, "walk_start_l"),
        (LocoState.WALK_CYCLE, 1, "walk_cycle_r"),
        (LocoState.BWALK_END, 0, "bwalk_end_l"),
        (LocoState.WALK2RUN, 1, "walk2run"),
        (LocoState.CRAWL_END, 0, "crawl_start"),
    ]:
        assert lib.clip_names[lib.loco_clip[state, foot]].endswith("/" + name)
    assert lib.loco_dir[LocoState.CRAWL_END] == -1 and lib.loco_dir[LocoState.CRAWL_CYCLE] == 1
    assert clip_stem("dir/walk_cycle_l_low.chset.env") == "walk_cycle_l_low"
    with pytest.raises(KeyError):
        lib.clip_id("nope")


def test_locomotion_clips_are_made_local_and_ground_speed_measured(graphs) -> None:
    static, loco, crawl = graphs
    lib = MotionLibrary(static, [synthetic_figures()], loco, crawl)
    cs = lib.sets[0]
    for cid, info in enumerate(lib.clips):
        rows = slice(cs.clip_start[cid], cs.clip_start[cid] + cs.clip_nframes[cid])
        pos = cs.fig_data[rows, 0, :3]
        if info.graph:
            np.testing.assert_allclose(pos[-1, [0, 2]], pos[0, [0, 2]], atol=1e-3)  # in place
            assert info.travel_cm > 1.0
            assert info.ground_speed == pytest.approx(info.travel_cm / 100.0 / info.duration)
        else:
            assert info.ground_speed == 0.0
    walk = lib.clips[lib.clip_id("walk_cycle_l")]
    assert walk.travel_cm == pytest.approx(70.0, abs=1e-3) and walk.ground_speed == pytest.approx(1.4)
    raw = MotionLibrary(static, [synthetic_figures()], loco, crawl, in_place=False)
    assert raw.clips[lib.clip_id("walk_cycle_l")].travel_cm == 0.0
    assert raw.clip_ground_speed[lib.clip_id("walk_cycle_l")] == pytest.approx(1.4)


def test_ground_speed_fields_take_precedence(graphs) -> None:
    static, loco, crawl = graphs
    loco2 = subset(loco, lambda f: True)
    loco2.channelsets = [c for c in loco.channelsets]
    k = loco2.graph.files.index("walk_cycle_l.chset.env")
    j = loco2.graph.files.index("walk_cycle_r.chset.env")
    loco2.channelsets[k] = _with(loco2.channelsets[k], ground_speed=210.0)  # cm/s
    loco2.channelsets[j] = _with(loco2.channelsets[j], stride_length=100.0)  # cm over 0.5 s
    lib = MotionLibrary(static, [synthetic_figures()], loco2, crawl)
    assert lib.clip_ground_speed[lib.clip_id("walk_cycle_l")] == pytest.approx(2.1)
    assert lib.clip_ground_speed[lib.clip_id("walk_cycle_r")] == pytest.approx(2.0)


def _with(cs, **fields):
    import dataclasses

    new = dataclasses.replace(cs)
    for k, v in fields.items():
        setattr(new, k, v)
    return new


def test_defaults_without_travel_and_missing_families(graphs) -> None:
    static, loco, _ = graphs
    no_run = subset(loco, lambda f: not f.startswith("run") and "2" not in f and not f.startswith("bwalk"))
    lib = MotionLibrary(static, [synthetic_figures()], no_run, None, in_place=False)
    assert lib.can_walk and not lib.can_run and not lib.can_crawl
    # backward walking falls back to the forward steps played backwards
    assert lib.loco_dir[LocoState.BWALK_CYCLE] == -1
    assert lib.loco_clip[LocoState.BWALK_START, 0] == lib.loco_clip[LocoState.WALK_END, 0]
    m = SoldierManager(lib, record_clips=True)
    i = m.create_soldier()
    m.apply_requests(make_entity_requests(i, velocity=(0, 5.0, 0), heading=0.0), 0.0)
    for k in range(90):
        m.tick(k / 30)
    assert {c.clip.rsplit("/")[-1][:10] for c in m.clips_of(i)} <= {"walk_start", "walk_cycle"}
    m2 = SoldierManager(lib)
    j = m2.create_soldier()
    m2.apply_requests(make_entity_requests(j, Appearance.PRONE, velocity=(0, 1.0, 0)), 0.0)
    assert m2.soldier_info(j)["goal"] == "PRONE_STOWED"  # no crawl clips: prone soldiers do not crawl
    assert DEFAULT_GROUND_SPEED["walk"] > 0


def test_rest_poses_and_paths(graphs) -> None:
    static, loco, crawl = graphs
    lib = MotionLibrary(static, [synthetic_figures()], loco, crawl)
    dead = lib.node("DEAD")
    assert lib.clip_names[lib.rest_clip[dead]].endswith("ststow2dead_low") and lib.rest_dir[dead] == 1
    steps = lib.path(lib.node("STAND_STOWED"), lib.node("PRONE_FIRE"))
    assert steps is not None
    assert [lib.postures[s.end] for s in steps] == ["CRAWL", "PRONE_STOWED", "PRONE_FIRE"]
    assert math.isclose(sum(s.duration for s in steps), 3.6)
    assert lib.path(dead, dead) == ()
    assert lib.path(lib.node("STAND_STOWED"), dead) is lib.path(lib.node("STAND_STOWED"), dead)  # cached


def test_several_figure_sets_share_clip_ids(graphs) -> None:
    static, loco, crawl = graphs
    soldier = make_soldier("soldier", "DI.fig", 50)
    sets = [[soldier, make_figure("rifle", "AK_47.fig", [])], [soldier, make_figure("m16", "M16.fig", [])]]
    lib = MotionLibrary(static, sets, loco, crawl)
    assert lib.set_keys == [("DI.fig", "AK_47.fig"), ("DI.fig", "M16.fig")]
    m = SoldierManager(lib)
    a = m.create_soldier(weapon="AK_47.fig")
    b = m.create_soldier(weapon="M16.fig")
    m.apply_requests(make_entity_requests([a, b], Appearance.KNEEL), 0.0)
    u = m.tick(0.5)
    assert u.indices.tolist() == [a, b]
    np.testing.assert_array_equal(u.joints[0], u.joints[1])  # same clip, same soldier figure
    assert not np.array_equal(u.figures[0, 1], u.figures[1, 1])  # the M16 has no recorded placement
    with pytest.raises(ValueError, match="DOFs"):
        MotionLibrary(static, [sets[0], [make_soldier("x", "DI.fig", 40), sets[0][1]]], loco, crawl)


def test_written_library_loads_back(tmp_path, graphs) -> None:
    paths = write_synthetic_library(tmp_path)
    loaded = [load_posture_graph(paths[k]) for k in ("static", "loco", "crawl")]
    a = MotionLibrary(loaded[0], [synthetic_figures()], loaded[1], loaded[2])
    b = MotionLibrary(graphs[0], [synthetic_figures()], graphs[1], graphs[2])
    assert a.clip_names == b.clip_names
    np.testing.assert_allclose(a.clip_duration, b.clip_duration)
    np.testing.assert_allclose(a.clip_ground_speed, b.clip_ground_speed, rtol=1e-5)
    np.testing.assert_allclose(a.sets[0].joint_data, b.sets[0].joint_data, atol=1e-6)


def test_a_weapon_variant_plays_its_own_graphs_and_must_match_clip_for_clip() -> None:
    """Issue 16: an M16 set samples the M16 graphs' channels under the base clip ids; mismatches fail."""
    ak = synthetic_figures(12)
    m16 = [ak[0], make_figure("rifle", "M16.fig", [])]
    static, loco, crawl = synthetic_graphs(ak)
    variant = (*synthetic_graphs(m16, seed=8), None, None)  # the same clips, other data; no turn/react graphs
    lib = MotionLibrary(static, [ak, m16], loco, crawl, weapon_graphs={"M16.fig": variant})
    assert (
        lib.set_keys == [("DI.fig", "AK_47.fig"), ("DI.fig", "M16.fig")]
        and lib.set_index("DI.fig", "M16.fig") == 1
    )
    clip = lib.clip_id("ststow2kstow")
    one = (np.array([clip]), np.array([0.0]), np.array([1]), np.array([1.0]), 0.5)
    a, b = lib.sets[0].sample(*one), lib.sets[1].sample(*one)
    assert np.abs(a.joints - b.joints).max() > 1e-3  # the M16 set plays the M16 graphs' data
    with pytest.raises(ValueError, match="channelsets"):
        no_crawl = (variant[0], variant[1], None, None, None)
        MotionLibrary(static, [ak, m16], loco, crawl, weapon_graphs={"M16.fig": no_crawl})
