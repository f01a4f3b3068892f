"""DEAD variant nodes (``DEAD@<start>``): each death ends in its own variant, getting up replays it backwards.

The static graph of the physics deaths (issue 14, option (b)) has no plain DEAD node: asked for DEAD a
soldier goes to the variant he reaches first, a dead soldier asked for DEAD stays where he lies, and the
status and soldier_info report the posture name ``DEAD``. Explicit times (no clocks)."""

from __future__ import annotations

import pytest

from protocol.entity import Appearance, WeaponState
from server.motion.posture_change import LoadedPostureGraph, bind_posture_graph
from server.motion.posture_graph import Arc, PostureGraph, posture_of
from server.soldier.library import MotionLibrary
from server.soldier.manager import SoldierManager
from server.soldier.synthetic import STATIC_FILES, synthetic_figures, synthetic_graphs
from tests.test_soldier_manager import request, run, seq

UP, KNEEL, PRONE, DEAD = Appearance.UPRIGHT, Appearance.KNEEL, Appearance.PRONE, Appearance.DEAD
DEPLOYED, FIRING = WeaponState.DEPLOYED, WeaponState.FIRING
GET_UP = 10.0


def variant(stem: str) -> str:
    return f"DEAD@{stem.removesuffix('2dead')}"


def variant_static_graph() -> LoadedPostureGraph:
    """The synthetic static graph with every death ending in its own DEAD variant (as ttes author build
    writes it): ``start -> DEAD@x`` forwards, ``DEAD@x -> start`` backwards in GET_UP seconds."""
    static, _, _ = synthetic_graphs()
    g = static.graph
    nodes = [p for p in g.postures if p != "DEAD"]
    arcs: list[Arc] = []
    for tok, (stem, a, z, secs) in enumerate(STATIC_FILES):
        if z == "DEAD":
            nodes.append(variant(stem))
            arcs += [Arc(a, variant(stem), tok, True, -1.0), Arc(variant(stem), a, tok, False, GET_UP)]
        else:
            arcs += [Arc(a, z, tok, True, secs), Arc(z, a, tok, False, secs)]
    return LoadedPostureGraph(static.name, PostureGraph(nodes, g.files, arcs, g.filename), static.channelsets)


@pytest.fixture(scope="module")
def lib() -> MotionLibrary:
    _, loco, crawl = synthetic_graphs()
    return MotionLibrary(variant_static_graph(), [synthetic_figures()], loco, crawl)


def manager(lib: MotionLibrary) -> tuple[SoldierManager, int]:
    m = SoldierManager(lib, record_clips=True)
    return m, m.create_soldier(now=0.0)


def test_posture_of_a_variant_node_is_its_posture() -> None:
    assert posture_of("DEAD@ststow") == "DEAD"
    assert posture_of("KNEEL_FIRE") == "KNEEL_FIRE"


def test_the_graph_goes_to_the_nearest_variant_and_stays_in_one() -> None:
    loaded = variant_static_graph()
    g, d = loaded.graph, loaded.durations
    assert sorted(g.variants("DEAD")) == sorted(variant(s) for s, _, z, _ in STATIC_FILES if z == "DEAD")
    assert g.nearest("KNEEL_FIRE", "DEAD", d) == "DEAD@kfire"
    assert g.nearest("PRONE_FIRE", "DEAD", d) == "DEAD@prfire"
    assert g.nearest("DEAD@crawl", "DEAD", d) == "DEAD@crawl"
    assert g.nearest("STAND_FIRE", "DEAD@ststow", d) == "DEAD@ststow"  # an exact node is kept
    path = loaded.shortest_path("STAND_FIRE", "DEAD")
    assert [(a.start, a.end, a.forward) for a in path] == [("STAND_FIRE", "DEAD@stfire", True)]
    assert loaded.shortest_path("DEAD@kstow", "DEAD") == []


def test_a_bound_posture_change_to_dead_takes_the_nearest_variant() -> None:
    loaded = variant_static_graph()
    bound = bind_posture_graph(loaded, synthetic_figures(), initial="PRONE_STOWED")
    assert bound.shortest_path("DEAD")[-1].end == "DEAD@prstow"


def test_the_library_precomputes_the_variant_to_head_for(lib: MotionLibrary) -> None:
    dead = lib.node("DEAD")  # the posture name finds a variant node
    assert lib.posture_names[dead] == "DEAD"
    nearest = [("STAND_STOWED", "DEAD@ststow"), ("KNEEL_STOWED", "DEAD@kstow"), ("CRAWL", "DEAD@crawl")]
    for start, expect in nearest:
        assert lib.postures[lib.goal_node[lib.node(start), dead]] == expect
    for v in lib.static.graph.variants("DEAD"):  # the dead stay where they lie
        assert lib.goal_node[lib.node(v), dead] == lib.node(v)
    ks = lib.node("KNEEL_STOWED")
    assert lib.goal_node[lib.node("STAND_STOWED"), ks] == ks  # plain postures are their own goal


@pytest.mark.parametrize(
    ("app", "weapon", "clip", "node"),
    [
        (UP, DEPLOYED, "ststow2dead", "DEAD@ststow"),
        (UP, FIRING, "stfire2dead", "DEAD@stfire"),
        (KNEEL, FIRING, "kfire2dead", "DEAD@kfire"),
        (PRONE, FIRING, "prfire2dead", "DEAD@prfire"),
    ],
)
def test_each_posture_dies_its_own_death(lib: MotionLibrary, app, weapon, clip, node) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, app, weapon, immediate=True)  # start resting in the posture
    request(m, i, 0.5, DEAD)
    run(m, 0.5, 5.0)
    assert seq(m, i)[-1] == (clip, True)
    info = m.soldier_info(i)
    assert (info["mode"], info["posture"], info["node"], info["goal"]) == ("IDLE", "DEAD", node, "DEAD")
    assert m.status()["postures"] == {"DEAD": 1}


def test_a_dead_soldier_asked_for_dead_stays(lib: MotionLibrary) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, KNEEL, DEPLOYED, immediate=True)
    request(m, i, 0.1, DEAD)
    run(m, 0.1, 3.0)
    before = seq(m, i)
    request(m, i, 3.0, DEAD)
    request(m, i, 3.5, DEAD, immediate=True)
    request(m, i, 4.0, DEAD, speed=2.0)  # nor do the dead walk
    run(m, 3.0, 6.0)
    assert seq(m, i) == before
    assert m.soldier_info(i)["node"] == "DEAD@kstow"


def test_getting_up_replays_that_death_backwards_slowly(lib: MotionLibrary) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, KNEEL, FIRING, immediate=True)
    request(m, i, 0.1, DEAD)
    run(m, 0.1, 3.0)
    request(m, i, 3.0, KNEEL, FIRING)
    run(m, 3.0, 3.0 + GET_UP + 1.0)
    log = m.clips_of(i)
    last = log[-1]
    assert (last.clip.rsplit("/", 1)[-1], last.forward, last.duration, last.time) == (
        "kfire2dead_low",
        False,
        GET_UP,
        3.0,
    )
    info = m.soldier_info(i)
    assert (info["mode"], info["posture"], info["node"]) == ("IDLE", "KNEEL_FIRE", "KNEEL_FIRE")


def test_a_soldier_dies_where_he_is_even_if_another_death_ends_sooner() -> None:
    """Physics deaths last as long as the body takes to settle: a kneeling death of 4 s must still win over
    standing up (1.2 s) and dying standing (1.5 s)."""
    loaded = variant_static_graph()
    g = loaded.graph
    slow = [4.0 if f.startswith("kfire2dead") else d for f, d in zip(g.files, loaded.durations, strict=True)]
    assert g.nearest("KNEEL_FIRE", "DEAD", slow) == "DEAD@kfire"
    path = g.shortest_path("KNEEL_FIRE", "DEAD", slow)
    assert [(a.start, a.end) for a in path] == [("KNEEL_FIRE", "DEAD@kfire")]
