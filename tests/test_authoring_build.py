"""The committed motion library (channelsets/, posture_graphs/) and `ttes author build` that makes it."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from authoring import build as B
from authoring import deaths, gait, postures, transitions
from peabody.loader import read_environment, read_figure
from server.jcl import parse_jcl
from server.motion.cache import load_npz, save_npz
from server.motion.channelset_file import format_channelset, parse_channelsets
from server.motion.posture_change import load_posture_graph
from server.motion.posture_graph import posture_of
from server.motion.synthetic import synthetic_channelset, toy_rifle, toy_soldier
from ttes.cli import main
from ttes.paths import CHANNELSETS, FIGURES, POSTURE_GRAPHS

GRAPHS = [g for fs in B.GRAPH_FILES.values() for g in fs.values()]
CLIP_NAMES = {j.name for j in B.clip_jobs()}


def test_stride_length_and_ground_speed_round_trip(tmp_path: Path):
    cs = synthetic_channelset("walk_cycle_l.chset", [toy_soldier(), toy_rifle()], 5, 60.0)
    cs = dataclasses.replace(cs, stride_length=74.25, ground_speed=134.5)
    text = format_channelset(cs)
    assert "stride_length = 74.25;" in text and "ground_speed = 134.5;" in text
    back = parse_channelsets(text)[0]
    assert (back.stride_length, back.ground_speed) == (74.25, 134.5)
    assert format_channelset(back) == text
    save_npz(back, tmp_path / "c.npz")
    cached = load_npz(tmp_path / "c.npz")
    assert cached is not None and (cached.stride_length, cached.ground_speed) == (74.25, 134.5)
    plain = parse_channelsets(
        format_channelset(dataclasses.replace(cs, stride_length=None, ground_speed=None))
    )[0]
    assert plain.stride_length is None and plain.ground_speed is None
    with pytest.raises(Exception, match="ground_speed"):
        parse_channelsets(text.replace("ground_speed = 134.5", "ground_speed = -1"))


@pytest.mark.parametrize("name", GRAPHS)
def test_graphs_load_and_every_arc_has_its_channelset(name: str):
    loaded = load_posture_graph(POSTURE_GRAPHS / name)
    graph = loaded.graph
    assert len(loaded.channelsets) == len(graph.files)
    figure_set = next(fs for fs, files in B.GRAPH_FILES.items() if name in files.values())
    want = {
        "soldier": {"soldier.fig", "AK_47.fig"},
        "DI": {"DI.fig", "AK_47.fig"},
        "M16": {"DI.fig", "M16.fig"},
    }
    suffix = B.SUFFIXES[figure_set]
    for cs, fname in zip(loaded.channelsets, graph.files, strict=True):
        types = {c.protofiletype for c in cs.figure_channels()}
        assert types == want[figure_set], cs.name
        stem = Path(fname).name.removesuffix(".chset.env")  # a clip of this figure set only
        assert stem.endswith(suffix) and stem[: len(stem) - len(suffix)] in CLIP_NAMES, fname
        assert cs.fps == 60
    for arc in graph.arcs:
        assert 0 <= arc.channelset < len(graph.files)


def test_static_graph_is_figure_7():
    loaded = load_posture_graph(POSTURE_GRAPHS / "soldier_low.graph")
    graph = loaded.graph
    variants = [f"DEAD@{d.name.removesuffix('2dead')}" for d in deaths.DEATHS]
    assert graph.postures == [p for p in postures.POSTURES if p != "DEAD"] + variants
    assert len(graph.files) == 17
    assert graph.files[0].endswith("ststow2stfire_low.chset.env")
    assert graph.files[16].endswith("stfire2kstow_low.chset.env")
    arcs = {(a.start, a.end): a for a in graph.arcs}
    for d in deaths.DEATHS:  # each death ends in its own DEAD variant; getting up replays it backwards
        node = deaths.dead_node(d.name)
        die, get_up = arcs[(d.start, node)], arcs[(node, d.start)]
        assert die.forward and die.time == -1.0
        assert not get_up.forward and get_up.time == deaths.GET_UP_SECONDS
        assert graph.files[die.channelset].endswith(f"{d.name}_low.chset.env")
        assert die.channelset == get_up.channelset
    assert sorted(a.start for a in graph.arcs if posture_of(a.start) == "DEAD") == sorted(variants)
    assert (
        arcs[("STAND_STOWED", "STAND_FIRE")].time == 0.8
        and arcs[("STAND_STOWED", "KNEEL_STOWED")].time == 1.6
    )
    path = [a.end for a in loaded.shortest_path("STAND_STOWED", "PRONE_FIRE")]
    assert path == ["CRAWL", "PRONE_STOWED", "PRONE_FIRE"]


def test_startup_environment_and_script():
    env = read_environment(POSTURE_GRAPHS / "jack-ttes-soldier_low.env")
    for i in range(10):
        assert env.figures[f"Di2_{i}"].filename == "DI.fig"
        assert env.figures[f"AK_47_{i}"].filename == "AK_47.fig"
    calls = parse_jcl((POSTURE_GRAPHS / "jack-ttes-soldier_low.jcl").read_text(), "jack-ttes-soldier_low.jcl")
    assert calls[0].name == "read_file" and calls[0].args == ("jack-ttes-soldier_low.env",)
    states = [c.args for c in calls if c.name == "create_soldier_state"]
    assert states == [(f"s{i}", f"Di2_{i}", f"AK_47_{i}") for i in range(10)]
    assert [c.name for c in calls[-2:]] == ["start_ttes_socket_simulation", "disable_graphics"]


def test_locomotion_clips_record_stride_and_speed():
    from server.motion.cache import load_channelset

    for name in gait.LOCO_CLIPS:
        for suffix in ("", "_low"):
            c = load_channelset(CHANNELSETS / f"{name}{suffix}.chset.env")
            assert c.stride_length is not None and c.stride_length > 0, name
            assert c.ground_speed == pytest.approx(c.stride_length / c.duration, rel=1e-3, abs=0.02), name
    walk = load_channelset(CHANNELSETS / "walk_cycle_l.chset.env")
    run = load_channelset(CHANNELSETS / "run_cycle_l.chset.env")
    assert 100 < walk.ground_speed < 180 and run.ground_speed > 250


def test_transitions_start_and_end_in_their_graph_postures():
    from server.motion.cache import load_channelset

    soldier = read_figure(FIGURES / "soldier.fig")
    rifle = read_figure(FIGURES / "AK_47.fig")
    keys = postures.build_postures(soldier, rifle, list(postures.POSTURES))
    for t in transitions.TRANSITIONS:
        cs = load_channelset(CHANNELSETS / f"{t.name}.chset.env")
        ends = ((0, t.start),) if t.name in deaths.death_specs() else ((0, t.start), (-1, t.end))
        for frame, posture in ends:  # a death ends where the physics laid it (its own DEAD variant)
            q = keys[posture].poses[postures.SOLDIER]
            got = np.concatenate(
                [cs.angles(cs.channel(j))[frame] for j, jt in soldier.joints.items() if jt.ndofs]
            )
            np.testing.assert_allclose(got, q, atol=1e-5, err_msg=f"{t.name}[{frame}] vs {posture}")


def test_build_of_one_clip_reproduces_the_committed_bytes(tmp_path: Path, capsys):
    rc = main(
        ["author", "build", "--only", "ststow2stfire", "--out", str(tmp_path), "--no-progress", "--json"]
    )
    assert rc == 0
    assert '"channelsets/ststow2stfire_low.chset.env"' in capsys.readouterr().out
    for rel in ("channelsets/ststow2stfire.chset.env", "channelsets/ststow2stfire_low.chset.env"):
        assert (tmp_path / rel).read_bytes() == (CHANNELSETS.parent / rel).read_bytes(), rel
    for name in [*GRAPHS, "jack-ttes-soldier_low.env", "jack-ttes-soldier_low.jcl"]:
        assert (tmp_path / "posture_graphs" / name).read_bytes() == (POSTURE_GRAPHS / name).read_bytes(), name


def test_build_rejects_unknown_clips_and_figure_sets(tmp_path: Path, capsys):
    assert main(["author", "build", "--only", "no_such_clip", "--out", str(tmp_path), "--no-progress"]) == 2
    assert "no clip matches" in capsys.readouterr().err
    with pytest.raises(ValueError):
        B.build(tmp_path, FIGURES, figure="G3")


def test_di_only_build_reslaves_committed_clips(tmp_path: Path):
    (tmp_path / "channelsets").mkdir()
    shutil.copy(CHANNELSETS / "ststow2stfire.chset.env", tmp_path / "channelsets")
    written = B.build(tmp_path, FIGURES, only="ststow2stfire", figure="DI", progress=False)
    assert tmp_path / "channelsets" / "ststow2stfire.chset.env" not in written
    assert (tmp_path / "channelsets" / "ststow2stfire_low.chset.env").read_bytes() == (
        CHANNELSETS / "ststow2stfire_low.chset.env"
    ).read_bytes()


def test_m16_library_holds_the_m16_by_its_own_grip_and_handguard():
    """An ``_m16_low`` clip binds to DI.fig + M16.fig; the palms are on the M16's grip and handguard, its
    butt where the AK's is in the master clip, its barrel along the AK's line, and it is out of the ground."""
    from authoring.quality import FigureSet, check_clip, play
    from authoring.rifle_swap import lowest_point
    from server.motion.binding import bind_channelset
    from server.motion.cache import load_channelset

    figs = FigureSet.from_dir(FIGURES, ["DI.fig", "M16.fig", "AK_47.fig", "soldier.fig"])
    for name in ("kstow2kfire", "prstow2prfire", "walk_cycle_l"):
        cs = load_channelset(CHANNELSETS / f"{name}_m16_low.chset.env")
        bound = bind_channelset(cs, [figs.figures["DI.fig"], figs.figures["M16.fig"]])
        assert {bf.protofiletype for bf in bound.figures} == {"DI.fig", "M16.fig"}
        assert {c.protofiletype for c in cs.channels} == {"DI.fig", "M16.fig"}  # no AK-47 left in it
        row = check_clip(cs, figs)
        assert (
            row["rifle"] == "M16.fig"
            and row["right_palm_rifle_cm"] <= 1.0
            and row["left_palm_rifle_cm"] <= 1.0
        )
        assert row["rifle_penetration_cm"] <= 1.0
        assert row["rifle_in_body_cm"] <= 1.0
        m16 = play(cs, figs).locations["M16.fig"]
        assert lowest_point(figs, "M16.fig", m16).min() >= -1.0
        # the AK of the DI.fig clip: both slaves are put down on their kneecaps alike (slave_contacts)
        ak = play(load_channelset(CHANNELSETS / f"{name}_low.chset.env"), figs).locations["AK_47.fig"]
        sites = {t: figs.kin[t].site_globals(np.zeros(0)) for t in ("AK_47.fig", "M16.fig")}
        butt = {t: sites[t][figs.kin[t].site_names.index("rifle.butt")] for t in sites}
        if name == "kstow2kfire":  # nothing near the ground: the M16 is the AK's placement, butt on butt
            np.testing.assert_allclose(
                (m16 @ butt["M16.fig"])[:, :3, 3], (ak @ butt["AK_47.fig"])[:, :3, 3], atol=1e-3
            )
            np.testing.assert_allclose(m16[:, :3, :3], ak[:, :3, :3], atol=1e-5)
            fire = m16[-1, :3, :3] @ np.array([0.0, 0.0, -1.0])  # KNEEL_FIRE aims along -Z as the AK does
            np.testing.assert_allclose(fire, ak[-1, :3, :3] @ np.array([0.0, 0.0, -1.0]), atol=1e-5)


def test_the_prone_m16_stays_out_of_the_body():
    from authoring.quality import FigureSet, check_clip
    from server.motion.cache import load_channelset

    figs = FigureSet.from_dir(FIGURES, ["DI.fig", "M16.fig"])
    row = check_clip(load_channelset(CHANNELSETS / "prstow2prfire_m16_low.chset.env"), figs)
    assert row["rifle_in_body_cm"] <= 1.0


def test_m16_graphs_list_only_m16_clips_and_a_build_reproduces_them(tmp_path: Path):
    for kind, fname in B.GRAPH_FILES["M16"].items():
        graph = load_posture_graph(POSTURE_GRAPHS / fname).graph
        assert graph.files and all(f.endswith("_m16_low.chset.env") for f in graph.files), fname
        # the AK graph's clips in the same order, and the same arcs: a clip id means the same clip in both
        ak = load_posture_graph(POSTURE_GRAPHS / B.GRAPH_FILES["DI"][kind]).graph
        assert [f.replace("_m16_low.", "_low.") for f in graph.files] == ak.files
        assert graph.arcs == ak.arcs and graph.postures == ak.postures
    (tmp_path / "channelsets").mkdir()
    shutil.copy(CHANNELSETS / "ststow2stfire.chset.env", tmp_path / "channelsets")
    written = B.build(tmp_path, FIGURES, only="ststow2stfire", figure="M16", progress=False)
    assert {p.name for p in written if p.parent.name == "channelsets"} == {"ststow2stfire_m16_low.chset.env"}
    assert (tmp_path / "channelsets" / "ststow2stfire_m16_low.chset.env").read_bytes() == (
        CHANNELSETS / "ststow2stfire_m16_low.chset.env"
    ).read_bytes()
    for fname in B.GRAPH_FILES["M16"].values():
        assert (tmp_path / "posture_graphs" / fname).read_bytes() == (POSTURE_GRAPHS / fname).read_bytes()
