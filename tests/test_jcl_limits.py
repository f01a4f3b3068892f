"""JCL that cannot hurt the service (issue 17): repeated loads share, tables are bounded, caches stay out of
the data directory."""

from __future__ import annotations

import dataclasses
import os
import shutil
from pathlib import Path

import pytest

from server.jcl import JclError
from server.startup import ServerWorld, SyntheticDataDir, write_synthetic_data_dir


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> SyntheticDataDir:
    return write_synthetic_data_dir(tmp_path_factory.mktemp("template"), soldiers=1)


@pytest.fixture
def data(template: SyntheticDataDir, tmp_path: Path) -> SyntheticDataDir:
    shutil.copytree(template.path, tmp_path / "data")
    return dataclasses.replace(template, path=tmp_path / "data")


def files_of(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*"))


def test_a_graph_loaded_under_many_names_is_shared(data: SyntheticDataDir) -> None:
    w = ServerWorld(data.path)
    w.run_startup(data.startup_script)
    first = w.graphs["soldier_low"]
    n_channelsets = len({id(c) for c in w.channelsets.values()})
    w.run_jcl("".join(f'load_posture_graph("soldier_low.graph", "copy{i}");' for i in range(50)))
    for i in range(50):
        g = w.graphs[f"copy{i}"]
        assert g.name == f"copy{i}"
        assert g.graph is first.graph
        assert all(a is b for a, b in zip(g.channelsets, first.channelsets, strict=True))
    assert len({id(c) for c in w.channelsets.values()}) == n_channelsets  # no new channelset objects


def test_a_channelset_loaded_under_many_names_is_shared(data: SyntheticDataDir) -> None:
    w = ServerWorld(data.path)
    w.run_jcl("".join(f'load_channelset("walk2run.chset.env", "w{i}");' for i in range(20)))
    assert len({id(w.channelsets[f"w{i}"]) for i in range(20)}) == 1
    w.run_jcl('load_posture_graph("soldier_loco.graph");')  # the graph's own walk2run is the same object
    assert w.channelsets["walk2run.chset"] is w.channelsets["w0"]


def test_a_changed_file_is_read_again(data: SyntheticDataDir) -> None:
    w = ServerWorld(data.path)
    w.run_jcl('load_channelset("walk2run.chset.env", "a");')
    path = data.path / "posture_graphs" / "walk2run.chset.env"
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    w.run_jcl('load_channelset("walk2run.chset.env", "b");')
    assert w.channelsets["a"] is not w.channelsets["b"]


def test_loaded_tables_are_bounded(data: SyntheticDataDir) -> None:
    w = ServerWorld(data.path)
    w.store.max_graphs = 3
    w.run_jcl("".join(f'load_posture_graph("soldier_low.graph", "g{i}");' for i in range(3)))
    with pytest.raises(JclError, match="too many posture graphs: 3 loaded, the limit is 3"):
        w.run_jcl('load_posture_graph("soldier_low.graph", "g3");')
    w.run_jcl('load_posture_graph("soldier_low.graph", "g0");')  # reloading a name is not a new one
    w.store.max_graphs = 10
    w.store.max_channelsets = len(w.channelsets) + 1
    w.run_jcl('load_channelset("walk2run.chset.env", "c0");')
    with pytest.raises(JclError, match="too many channelsets"):
        w.run_jcl('load_channelset("walk2run.chset.env", "c1");')
    with pytest.raises(JclError, match="too many channelsets"):  # a graph whose channelsets do not fit
        w.run_jcl('load_posture_graph("soldier_crawl.graph");')
    assert "soldier_crawl" not in w.graphs


def test_loads_write_nothing_into_the_data_directory(
    data: SyntheticDataDir, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("TTES_CACHE_DIR", str(tmp_path / "cache"))
    before = files_of(data.path)
    w = ServerWorld(data.path)
    w.run_startup(data.startup_script)
    w.run_jcl('load_channelset("walk2run.chset.env", "x");')
    assert files_of(data.path) == before
    assert len(list((tmp_path / "cache").glob("*.npz"))) > 10  # the caches went to the cache directory
    configured = ServerWorld(data.path, cache_dir=tmp_path / "mine")
    configured.run_startup(data.startup_script)
    assert len(list((tmp_path / "mine").glob("*.npz"))) > 10
    assert files_of(data.path) == before


def test_only_frames_that_may_load_files_go_to_a_worker_thread() -> None:
    """A frame of settings or soldier commands runs at once on the loop: in a thread it let virtual time
    run under autojump (and real ticks pass) before a throttle change took effect; loads still go there."""
    from server.world.commands import needs_worker

    assert not needs_worker("set_ttes_soldier_throttle(0.2);")
    assert not needs_worker('set_soldier_state("s0", "PRONE_STOWED"); set_ttes_report_interval(2);')
    assert needs_worker('load_channelset("walk.chset.env", "DI.fig");')
    assert needs_worker('load_posture_graph("soldier_low.graph");')
    assert needs_worker('read_file("jack-ttes-soldier_low.jcl");')
    assert not needs_worker("unload_channelsets_x();")  # a word, not a prefix
    # a 1994 client's start-up script, already run by the server, is answered as done: no thread (in one,
    # autojump ran 20 s of virtual time past test_dis_survive's waits while the gateway's creates queued)
    done = {"jack-ttes-soldier_low.jcl"}.__contains__
    assert not needs_worker('read_file("jack-ttes-soldier_low.jcl");', done)
    assert needs_worker('read_file("other.jcl");', done)
    assert needs_worker("read_file(name);", done)  # not a plain string: it may load
