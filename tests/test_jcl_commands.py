"""The seed's commands (002, 3.4-3.6) driven through JCL text against a real world (synthetic data dir)."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from server.jcl import JclError
from server.startup import ServerWorld, SyntheticDataDir, write_synthetic_data_dir
from server.world.commands import COMMANDS, help_table

DOC = Path(__file__).resolve().parents[1] / "docs" / "JCL.md"


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> SyntheticDataDir:
    """One synthetic data dir with its channelset caches written (a fresh copy per test is fast)."""
    d = write_synthetic_data_dir(tmp_path_factory.mktemp("template"), soldiers=2)
    ServerWorld(d.path).run_startup(d.startup_script)
    return d


def data_dir(template: SyntheticDataDir, tmp_path: Path) -> SyntheticDataDir:
    shutil.copytree(template.path, tmp_path / "data")
    return dataclasses.replace(template, path=tmp_path / "data")


@pytest.fixture
def world(template: SyntheticDataDir, tmp_path: Path) -> tuple[ServerWorld, Clock, list[str]]:
    d = data_dir(template, tmp_path)
    clock = Clock()
    w = ServerWorld(d.path, clock=clock)
    reports: list[str] = []
    w.events.report = lambda caller, text: reports.append(text)
    w.run_startup(d.startup_script)
    w.run_jcl('set_ttes_soldier_throttle(0); set_ttes_clip_recording("yes");')
    return w, clock, reports


def clips_of(w: ServerWorld, reports: list[str], name: str) -> list[tuple[str, bool]]:
    w.run_jcl(f'report_ttes_clips("{name}");')
    return [(c["clip"], c["forward"]) for c in json.loads(reports[-1])["clips"]]


def test_every_command_is_in_the_table_help_and_the_docs(world) -> None:
    w, _, reports = world
    assert w.jcl.commands == sorted(c.name for c in COMMANDS)
    w.run_jcl("help();")
    assert reports[-1] == help_table()
    assert help_table() in DOC.read_text(), "docs/JCL.md: paste server.world.commands.help_table()"
    seed_commands = {
        "write_channelset", "load_channelset", "bind_channelset", "play_bound_channelset",
        "step_bound_channelset", "set_channelset_parameters", "print_channelset_info",
        "reroot_figure_channel",
        "load_posture_graph", "bind_posture_graph", "posture_change", "create_master_slave_pair",
        "slave_parameters", "turn_slave_on", "turn_slave_off", "turn_behavior_constr_off",
        "create_channelset_motion", "open_ttes_sockets", "change_directory", "read_file",
        "create_soldier_state", "set_ttes_report_interval", "set_ttes_heading_offset",
        "set_ttes_soldier_throttle", "start_ttes_socket_simulation", "disable_graphics", "spit",
    }  # fmt: skip
    assert seed_commands <= set(w.jcl.commands)


def test_play_bound_channelset_plays_the_clip_on_the_bound_soldier(world) -> None:
    w, clock, reports = world
    w.run_jcl(
        'bind_channelset("ststow2kstow_low.chset", "ststow2kstow/s0", "Di2_0", "AK_47_0");'
        'play_bound_channelset("ststow2kstow/s0", "forwards", 2.0);'
    )
    m = w.manager
    assert m is not None
    s0, s1 = m.index_of("s0"), m.index_of("s1")
    info = m.soldier_info(s0)
    assert (info["mode"], info["clip"], info["clip_duration"]) == (
        "TRANSITION",
        "soldier_low/ststow2kstow_low",
        2.0,
    )
    assert m.soldier_info(s1)["mode"] == "IDLE"  # only the bound soldier plays
    clock.now = 2.5
    m.tick(clock.now)  # the clip ended in KNEEL_STOWED; the standing request takes the soldier back
    assert clips_of(w, reports, "s0") == [
        ("soldier_low/ststow2kstow_low", True),
        ("soldier_low/ststow2kstow_low", False),
    ]
    w.run_jcl('play_bound_channelset("ststow2kstow/s0", "backwards", -1);')
    assert m.soldier_info(s0)["forward"] is False
    with pytest.raises(JclError, match="forwards"):
        w.run_jcl('play_bound_channelset("ststow2kstow/s0", "sideways", -1);')
    with pytest.raises(JclError, match="no bound channelset"):
        w.run_jcl('play_bound_channelset("nothing/s0", "forwards", -1);')
    w.run_jcl(  # the same file under another name is the library's clip (issue 17: loads share)
        'load_channelset("ststow2kstow_low.chset.env", "same"); bind_channelset("same", "same/s0", "Di2_0");'
    )
    w.run_jcl('play_bound_channelset("same/s0", "forwards", -1);')
    graphs = w.data_dir / "posture_graphs"
    shutil.copy(graphs / "ststow2kstow_low.chset.env", graphs / "copy_low.chset.env")
    w.run_jcl('load_channelset("copy_low.chset.env", "copy"); bind_channelset("copy", "copy/s0", "Di2_0");')
    with pytest.raises(JclError, match="not a clip of the motion library"):
        w.run_jcl('play_bound_channelset("copy/s0", "forwards", -1);')


def test_step_bound_channelset_reports_one_stored_frame_at_a_time(world) -> None:
    w, _, reports = world
    w.run_jcl('bind_channelset("ststow2kstow_low.chset", "k/s0", "Di2_0", "AK_47_0");')
    frames = []
    for _ in range(3):
        w.run_jcl('step_bound_channelset("k/s0");')
        frames.append(json.loads(reports[-1])["frame"])
    assert frames == [1, 2, 3]
    w.run_jcl('step_bound_channelset("k/s0", -10);')
    shown = json.loads(reports[-1])
    assert shown["frame"] == 0
    cs = w.channelsets["ststow2kstow_low.chset"]
    bound = w.store.bound_channelsets["k/s0"]
    np.testing.assert_allclose(shown["poses"]["Di2_0"], bound.sample(0.0).poses["Di2_0"], atol=1e-6)
    w.run_jcl('step_bound_channelset("k/s0", 1000);')
    assert json.loads(reports[-1])["frame"] == cs.nframes - 1
    for huge in ("1e999", "-1e999"):  # inf from the parser: a located error, never an escaping exception
        with pytest.raises(JclError, match="not a number of frames"):
            w.run_jcl(f'step_bound_channelset("k/s0", {huge});')
        with pytest.raises(JclError, match="verbosity"):
            w.run_jcl(f'print_channelset_info("ststow2kstow_low.chset", {huge});')


def test_write_channelset_cuts_a_bound_channelset_into_a_new_file(world) -> None:
    w, _, _ = world
    w.run_jcl(
        'bind_channelset("ststow2kstow_low.chset", "k/s0", "Di2_0", "AK_47_0");'
        'write_channelset("cuts/k_cut.chset.env", "k_cut", 0, 10, 30, 2, "k/s0");'
    )
    path = w.data_dir / "cuts" / "k_cut.chset.env"
    assert path.is_file()
    cut = w.channelsets["k_cut"]
    assert (cut.nframes, cut.fps) == (6, 30.0)
    w.run_jcl(
        'bind_channelset("k_cut", "cut/s0", "Di2_0", "AK_47_0");'
        'load_channelset("cuts/k_cut.chset.env", "again");'
    )
    cut_bound, src_bound = w.store.bound_channelsets["cut/s0"], w.store.bound_channelsets["k/s0"]
    for k in range(6):
        np.testing.assert_allclose(
            cut_bound.sample(k).poses["Di2_0"], src_bound.sample(2 * k).poses["Di2_0"], atol=1e-5
        )
    assert w.channelsets["again"].nframes == 6
    for bad, why in [
        ('"cuts/k_cut.chset.env"', "exists"),
        ('"k.txt"', "must end in"),
        ('"../outside.chset.env"', "outside the data directory"),
    ]:
        with pytest.raises(JclError, match=why):
            w.run_jcl(f'write_channelset({bad}, "x", 0, 10, 30, 2, "k/s0");')
    with pytest.raises(JclError, match="bad frame range"):
        w.run_jcl('write_channelset("y.chset.env", "y", 5, 1, 30, 1, "k/s0");')


def test_reroot_figure_channel_puts_every_frame_on_one_site(world) -> None:
    w, _, _ = world
    fig = w.environment.figures["Di2_0"]
    site = next(f"{seg.name}.{s}" for seg in list(fig.segments.values())[2:] for s in seg.sites)
    before = w.channelsets["walk_cycle_l.chset"]
    w.run_jcl(f'reroot_figure_channel("walk_cycle_l.chset", "Di2_0", "{site}");')
    after = w.channelsets["walk_cycle_l.chset"]
    assert after is not before and after.nframes == before.nframes
    chan = next(c for c in after.figure_channels() if c.protofiletype == "DI.fig")
    assert set(after.roots(chan)) == {site}
    with pytest.raises(JclError, match="no site"):
        w.run_jcl('reroot_figure_channel("walk_cycle_l.chset", "Di2_0", "nowhere.site");')


def test_posture_change_drives_the_soldier_of_the_bound_graph(world) -> None:
    w, clock, reports = world
    w.run_jcl('bind_posture_graph("soldier_low", "s1/ptrans", "Di2_1", "AK_47_1");')
    assert w.store.bound_graphs["s1/ptrans"].graph is w.graphs["soldier_low"].graph
    w.run_jcl('posture_change("s1/ptrans", "PRONE_FIRE");')
    said = json.loads(reports[-1])
    assert said["soldier"] == "s1" and said["path"][-1] == "PRONE_FIRE" and said["goal"] == "PRONE_FIRE"
    w.run_jcl('posture_change("s1/ptrans", "KNEEL_FIRE");')  # mid-transition: re-planned from the arc playing
    said = json.loads(reports[-1])
    assert said["path"][-1] == "KNEEL_FIRE" and said["goal"] == "KNEEL_FIRE"
    w.run_jcl('posture_change("s1/ptrans", "PRONE_FIRE");')
    m = w.manager
    assert m is not None
    clock.now = 60.0
    m.tick(clock.now)
    assert m.soldier_info(m.index_of("s1"))["posture"] == "PRONE_FIRE"  # and it stays there
    assert m.soldier_info(m.index_of("s0"))["posture"] == "STAND_STOWED"
    with pytest.raises(JclError, match="no posture 'FLYING'"):
        w.run_jcl('posture_change("s1/ptrans", "FLYING");')
    with pytest.raises(JclError, match="no bound posture graph"):
        w.run_jcl('posture_change("soldier_low", "KNEEL_FIRE");')


def test_bind_posture_graph_picks_the_figures_the_library_is_bound_to(template, tmp_path: Path) -> None:
    d = data_dir(template, tmp_path)
    plain = ServerWorld(d.path)
    plain.run_startup(d.startup_script)
    assert plain.library is not None and plain.library.sets[0].prototypes[0].name == "Di2_0"
    bound = ServerWorld(d.path)
    bound.run_jcl(
        'read_file("jack-ttes-soldier_low.env"); load_posture_graph("soldier_low.graph", "soldier_low");'
        'bind_posture_graph("soldier_low", "s1/ptrans", "Di2_1", "AK_47_1");'
        'create_soldier_state("s0", "Di2_0", "AK_47_0");'
    )
    assert bound.library is not None
    assert [f.name for f in bound.library.sets[0].prototypes] == ["Di2_1", "AK_47_1"]


def test_settings_commands_replace_the_one_settings_value(world) -> None:
    w, _, _ = world
    m = w.manager
    assert m is not None
    before = m.settings
    w.run_jcl(
        'set_channelset_parameters("yes"); set_ttes_heading_offset(256, 0, 256);'
        "set_ttes_soldier_throttle(0.065);"
        "set_ttes_walk_run_threshold(2.5); set_ttes_blend_time(0.1);"
    )
    after = m.settings
    assert after is not before and w.settings is after
    assert (after.every_frame, after.heading_offsets, after.throttle) == (True, (256.0, 0.0, 256.0), 0.065)
    assert (after.walk_run_threshold, after.blend_time) == (2.5, 0.1)
    with pytest.raises(JclError, match="throttle"):
        w.run_jcl("set_ttes_soldier_throttle(-1);")
    with pytest.raises(JclError, match="walk/run threshold"):
        w.run_jcl("set_ttes_walk_run_threshold(0);")
    assert m.settings is after  # a refused value changes nothing


def test_slaving_and_change_directory_are_refused_with_the_reason(world) -> None:
    w, _, _ = world
    for call in [
        'create_master_slave_pair("soldier", "Di2_0");',
        'slave_parameters("yes","yes","yes","yes",0.50,"yes",0.50,"yes","yes");',
        "turn_slave_on();",
        "turn_slave_off();",
        "turn_behavior_constr_off();",
        "create_channelset_motion();",
    ]:
        with pytest.raises(JclError, match=re.escape("slaving is off-line authoring")):
            w.run_jcl(call)
    with pytest.raises(JclError, match="data directory is fixed"):
        w.run_jcl('change_directory("/tmp");')
    w.run_jcl('open_ttes_sockets("localhost");')  # the 1994 -E line: harmless


def test_spit_writes_the_environment_as_tips(world) -> None:
    w, _, _ = world
    w.run_jcl('spit("env.tips");')
    text = (w.data_dir / "env.tips").read_text()
    assert text.startswith("4 figures\nFIGURE #0\nDi2_0\n")
    with pytest.raises(JclError, match="exists"):
        w.run_jcl('spit("env.tips");')


def test_over_the_wire_a_report_is_a_status_and_a_refusal_a_jcl_error() -> None:
    from test_server_support import make_server

    from protocol.connection import CLIENT, NEED_DATA, PAUSED, Connection
    from protocol.errors import ErrorCode
    from protocol.events import Error, Hello, Jcl, Status
    from server.session import Session

    server = make_server()
    server.start_world()
    session = Session(server.world, server.board_ref, server.config, "jcl")
    client = Connection(CLIENT)
    got: list[object] = []
    for event in (Hello("jcl", "controller"), Jcl("help();", 1), Jcl("turn_slave_on();", 2)):
        session.feed(client.send(event))
        client.receive_data(session.take_output())
        while (ev := client.next_event()) is not NEED_DATA and ev is not PAUSED:
            got.append(ev)
    assert any(isinstance(e, Status) and e.text == help_table() for e in got)
    (err,) = [e for e in got if isinstance(e, Error)]
    assert (err.code, err.ref) == (int(ErrorCode.JCL_ERROR), 2)
    assert "slaving is off-line authoring" in err.message


def test_print_channelset_info_and_load_posture_graph(world) -> None:
    w, _, reports = world
    w.run_jcl('load_posture_graph("soldier_crawl.graph", "crawl_copy");')
    w.run_jcl('print_channelset_info("crawl_start.chset");')
    assert "crawl_copy" in w.graphs and "crawl_start" in reports[-1]
    with pytest.raises(JclError, match="no channelset 'nothing'"):
        w.run_jcl('print_channelset_info("nothing");')


_WORDS = [
    "k/s0", "s0", "s1", "Di2_0", "AK_47_0", "soldier_low", "s1/ptrans", "PRONE_FIRE", "DEAD", "forwards",
    "backwards", "yes", "no", "ststow2kstow_low.chset", "walk_cycle_l.chset", "x.chset.env", "y.tips",
    "../up.tips", "", "s0.proximal", "nothing",
]  # fmt: skip
_NUMBERS = [0.0, 1.0, -1.0, 2.5, 1e999, -1e999, 1e9, 0.5, 3.0]
# a world per example costs ~0.3 s: a short run in `make test`, the profile's count in `make fuzz`
_FUZZING = os.environ.get("HYPOTHESIS_PROFILE", "ci") != "ci"
_SHORT_UNLESS_FUZZING = settings() if _FUZZING else settings(max_examples=25)


@pytest.mark.fuzz
@_SHORT_UNLESS_FUZZING
@given(st.data())
def test_fuzz_every_command_with_plausible_arguments_only_raises_jcl_error(
    template: SyntheticDataDir, tmp_path_factory: pytest.TempPathFactory, data: st.DataObject
) -> None:
    """A client's JCL never gets anything but a JCL error (ERROR 105) out of a command: no exception that
    would take its session down, whatever the arguments."""
    d = data_dir(template, tmp_path_factory.mktemp("fuzz"))
    clock = Clock()
    w = ServerWorld(d.path, clock=clock)
    w.run_startup(d.startup_script)
    w.run_jcl('bind_channelset("ststow2kstow_low.chset", "k/s0", "Di2_0", "AK_47_0");')
    w.run_jcl('bind_posture_graph("soldier_low", "s1/ptrans", "Di2_1", "AK_47_1");')
    arg = st.one_of(st.sampled_from(_WORDS), st.sampled_from(_NUMBERS))
    for _ in range(data.draw(st.integers(1, 6))):
        name = data.draw(st.sampled_from([c.name for c in COMMANDS if c.name != "read_file"]))
        args = data.draw(st.lists(arg, max_size=8))
        text = f"{name}({', '.join(json.dumps(a) if isinstance(a, str) else repr(a) for a in args)});"
        clock.now += data.draw(st.sampled_from([0.0, 0.1, 5.0]))
        with contextlib.suppress(JclError):
            w.run_jcl(text.replace("inf", "1e999"))
        if w.manager is not None:
            w.manager.tick(clock.now)
