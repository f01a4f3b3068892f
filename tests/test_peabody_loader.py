"""Reading and writing figure and environment files: counts, meaning, errors, extensions, round trips."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from peabody import values as V
from peabody.fk import FigureKinematics
from peabody.language import Block, PeabodyError
from peabody.loader import (
    LoadContext,
    load_text,
    read_environment,
    read_figure,
    register_block,
    unregister_block,
)
from peabody.model import Environment
from peabody.writer import (
    environment_differences,
    figure_differences,
    format_environment,
    format_figure,
    write_environment,
    write_figure,
)

DATA = Path(__file__).parent / "data" / "peabody"
FIGURES = Path(__file__).resolve().parents[1] / "figures"


def test_read_figure_counts_and_fields() -> None:
    fig = read_figure(DATA / "arm.fig")
    assert fig.name == "arm" and fig.filename == "arm.fig" and fig.source == str((DATA / "arm.fig").resolve())
    assert list(fig.segments) == ["base", "upper", "lower"]
    assert list(fig.joints) == ["shoulder", "elbow"]
    assert fig.dof_count == 2 and len(fig.sites()) == 6
    assert fig.root is fig.site("base.bottom")
    elbow = fig.joints["elbow"]
    assert elbow.site1 is fig.site("upper.distal") and elbow.site2 is fig.site("lower.proximal")
    (dof,) = elbow.dofs
    assert dof.kind == "R" and np.allclose(dof.axis, (0, 0, 1))
    assert (dof.lower, dof.upper, dof.value) == pytest.approx((0, math.radians(150), math.radians(30)))
    upper = fig.segments["upper"]
    assert upper.psurf_file == "cube.pss" and np.allclose(upper.psurf_transform, np.diag([4, 30, 4, 1]))
    assert upper.psurf is not None and upper.psurf.polygon_count == 6
    assert np.allclose(upper.psurf.nodes.max(axis=0), (4, 30, 4))  # the scale is applied on reading
    assert np.allclose(fig.site("lower.distal").location, V.translation(2, 20, 2) @ V.rot_z(math.pi / 2))


def test_read_figure_under_a_new_name_and_without_psurfs() -> None:
    fig = read_figure(DATA / "rifle.fig", name="AK_47_0", load_psurfs=False)
    assert fig.name == "AK_47_0" and fig.filename == "rifle.fig"
    gun = fig.segments["gun"]
    assert gun.psurf is None and gun.psurf_file == "cube.pss"
    assert gun.attributes == {"mass": 3.5, "color": "olive"}
    assert fig.root is fig.site("gun.grip")


def test_environment_file() -> None:
    env = read_environment(DATA / "scene.env")
    assert list(env.figures) == ["arm_0", "arm_1", "rifle_0", "marker"]
    arm0, arm1, rifle, marker = env.figures.values()
    assert arm0.filename == arm1.filename == "arm.fig" and arm0 is not arm1
    assert arm0.joints["shoulder"].dofs[0].value == pytest.approx(math.radians(10))  # `joint arm_0.shoulder`
    assert arm1.joints["elbow"].dofs[0].value == pytest.approx(math.radians(45))  # inside the figure block
    assert arm0.joints["elbow"].dofs[0].value == pytest.approx(math.radians(30))  # the file's default
    assert np.allclose(arm0.location, V.translation(0, 0, 50))
    assert np.allclose(arm1.location, V.translation(200, 0, 0) @ V.rot_y(math.pi / 2))
    # the two instances share psurf geometry, loaded once
    assert arm0.segments["upper"].psurf is arm1.segments["upper"].psurf
    # connect: the rifle's grip now sits on arm_0's hand
    hand = FigureKinematics(arm0).site_global("lower.distal")
    assert rifle.root is rifle.site("gun.grip") and np.allclose(rifle.location, hand)
    # inline figure with a protofiletype, placed on a world site
    assert marker.filename == "marker.fig" and marker.source is None
    assert np.allclose(env.world.sites["dock"].location, V.translation(100, 0, 0))
    assert np.allclose(FigureKinematics(marker).site_global("dot.centre"), V.translation(100, 0, 0))


def test_reopening_a_figure_and_rerooting_keeps_it_in_place() -> None:
    env = read_environment(DATA / "scene.env")
    hand = FigureKinematics(env.figures["arm_0"]).site_global("lower.distal")
    load_text("figure arm_0 { root = lower.distal; }", env)
    arm0 = env.figures["arm_0"]
    assert arm0.root is arm0.site("lower.distal") and np.allclose(arm0.location, hand)
    load_text("figure arm_0 { root = base.bottom; location = trans(1, 2, 3); }", env)
    assert np.allclose(arm0.location, V.translation(1, 2, 3))


def test_reading_the_same_environment_twice_reinitialises() -> None:
    text = "figure c { segment s { site a->location = trans(1, 0, 0); } }"
    env = load_text(text)
    env.figures["c"].segments["s"].sites["a"].location = np.eye(4)
    load_text(text, env)
    assert np.allclose(env.figures["c"].site("s.a").location, V.translation(1, 0, 0))


GOOD = (
    "figure f { segment a { site p->location = trans(0,0,0); } "
    "segment b { site p { location = trans(0,0,0); } } "
)
JOINED = GOOD + "joint j { connect a.p to b.p; } "


@pytest.mark.parametrize(
    ("text", "line", "col", "words"),
    [
        (GOOD + "\njoint j { connect a.p to b.nope; } }", 2, 26, "has no site 'nope'"),
        (GOOD + "\njoint j { connect a.p to c.p; } }", 2, 26, "no segment 'c'"),
        (GOOD + "\njoint j { connect a.p to b.p; type = R(w); } }", 2, 40, "bad DOF spec"),
        (
            GOOD + "\njoint j { connect a.p to b.p; type = R(z); displacement = (1, 2); } }",
            2,
            59,
            "expected 1",
        ),
        (
            GOOD + "\njoint j { connect a.p to b.p; type = R(z); lower_limits = (1, 2); } }",
            2,
            59,
            "expected 1",
        ),
        (GOOD + "\njoint j { connect a.p to a.p; } }", 2, 11, "two different segments"),
        (GOOD + "\njoint j { type = R(z); } }", 2, 1, "has no 'connect"),
        (GOOD + "\njoint j { connect a.p b.p; } }", 2, 11, "connect SITE to SITE"),
        (GOOD + "\nsegment a { } }", 2, 1, "defined twice"),
        (GOOD + "\nroot = a.p; root = b.p; }", 2, 13, "assigned twice"),
        (GOOD + "\nsize = 3; }", 2, 1, "unknown figure field"),
        (GOOD + "\nroot = zz; }", 2, 8, "SEGMENT.SITE"),
        (GOOD + "\nroot = a.p; location = 5; }", 2, 24, "expected a transform"),
        (JOINED + "}\nwidget w { }", 2, 1, "unknown block keyword 'widget'"),
        (JOINED + '}\nfigure g { file = "missing.fig"; }', 2, 12, "cannot find figure file"),
        (JOINED + '}\nfigure f { file = "arm.fig"; }', 2, 1, "already exists"),
        (JOINED + "}\njoint g.j { }", 2, 1, "no figure named 'g'"),
        (GOOD + "}", 1, 1, "not connected to the root"),
        ("figure f { segment s { site a { size = 1; } } }", 1, 33, "unknown site field"),
        (
            "figure f { segment s { site a->location = trans(0,0,0); site a->location = trans(0,0,0); } }",
            1,
            57,
            "twice",
        ),
        ('figure f { segment s { psurf = "nothing.pss"; } }', 1, 24, "cannot find psurf"),
        ("figure f { segment s { psurf = 5 * scale(2); } }", 1, 32, "psurf ="),
        ('figure "9f" { }', 1, 1, "bad figure name"),
        ("x = 1;", 1, 1, "unknown top-level statement"),
        ('include "a\x00b";', 1, 1, "cannot find included file"),
        ('include "' + "a" * 5000 + '";', 1, 1, "cannot find included file"),
        (JOINED + "}\nconnect world.nowhere to f.a.p;", 2, 9, "the world has no site"),
        ("segment world { size = 1; }", 1, 17, "only sites"),
    ],
)
def test_semantic_errors_are_located(text: str, line: int, col: int, words: str) -> None:
    with pytest.raises(PeabodyError) as info:
        load_text(text, None, "bad.env", DATA)
    err = info.value
    assert words in err.message
    assert (err.file, err.line, err.column) == ("bad.env", line, col)


def test_a_figure_file_holds_one_figure() -> None:
    with pytest.raises(PeabodyError, match="only one figure block"):
        read_figure(DATA / "scene.env")


def test_non_utf8_files_are_located_errors(tmp_path: Path) -> None:
    path = tmp_path / "x.fig"
    path.write_bytes(b"figure f {\n  segment \xff { } }")
    with pytest.raises(PeabodyError) as info:
        read_figure(path)
    assert (info.value.line, info.value.column) == (2, 11)


# --- the extension point ------------------------------------------------------------------------------------


def test_registered_blocks_are_handed_over() -> None:
    seen: list[tuple[Block, Environment, LoadContext]] = []

    def handler(block: Block, env: Environment, ctx: LoadContext) -> None:
        seen.append((block, env, ctx))
        env.extensions.setdefault("gadget", {})[block.name] = len(block.body)

    register_block("gadget", handler, writer=lambda name, n: f"gadget {name} {{ count = {n}; }}")
    try:
        env = load_text("gadget g1.x { a = 1; frame[3] = (0.1); }", None, "g.env", DATA)
        assert env.extensions["gadget"] == {"g1.x": 2}
        block, got_env, ctx = seen[0]
        assert (
            block.keyword == "gadget" and got_env is env and ctx.filename == "g.env" and ctx.base_dir == DATA
        )
        assert "gadget g1.x { count = 2; }" in format_environment(env)
    finally:
        unregister_block("gadget")
    with pytest.raises(PeabodyError, match="unknown block keyword 'gadget'"):
        load_text("gadget g { }")


def test_handler_failures_become_located_errors() -> None:
    def handler(block: Block, env: Environment, ctx: LoadContext) -> None:
        raise KeyError("frame 9 is missing")

    register_block("broken", handler)
    try:
        with pytest.raises(PeabodyError, match="frame 9 is missing") as info:
            load_text("\n  broken b { }", None, "b.env")
        assert (info.value.line, info.value.column) == (2, 3)
    finally:
        unregister_block("broken")
    with pytest.raises(ValueError, match="built-in"):
        register_block("figure", handler)


# --- round trips --------------------------------------------------------------------------------------------


def _fig_files() -> list[Path]:
    return sorted(DATA.glob("*.fig")) + sorted(FIGURES.glob("*.fig"))


@pytest.mark.parametrize("path", _fig_files(), ids=lambda p: p.name)
def test_figure_round_trip(path: Path, tmp_path: Path) -> None:
    fig = read_figure(path)
    # in memory, psurfs resolved against the original folder
    again = load_text(format_figure(fig), None, "rt", path.parent).figures[fig.name]
    again.filename = fig.filename
    assert figure_differences(fig, again) == []
    # through a file in another folder: psurf references are rewritten relative to it
    out = tmp_path / "sub" / path.name
    out.parent.mkdir()
    write_figure(fig, out)
    back = read_figure(out)
    assert figure_differences(fig, back) == []


def test_round_trip_with_rotations_and_odd_values(tmp_path: Path) -> None:
    text = """figure odd {
        segment s { site a->location = xyz(12.5deg, -80deg, 170deg) * trans(1.234567cm, -2m, 3in);
                    site b->location = matrix(2,0,0,1, 0,1,0,2, 0,0,1,3, 0,0,0,1); note = ("x", 2cm); }
        segment t { site a->location = xyz(0, 90deg, 0) * trans(0,0,0); }
        joint j { connect s.a to t.a; type = T(0.6, 0.8, 0) * R(-y); lower_limits = (-inf, -10deg);
                  displacement = (12.5cm, 33deg); }
        root = t.a; location = xyz(0, 0, 45deg) * trans(10m, 0, 0);
    }"""
    fig = load_text(text).figures["odd"]
    again = load_text(format_figure(fig)).figures["odd"]
    assert figure_differences(fig, again) == []


@pytest.mark.parametrize("inline", [False, True])
def test_environment_round_trip(inline: bool, tmp_path: Path) -> None:
    env = read_environment(DATA / "scene.env")
    text = format_environment(env, base_dir=DATA, inline=inline)
    again = load_text(text, None, "rt.env", DATA)
    assert environment_differences(env, again) == []
    # written elsewhere, figure files and psurfs are referenced relative to the new file
    out = tmp_path / "elsewhere" / "scene.env"
    out.parent.mkdir()
    write_environment(env, out, inline=inline)
    assert environment_differences(env, read_environment(out)) == []


def test_environment_by_base_name_uses_the_search_path(tmp_path: Path) -> None:
    env = read_environment(DATA / "scene.env")
    out = tmp_path / "scene.env"
    out.write_text(format_environment(env))  # `file = "arm.fig";`: found through the search path
    with pytest.raises(PeabodyError, match="cannot find figure file"):
        read_environment(out)
    assert environment_differences(env, read_environment(out, search_path=[DATA])) == []


def test_write_figure_for_generated_figures(tmp_path: Path) -> None:
    shutil.copy(DATA / "cube.pss", tmp_path / "cube.pss")
    fig = read_figure(DATA / "rifle.fig", load_psurfs=False)
    fig.segments["gun"].attributes["barrel"] = (41.5, "cm?")
    write_figure(fig, tmp_path / "rifle.fig")
    back = read_figure(tmp_path / "rifle.fig")
    assert back.segments["gun"].psurf is not None
    assert figure_differences(fig, back, psurfs=False) == []


# --- fuzz ---------------------------------------------------------------------------------------------------

_SAMPLES = sorted(p.read_text() for p in DATA.glob("*.fig")) + sorted(
    p.read_text() for p in DATA.glob("*.env")
)
_PIECES = [
    "{",
    "}",
    ";",
    "=",
    "(",
    ")",
    ",",
    "*",
    "-",
    ".",
    " ",
    "\n",
    "0",
    "9",
    "cm",
    "deg",
    "x",
    "to ",
    "R(z)",
    "T(y)",
    "trans(1,2,3)",
    "segment ",
    "joint ",
    "site ",
    "connect ",
    "figure ",
    "root",
    "inf",
    '"',
    "->",
]


@pytest.mark.fuzz
@given(
    st.sampled_from(_SAMPLES),
    st.lists(
        st.tuples(st.integers(0, 10**6), st.integers(0, 8), st.sampled_from(_PIECES)), min_size=1, max_size=5
    ),
)
def test_mutated_files_load_or_fail_with_a_location(sample: str, edits: list[tuple[int, int, str]]) -> None:
    text = sample
    for pos, cut, insert in edits:
        i = pos % (len(text) + 1)
        text = text[:i] + insert + text[i + cut :]
    try:
        env = load_text(text, None, "m.env", DATA)
    except PeabodyError as err:
        assert err.file.endswith(".env") or err.file.endswith(".fig") or err.file.endswith(".pss")
        assert err.line >= 1 and err.column >= 1
        return
    # whatever loaded writes back and reloads to the same environment
    again = load_text(format_environment(env, DATA, inline=True), None, "rt.env", DATA)
    assert environment_differences(env, again) == []
