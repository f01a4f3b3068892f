"""Channelsets: text files through the Peabody parser, the writer, caches, binding, recording, re-rooting."""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from peabody import quaternion
from peabody.fk import FigureKinematics
from peabody.loader import load_text
from server.motion.binding import bind_channelset, pose_layout
from server.motion.cache import cache_dir, cache_path, load_channelset, load_npz, save_npz
from server.motion.channelset import JointTrack, channelsets_close, make_channelset
from server.motion.channelset_file import (
    format_channelset,
    parse_channelsets,
    read_channelset,
)
from server.motion.errors import BindingError, ChannelsetError
from server.motion.info import channelset_info, print_channelset_info
from server.motion.recording import Recording, reroot_figure_channel, write_channelset
from server.motion.synthetic import make_figure, make_soldier, synthetic_channelset, toy_rifle, toy_soldier
from ttes.cli import main

DATA = Path(__file__).resolve().parent / "data" / "motion"

FIGURE6 = """
channelset crawl2prstow.chset {
  size = 2;
  fps = 60;
  count = 2;
  sharedchannel soldier { /* figure position */
    type = "sharedfigure";
    protofiletype = "soldier_cam.fig";
    object = "soldier";
    frame[0] = ("lower_torso.proximal", trans(31.68cm,43.53cm,-31.05cm));
    frame[1] = ("lower_torso.proximal", trans(31.68cm,42.77cm,-31.05cm));
    frame[2] = ("lower_torso.proximal", xyz(0deg,90deg,0deg) * trans(11.52cm,4.15cm,-26.49cm));
  }
  sharedchannel right.toes { /* joint angles */
    type = "sharedjoint";
    protofiletype = "soldier_cam.fig";
    object = "right.toes"; /* R(y) */
    frame[0] = (0);
    frame[1] = (10deg);
    frame[2] = (0.5);
  }
}
"""


# --- reading -----------------------------------------------------------------------------------------------


def test_figure6_channelset_reads_into_arrays() -> None:
    (cs,) = parse_channelsets(FIGURE6, "fig6.chset.env")
    assert (cs.name, cs.size, cs.nframes, cs.fps, cs.count) == ("crawl2prstow.chset", 2, 3, 60.0, 2)
    assert cs.duration == pytest.approx(2 / 60)
    fig, toes = cs.channels
    assert (fig.type, fig.protofiletype, fig.object, fig.column) == (
        "sharedfigure",
        "soldier_cam.fig",
        "soldier",
        0,
    )
    assert (toes.name, toes.type, toes.object, toes.width) == ("right.toes", "sharedjoint", "right.toes", 1)
    assert cs.joint_data.dtype == np.float32 and cs.joint_data.shape == (3, 1)
    np.testing.assert_allclose(cs.angles(toes)[:, 0], [0.0, math.radians(10), 0.5], rtol=1e-6)
    np.testing.assert_allclose(
        cs.fig_pos[:, 0], [[31.68, 43.53, -31.05], [31.68, 42.77, -31.05], [11.52, 4.15, -26.49]]
    )
    assert cs.roots(fig) == ["lower_torso.proximal"] * 3
    np.testing.assert_allclose(cs.fig_quat[0, 0], [1, 0, 0, 0])
    # xyz(0, 90deg, 0) * trans(p): the frame turned 90 degrees about y, placed at p
    t = cs.transforms(fig)[2]
    np.testing.assert_allclose(t[:3, 3], [11.52, 4.15, -26.49], rtol=1e-6)
    np.testing.assert_allclose(t[:3, :3] @ [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], atol=1e-6)


def test_size_may_count_frames_on_read_but_is_written_as_intervals() -> None:
    text = FIGURE6.replace("size = 2;", "size = 3;")
    (cs,) = parse_channelsets(text, "x")
    assert cs.nframes == 3 and cs.size == 2
    assert "  size = 2;\n" in format_channelset(cs)


def test_seed_channelsets_read(tmp_path: Path) -> None:
    cs = read_channelset(DATA / "crawl2prstow_low.chset.env")
    assert cs.name == "crawl2prstow_low.chset" and cs.fps == 10 and cs.nframes == 9
    assert [c.name for c in cs.channels] == ["soldier", "rifle", "waist", "neck", "right.knee", "left_knee"]


def test_channelsets_load_through_the_peabody_environment_loader() -> None:
    env = load_text(FIGURE6, filename="fig6.env")
    cs = env.extensions["channelset"]["crawl2prstow.chset"]
    assert cs.nframes == 3  # type: ignore[attr-defined]


def located(text: str) -> ChannelsetError:
    with pytest.raises(ChannelsetError) as info:
        parse_channelsets(text, "bad.chset.env")
    err = info.value
    assert err.file == "bad.chset.env" and isinstance(err.line, int)
    return err


def line_of(text: str, needle: str) -> int:
    return text[: text.index(needle)].count("\n") + 1


@pytest.mark.parametrize(
    ("old", "new", "marker"),
    [
        ("size = 2;", "size = 7;", "size = 7"),
        ("count = 2;", "count = 3;", "count = 3"),
        ('type = "sharedjoint";', 'type = "sharedthing";', "sharedchannel right.toes"),
        ("frame[1] = (10deg);", "frame[1] = (10deg, 3);", "frame[1] = (10deg, 3)"),
        ("frame[1] = (10deg);", "frame[0] = (10deg);", "frame[0] = (10deg)"),
        ("frame[1] = (10deg);", "", "sharedchannel right.toes"),
        ('object = "soldier";', "colour = 3;", "colour = 3"),
        ("trans(31.68cm,42.77cm,-31.05cm)", "scale(2) * trans(1,2,3)", "scale(2)"),
        ("fps = 60;", "fps = 0;", "0;"),
        ("fps = 60;", "", "channelset crawl2prstow"),
    ],
)
def test_bad_channelsets_give_located_errors(old: str, new: str, marker: str) -> None:
    text = FIGURE6.replace(old, new)
    assert text != FIGURE6
    err = located(text)
    assert err.line == line_of(text, marker), str(err)


def test_different_frame_counts_and_foreign_blocks_are_errors() -> None:
    text = FIGURE6.replace("    frame[2] = (0.5);\n", "")
    located(text)
    with pytest.raises(ChannelsetError):
        parse_channelsets("figure f { }\n", "x")


# --- writing -----------------------------------------------------------------------------------------------


def test_text_round_trip_of_a_synthetic_clip() -> None:
    soldier, rifle = make_soldier(ndof=20), toy_rifle()
    cs = synthetic_channelset("walk/left step", [soldier, rifle], nframes=31, fps=30)
    text = format_channelset(cs)
    assert text.startswith('channelset "walk/left step" {')
    (back,) = parse_channelsets(text, "x")
    assert channelsets_close(cs, back, atol=1e-6)
    np.testing.assert_array_equal(back.joint_data, cs.joint_data)  # float32 shortest reprs: exact
    np.testing.assert_array_equal(back.fig_pos, cs.fig_pos)
    (again,) = parse_channelsets(format_channelset(back), "x")
    assert channelsets_close(back, again, atol=1e-6)


@pytest.mark.parametrize("path", sorted(DATA.glob("*.chset.env")), ids=lambda p: p.name)
def test_data_files_round_trip(path: Path) -> None:
    cs = read_channelset(path)
    (back,) = parse_channelsets(format_channelset(cs), str(path))
    assert channelsets_close(cs, back, atol=1e-6)


def test_writer_output_uses_the_parser_fast_paths() -> None:
    import peabody.language as lang

    cs = synthetic_channelset("c", [make_soldier(ndof=6)], nframes=5)
    text = format_channelset(cs)
    fast = parse_channelsets(text, "x")[0]
    lang.FAST_PATHS = False
    try:
        slow = parse_channelsets(text, "x")[0]
    finally:
        lang.FAST_PATHS = True
    assert channelsets_close(fast, slow, atol=0.0)
    np.testing.assert_array_equal(fast.fig_quat, slow.fig_quat)


# --- cache -------------------------------------------------------------------------------------------------


def test_cache_is_written_used_and_rebuilt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    src = tmp_path / "c.chset.env"
    shutil.copy(DATA / "ststow2crawl_low.chset.env", src)
    assert cache_path(src).parent == cache_dir() and cache_path(src).name.startswith("c.chset-")
    first = load_channelset(src)
    assert cache_path(src).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.chset.env"]  # nothing beside the data

    import server.motion.channelset_file as cf

    def no_parsing(path: object) -> None:
        raise AssertionError("the fresh cache should have been used")

    monkeypatch.setattr(cf, "read_channelset", no_parsing)
    cached = load_channelset(src)
    assert channelsets_close(first, cached, atol=0.0)
    monkeypatch.undo()

    # newer text (different content) -> parsed again and the cache rewritten
    text = src.read_text().replace("fps = 10;", "fps = 20;")
    src.write_text(text)
    st = src.stat()
    os.utime(src, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert load_channelset(src).fps == 20.0
    assert load_npz(cache_path(src), src.stat()).fps == 20.0  # type: ignore[union-attr]

    # an unreadable cache is rebuilt
    cache_path(src).write_bytes(b"not a zip file")
    assert load_npz(cache_path(src)) is None
    assert load_channelset(src).fps == 20.0
    assert load_npz(cache_path(src), src.stat()) is not None


def test_cache_round_trip_is_exact(tmp_path: Path) -> None:
    cs = synthetic_channelset("c", [make_soldier(ndof=9), toy_rifle()], nframes=12)
    save_npz(cs, tmp_path / "c.npz")
    back = load_npz(tmp_path / "c.npz")
    assert back is not None and channelsets_close(cs, back, atol=0.0)
    np.testing.assert_array_equal(back.fig_quat, cs.fig_quat)
    assert back.channels == cs.channels and back.root_names == cs.root_names


# --- binding -----------------------------------------------------------------------------------------------


def test_binding_maps_channels_onto_pose_vectors_and_shares_the_data() -> None:
    cs = read_channelset(DATA / "crawl2prstow_low.chset.env")
    s3, g3 = toy_soldier("soldier3"), toy_rifle("gun3")
    b = bind_channelset(cs, [s3, g3])
    assert b.name == "crawl2prstow_low.chset/soldier3" and b.unbound == ()
    sol = b.figure("soldier3")
    layout = pose_layout(s3)
    assert sol.dst.tolist() == [*range(layout["waist"].start, layout["waist"].stop), 3, 4, 5, 6]
    assert b.figure("gun3").figure_channel == cs.channel("rifle").column
    assert b.channelset.joint_data is cs.joint_data
    assert 0 < b.nbytes < cs.nbytes
    sample = b.sample(cs.nframes - 1)
    np.testing.assert_allclose(sample.poses["soldier3"], cs.joint_data[-1], atol=0)
    # two soldiers bound to one channelset each hold only their maps
    b2 = bind_channelset(cs, [toy_soldier("soldier4"), toy_rifle("gun4")], "crawl/soldier4")
    assert b2.channelset is b.channelset and b2.name == "crawl/soldier4"


def test_binding_reports_missing_joints_and_rejects_mismatches() -> None:
    cs = read_channelset(DATA / "crawl2prstow_low.chset.env")
    partial = make_figure("s", "toy_soldier.fig", [("waist", 3), ("neck", 2)])
    b = bind_channelset(cs, [partial])
    assert set(b.unbound) == {"right.knee", "left_knee", "rifle"}
    with pytest.raises(BindingError):
        bind_channelset(cs, [partial], strict=True)
    wrong = make_figure("s", "toy_soldier.fig", [("waist", 2)])
    with pytest.raises(BindingError, match="DOFs"):
        bind_channelset(cs, [wrong])
    with pytest.raises(BindingError, match="none of the figures"):
        bind_channelset(cs, [make_figure("x", "other.fig", [("waist", 3)])])


def test_print_channelset_info_reports_bytes_per_channelset_and_binding(
    capsys: pytest.CaptureFixture[str],
) -> None:
    cs = read_channelset(DATA / "ststow2crawl_low.chset.env")
    b = bind_channelset(cs, [toy_soldier("soldier3"), toy_rifle("gun3")])
    print_channelset_info(cs, [b], verbosity=2)
    out = capsys.readouterr().out
    assert (
        f"{cs.nbytes} bytes" in out and f"bound channelset {b.name} (soldier3, gun3): {b.nbytes} bytes" in out
    )
    assert "right.knee" in out and "rad" in out
    info = channelset_info(cs)
    assert info["size"] == 20 and info["duration_s"] == pytest.approx(2.0) and info["count"] == 6


def test_cli_channelset_info_json(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    import json

    src = tmp_path / "x.chset.env"
    shutil.copy(DATA / "crawl2prstow_low.chset.env", src)
    assert main(["channelset", "info", str(src), "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert {k: obj[k] for k in ("name", "size", "fps", "count")} == {
        "name": "crawl2prstow_low.chset",
        "size": 8,
        "fps": 10.0,
        "count": 6,
    }
    assert obj["duration_s"] == pytest.approx(0.8) and obj["bytes"] > 0
    assert obj["channels"][4] == {
        "name": "right.knee",
        "type": "sharedjoint",
        "object": "right_knee",
        "protofiletype": "toy_soldier.fig",
    }
    bad = tmp_path / "bad.chset.env"
    bad.write_text("channelset x { fps = 1; }\n")
    assert main(["channelset", "info", str(bad)]) == 1
    assert "bad.chset.env:1" in capsys.readouterr().err


# --- recording and re-rooting ------------------------------------------------------------------------------


def test_write_channelset_pulls_begin_to_end_every_stride(tmp_path: Path) -> None:
    soldier, rifle = toy_soldier(), toy_rifle()
    rec = Recording([soldier, rifle])
    for k in range(300):
        soldier.joints["waist"].dofs[0].value = k * 0.001
        soldier.joints["left_knee"].dofs[0].value = -k * 0.002
        soldier.location = np.eye(4)
        soldier.location[:3, 3] = (k, 0.0, 0.0)
        rec.capture()
    assert rec.nframes == 300
    cs = write_channelset(tmp_path / "rec.chset.env", "rec", rec, begin=100, end=220, fps=30, stride=2)
    assert cs.nframes == 61 and cs.size == 60 and cs.duration == pytest.approx(2.0)
    waist = cs.angles(cs.channel("waist"))[:, 0]
    np.testing.assert_allclose(waist, np.arange(100, 221, 2) * 0.001, rtol=1e-6)
    np.testing.assert_allclose(cs.fig_pos[:, cs.channel("soldier").column, 0], np.arange(100, 221, 2))
    assert [c.name for c in cs.channels][:2] == ["soldier", "waist"]
    assert cs.channel("rifle").protofiletype == "toy_rifle.fig"
    back = read_channelset(tmp_path / "rec.chset.env")
    assert channelsets_close(cs, back, atol=1e-6)
    only = write_channelset(None, "r", rec, 0, 10, 30, 5, figures=["rifle"])
    assert [c.name for c in only.channels] == ["rifle"] and only.nframes == 3
    with pytest.raises(ChannelsetError):
        write_channelset(None, "r", rec, 250, 320, 30, 1)


def test_reroot_figure_channel_gives_every_frame_the_new_root() -> None:
    fig = make_figure("f", "chain.fig", [("a", 3), ("b", 2), ("c", 1)])
    kin = FigureKinematics(fig)
    cs = synthetic_channelset("walk", [fig], nframes=9, seed=4)
    # the recording's root hops between sites, as in the walking data
    tracks = cs.tracks()
    tracks[-1].roots = ["s0.proximal", "s0.proximal", "s3.distal"] * 3  # type: ignore[union-attr]
    hopping = make_channelset("walk", cs.fps, tracks)
    new = reroot_figure_channel(hopping, fig, "s2.distal", kin)
    chan = new.channel("f")
    assert new.roots(chan) == ["s2.distal"] * 9
    old_t = hopping.transforms(hopping.channel("f"))
    new_t = new.transforms(chan)
    poses = hopping.joint_data.astype(np.float64)  # every DOF is driven, in pose-vector order
    for k in range(9):
        root = hopping.roots(hopping.channel("f"))[k]
        g = kin.site_globals(poses[k])
        names = kin.site_names
        expect = old_t[k] @ np.linalg.inv(g[names.index(root)]) @ g[names.index("s2.distal")]
        np.testing.assert_allclose(new_t[k], expect, atol=1e-4)
    np.testing.assert_array_equal(new.joint_data, hopping.joint_data)
    with pytest.raises(ChannelsetError):
        reroot_figure_channel(hopping, fig, "s9.nowhere", kin)


def test_make_channelset_validates() -> None:
    with pytest.raises(ChannelsetError):
        make_channelset("x", 30, [])
    with pytest.raises(ChannelsetError):
        make_channelset(
            "x",
            30,
            [JointTrack("a", "f", "a", np.zeros((3, 1))), JointTrack("b", "f", "b", np.zeros((4, 1)))],
        )
    with pytest.raises(ChannelsetError):
        make_channelset("x", 30, [JointTrack("a", "f", "a", np.full((3, 1), np.nan))])
    q = quaternion.from_matrix(np.eye(4))
    np.testing.assert_allclose(q, [1, 0, 0, 0])


def test_pose_layout_is_the_project_wide_fk_layout() -> None:
    fig = make_soldier(ndof=17)
    assert pose_layout(fig) == FigureKinematics(fig).dof_slices


def test_environment_with_channelsets_writes_back() -> None:
    from peabody.writer import format_environment

    env = load_text(FIGURE6, filename="fig6.env")
    text = format_environment(env)
    again = load_text(text, filename="again.env")
    a = env.extensions["channelset"]["crawl2prstow.chset"]
    b = again.extensions["channelset"]["crawl2prstow.chset"]
    assert channelsets_close(a, b, atol=1e-6)  # type: ignore[arg-type]


def test_a_library_of_forty_clips_loads_from_cache(tmp_path: Path) -> None:
    soldier, rifle = make_soldier(ndof=12), toy_rifle()
    paths = []
    for i in range(40):
        cs = synthetic_channelset(f"clip{i}", [soldier, rifle], nframes=6, seed=i)
        p = tmp_path / f"clip{i}.chset.env"
        p.write_text(format_channelset(cs))
        paths.append(p)
    first = [load_channelset(p) for p in paths]
    assert all(cache_path(p).is_file() for p in paths)
    second = [load_npz(cache_path(p), p.stat()) for p in paths]
    assert all(
        s is not None and channelsets_close(f, s, atol=0.0) for f, s in zip(first, second, strict=True)
    )


FIGURES = Path(__file__).resolve().parents[1] / "figures"


@pytest.mark.skipif(not (FIGURES / "DI.fig").is_file(), reason="shipped DI.fig not present")
def test_record_bind_sample_and_reroot_on_the_shipped_di_figure(tmp_path: Path) -> None:
    from peabody.loader import read_figure
    from server.motion.sampling import ClipLibrary

    di = read_figure(FIGURES / "DI.fig", "Di2_0", load_psurfs=False)
    gun = read_figure(FIGURES / "AK_47.fig", "AK_47_0", load_psurfs=False)
    kin = FigureKinematics(di)
    rec = Recording([di, gun])
    rng = np.random.default_rng(0)
    for _ in range(12):
        kin.set_pose(np.clip(rng.normal(0.0, 0.2, kin.ndof), kin.lower, kin.upper))
        rec.capture()
    cs = write_channelset(tmp_path / "di.chset.env", "di_test", rec, 0, 11, 30)
    back = read_channelset(tmp_path / "di.chset.env")
    assert channelsets_close(cs, back, atol=1e-6)
    b = bind_channelset(back, [di, gun])
    assert b.unbound == () and b.figure("Di2_0").dst.tolist() == list(range(kin.ndof))
    lib = ClipLibrary([di, gun])
    lib.add(back)
    out = lib.sample(np.zeros(3, int), np.zeros(3), np.ones(3), -np.ones(3), 11 / 30)
    np.testing.assert_allclose(out.joints[:, : kin.ndof], np.tile(back.joint_data[-1], (3, 1)), atol=1e-6)
    site = kin.site_names[-1]
    rerooted = reroot_figure_channel(back, di, site, kin)
    assert set(rerooted.roots(rerooted.channel("Di2_0"))) == {site}


# --- optional fields: release_frame and end_offset ----------------------------------------------------------


def test_release_frame_and_end_offset_round_trip_through_text_and_cache(tmp_path: Path) -> None:
    import dataclasses

    cs = synthetic_channelset("turn", [make_soldier(ndof=6), toy_rifle()], nframes=12)
    cs = dataclasses.replace(cs, release_frame=7, end_offset=(-40.0, 12.5, 90.0))
    text = format_channelset(cs)
    assert "release_frame = 7;" in text and "end_offset = (-40, 12.5, 90);" in text
    (back,) = parse_channelsets(text, "x")
    assert back.release_frame == 7 and back.end_offset == (-40.0, 12.5, 90.0)
    save_npz(back, tmp_path / "c.npz")
    cached = load_npz(tmp_path / "c.npz")
    assert cached is not None and cached.release_frame == 7 and cached.end_offset == (-40.0, 12.5, 90.0)
    plain = synthetic_channelset("plain", [make_soldier(ndof=6)], nframes=4)
    save_npz(plain, tmp_path / "p.npz")
    again = load_npz(tmp_path / "p.npz")
    assert again is not None and again.release_frame is None and again.end_offset is None


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("release_frame", "12", r"release_frame = 12 but the frames are 0\.\.2"),
        ("release_frame", "1.5", "release_frame must be a non-negative integer"),
        ("end_offset", "(1, 2)", "expected 3 numbers"),
    ],
)
def test_bad_optional_fields_are_located_errors(field: str, value: str, message: str) -> None:
    text = FIGURE6.replace("  count = 2;", f"  count = 2;\n  {field} = {value};")
    with pytest.raises(ChannelsetError, match=message) as info:
        parse_channelsets(text, "bad.chset.env")
    assert "bad.chset.env" in str(info.value)


def test_release_frame_out_of_range_is_refused_by_the_channelset() -> None:
    import dataclasses

    cs = synthetic_channelset("c", [make_soldier(ndof=6)], nframes=4)
    with pytest.raises(ChannelsetError, match=r"release_frame must be a frame 0\.\.3"):
        dataclasses.replace(cs, release_frame=4)
    with pytest.raises(ChannelsetError, match="end_offset must be three finite numbers"):
        dataclasses.replace(cs, end_offset=(0.0, math.nan, 0.0))
