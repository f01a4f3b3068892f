"""TIPS files (seed 002, section 7): the spitter, the stub's loader (7.1 and 7.3), the articulation file."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from client_stub.stub.artic import (
    ArticError,
    articulation,
    bind_table,
    format_artic,
    parse_artic,
    update_table_for,
)
from client_stub.stub.tips import TipsError, load_tips, parse_tips
from peabody.loader import read_figure
from peabody.model import Environment, Figure, Psurf, Segment, Site
from peabody.tips import format_tips, spit

REPO = Path(__file__).resolve().parent.parent
FIGURES = REPO / "figures"
SHIPPED = REPO / "client_stub" / "data"

# Section 7.2, verbatim: "a Peabody environment which contains a single unit cube as its only figure"
SEED_CUBE = """1 figures
FIGURE #0
cube
FIGURE #0
cube.fig
Global position matrix
1.000000 0.000000 0.000000 0.000000
0.000000 1.000000 0.000000 0.000000
0.000000 0.000000 1.000000 0.000000
0.000000 0.000000 0.000000 1.000000
Root site inverse matrix
1.000000 0.000000 0.000000 0.000000
0.000000 1.000000 0.000000 0.000000
0.000000 0.000000 1.000000 0.000000
0.000000 0.000000 0.000000 1.000000
1 (psurf flag)
1 (# attributes)
0.173333 0.125490 0.173333
0.693333 0.501961 0.693333
0.000000 0.000000 0.000000
0 (texture flag)
8 total nodes
0.000000 0.000000 0.000000
0.000000 0.000000 1.000000
1.000000 0.000000 1.000000
1.000000 0.000000 0.000000
0.000000 -1.000000 0.000000
0.000000 -1.000000 1.000000
1.000000 -1.000000 1.000000
1.000000 -1.000000 0.000000
6 faces
0 attribnum
4 vertices
0.000000 0.000000 0.000000
0
1
2
3
0 attribnum
4 vertices
0.000000 0.000000 0.000000
0
3
7
4
0 attribnum
4 vertices
0.000000 0.000000 0.000000
2
6
7
3
0 attribnum
4 vertices
0.000000 0.000000 0.000000
0
4
5
1
0 attribnum
4 vertices
0.000000 0.000000 0.000000
4
7
6
5
0 attribnum
4 vertices
0.000000 0.000000 0.000000
1
5
6
2
1 sites
0 joints
SITE
base
Site 1 matrix
1.000000 0.000000 0.000000 0.000000
0.000000 1.000000 0.000000 0.000000
0.000000 0.000000 1.000000 0.000000
0.000000 0.000000 0.000000 1.000000
"""

CUBE_NODES = [(0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0), (0, -1, 0), (0, -1, 1), (1, -1, 1), (1, -1, 0)]
CUBE_FACES = [(0, 1, 2, 3), (0, 3, 7, 4), (2, 6, 7, 3), (0, 4, 5, 1), (4, 7, 6, 5), (1, 5, 6, 2)]


def cube_environment() -> Environment:
    psurf = Psurf(
        np.array(CUBE_NODES, float),
        [np.array(f) for f in CUBE_FACES],
        np.zeros(6, np.int64),
        [{"diffuse": (0.693333, 0.501961, 0.693333)}],
    )
    fig = Figure("cube", filename="cube.fig")
    seg = fig.add_segment(Segment("cube", psurf=psurf))
    fig.root = seg.add_site(Site("base"))
    env = Environment()
    env.add_figure(fig)
    return env


def test_spit_reproduces_the_seed_cube_byte_for_byte() -> None:
    assert format_tips(cube_environment()) == SEED_CUBE


def test_loader_reads_the_seed_cube() -> None:
    tips = parse_tips(SEED_CUBE, "cube.tips")
    (fig,) = tips.figures
    assert (fig.name, fig.filename) == ("cube", "cube.fig")
    assert np.array_equal(fig.location, np.eye(4)) and np.array_equal(fig.root_inverse, np.eye(4))
    geom = fig.root.geometry
    assert geom is not None and not geom.strips
    assert np.array_equal(geom.vertices, np.array(CUBE_NODES, float))
    assert [tuple(p) for p in geom.polygons or []] == CUBE_FACES
    assert len(geom.triangles) == 12  # six quads, fanned
    np.testing.assert_allclose(geom.attributes[0].diffuse, (0.693333, 0.501961, 0.693333))
    assert [s.name for s in fig.root.sites] == ["base"] and fig.walk() == []


def test_matrices_are_written_row_vector_and_read_back_column_vector(tmp_path: Path) -> None:
    env = cube_environment()
    fig = env.figures["cube"]
    fig.location = np.array([[0.0, -1, 0, 10], [1, 0, 0, 20], [0, 0, 1, 30], [0, 0, 0, 1]])
    text = format_tips(env)
    lines = text.splitlines()
    i = lines.index("Global position matrix")
    assert lines[i + 4] == "10.000000 20.000000 30.000000 1.000000"  # translation in the fourth row
    np.testing.assert_allclose(parse_tips(text).figures[0].location, fig.location)


@pytest.fixture(scope="module")
def di() -> tuple[Figure, str]:
    fig = read_figure(FIGURES / "DI.fig")
    env = Environment()
    env.add_figure(fig)
    return fig, format_tips(env)


def test_di_round_trip_keeps_geometry_sites_and_joints(di: tuple[Figure, str]) -> None:
    fig, text = di
    (tf,) = parse_tips(text, "DI.tips").figures
    np.testing.assert_allclose(tf.location, fig.location, atol=1e-6)
    assert [j.name for j in tf.pose_order()] == list(fig.joints)
    segments = {"root": tf.root} | {j.segment.name: j.segment for j, _, _ in tf.walk()}
    root_name = fig.root.segment.name
    assert len(segments) == len(fig.segments)
    for name, seg in fig.segments.items():
        ts = segments["root" if name == root_name else name]
        assert [s.name for s in ts.sites] == list(seg.sites)
        for s in ts.sites:
            np.testing.assert_allclose(s.matrix, seg.sites[s.name].location, atol=1e-6)
        if seg.psurf is None:
            assert ts.geometry is None
            continue
        assert ts.geometry is not None
        np.testing.assert_allclose(ts.geometry.vertices, seg.psurf.nodes, atol=1e-6)
        assert [tuple(p) for p in ts.geometry.polygons or []] == [tuple(f) for f in seg.psurf.faces]
    for joint, _, _ in tf.walk():
        pj = fig.joints[joint.name]
        assert [d.kind for d in joint.dofs] == [d.kind for d in pj.dofs]
        for d, pd in zip(joint.dofs, pj.dofs, strict=True):
            np.testing.assert_allclose(d.axis, pd.axis, atol=1e-6)
            for a, b in ((d.lower, pd.lower), (d.upper, pd.upper)):
                assert (math.isinf(a) and a == b) or abs(a - b) < 1e-6
        far = pj.site1 if joint.reverse else pj.site2
        assert joint.othersite == f"{far.segment.name}.{far.name}"


def test_shipped_tips_files_are_current() -> None:
    """client_stub/data/*.tips are `ttes figure spit figures/X.fig` (regenerate when the figures change)."""
    for name in ("DI", "AK_47", "M16"):
        env = Environment()
        env.add_figure(read_figure(FIGURES / f"{name}.fig"))
        assert (SHIPPED / f"{name}.tips").read_text() == format_tips(env), (
            f"stale: run `ttes figure spit figures/{name}.fig client_stub/data/{name}.tips`"
        )


def test_spit_cli_writes_a_loadable_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from ttes.cli import main

    out = tmp_path / "pair.tips"
    assert (
        main(["figure", "spit", str(FIGURES / "DI.fig"), str(FIGURES / "AK_47.fig"), str(out), "--json"]) == 0
    )
    assert '"figures": ["DI", "AK_47"]' in capsys.readouterr().out
    assert [f.name for f in load_tips(out).figures] == ["DI", "AK_47"]
    assert main(["figure", "spit", str(tmp_path / "missing.fig"), str(out)]) == 1


# -- the 7.3 alternate format ------------------------------------------------------------------------------


def _strip_order(poly: tuple[int, ...]) -> list[int]:
    """A convex polygon as one triangle strip: v0, v1, vn-1, v2, vn-2, ..."""
    lo, hi = 1, len(poly) - 1
    order = [poly[0]]
    take_lo = True
    while lo <= hi:
        order.append(poly[lo] if take_lo else poly[hi])
        if take_lo:
            lo += 1
        else:
            hi -= 1
        take_lo = not take_lo
    return order


def strips_version(text: str, *, indexed: bool, color: str, normals: str) -> str:
    """The cube rewritten in section 7.3's encoding (what the Performer 1.2 pfuBuilder produced)."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.endswith("total nodes"))
    end = next(i for i, ln in enumerate(lines) if ln.endswith(" sites"))
    strips = [_strip_order(f) for f in CUBE_FACES]
    verts = [CUBE_NODES[v] for s in strips for v in s]
    out = ["geoset", "0 (attribute)", f"{len(strips)} (strips)", *[str(len(s)) for s in strips]]
    out.append("indexed" if indexed else "not indexed")
    for k, v in enumerate(verts):
        if indexed:
            out.append(str([i for s in strips for i in s][k]))
        out.append(" ".join(f"{c:f}" for c in v))
    out.append(color)
    if color == "PFGS_OVERALL":
        out.append("0.5 0.25 0.75 1")
    elif color == "PFGS_PER_VERTEX":
        out += ["0.1 0.2 0.3 1"] * len(verts)
    out.append(normals)
    if normals == "PFGS_PER_VERTEX":
        out += ["0 0 1"] * len(verts)
    elif normals == "PFGS_PER_PRIM":
        out += ["1 0 0"] * len(strips)
    out += ["PFGS_OFF", "endgeosets"]
    return "\n".join(lines[:start] + out + lines[end:]) + "\n"


def _corners(vertices: np.ndarray, triangles: np.ndarray) -> set[tuple[float, ...]]:
    return {tuple(np.round(vertices[i], 6)) for i in triangles.ravel()}


def _area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / 2)


def _signed_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


@pytest.mark.parametrize("indexed", [True, False])
@pytest.mark.parametrize(
    ("color", "normals"),
    [("PFGS_OVERALL", "PFGS_PER_VERTEX"), ("PFGS_PER_VERTEX", "PFGS_OFF"), ("PFGS_OFF", "PFGS_PER_PRIM")],
)
def test_loader_reads_the_alternate_strip_format(indexed: bool, color: str, normals: str) -> None:
    poly = parse_tips(SEED_CUBE).figures[0].root.geometry
    geom = (
        parse_tips(strips_version(SEED_CUBE, indexed=indexed, color=color, normals=normals))
        .figures[0]
        .root.geometry
    )
    assert poly is not None and geom is not None and geom.strips
    assert len(geom.triangles) == 12
    # the same surface (a strip splits a quad along the other diagonal than a fan), wound the same way:
    # strips alternate their winding and the loader undoes it, so the enclosed volume keeps its sign
    assert _corners(geom.vertices, geom.triangles) == _corners(poly.vertices, poly.triangles)
    assert _area(geom.vertices, geom.triangles) == pytest.approx(_area(poly.vertices, poly.triangles))
    assert _signed_volume(geom.vertices, geom.triangles) == pytest.approx(
        _signed_volume(poly.vertices, poly.triangles)
    )
    if color == "PFGS_OVERALL":
        assert geom.vertex_colors is not None
        np.testing.assert_allclose(
            geom.vertex_colors, np.tile([0.5, 0.25, 0.75, 1.0], (len(geom.vertices), 1))
        )
    elif color == "PFGS_OFF":
        assert geom.vertex_colors is None
    assert (geom.vertex_normals is None) == (normals == "PFGS_OFF")


# -- errors ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("mutate", "line", "words"),
    [
        (lambda ls: ls[:30], 31, "end of file"),
        (lambda ls: [*ls[:22], "0.0 zero 1.0", *ls[23:]], 23, "not a number"),
        (lambda ls: [*ls[:34], "9", *ls[35:]], 35, "out of range"),
        (lambda ls: [*ls[:6], "1 2 3", *ls[7:]], 7, "4 numbers"),
        (lambda ls: [*ls[:6], "nan 0 0 0", *ls[7:]], 7, "finite"),
        (lambda ls: ["99 figures", *ls[1:]], 1, "out of range"),
        (lambda ls: ["2 figures", *ls[1:]], 83, "end of file"),
    ],
)
def test_malformed_files_raise_located_tips_errors(mutate, line: int, words: str) -> None:
    text = "\n".join(mutate(SEED_CUBE.splitlines())) + "\n"
    with pytest.raises(TipsError) as err:
        parse_tips(text, "bad.tips")
    assert err.value.line == line and words in err.value.message
    assert str(err.value).startswith(f"bad.tips:{line}:")


def test_unreadable_file_is_a_tips_error(tmp_path: Path) -> None:
    bad = tmp_path / "bin.tips"
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(TipsError):
        load_tips(bad)
    with pytest.raises(TipsError):
        load_tips(tmp_path / "absent.tips")


def jointed_text() -> str:
    """The cube with a lid on a two-DOF hinge: joints, DOF lines and a second segment to corrupt."""
    from peabody.model import Dof, Joint

    env = cube_environment()
    fig = env.figures["cube"]
    lid = fig.add_segment(Segment("lid", psurf=Psurf(np.eye(3), [np.array([0, 1, 2])])))
    lid.add_site(Site("proximal"))
    hinge = Dof("R", np.array([1.0, 0, 0]), -1.0, 1.0)
    fig.add_joint(
        Joint("hinge", fig.site("cube.base"), lid.sites["proximal"], [hinge, Dof("T", np.array([0, 1.0, 0]))])
    )
    return format_tips(env)


@pytest.mark.fuzz
@given(st.data())
def test_any_corruption_raises_only_tips_error(data: st.DataObject) -> None:
    text = data.draw(st.sampled_from([SEED_CUBE, jointed_text()]))
    lines = text.splitlines()
    junk = [
        "",
        "-1",
        "99999999",
        "1e309",
        "nan",
        "x",
        "1 2",
        "geoset",
        "endgeosets",
        "0 0 0 0",
        "R 0 0 0 1 2",
        "1",
    ]
    for _ in range(data.draw(st.integers(1, 4))):
        if not lines:
            break
        i = data.draw(st.integers(0, len(lines) - 1))
        op = data.draw(st.sampled_from(["drop", "dup", "replace"]))
        if op == "drop":
            lines.pop(i)
        elif op == "dup":
            lines.insert(i, lines[i])
        else:
            lines[i] = data.draw(st.sampled_from(junk))
    with contextlib.suppress(TipsError):
        parse_tips("\n".join(lines))


def test_jointed_figure_round_trip() -> None:
    (fig,) = parse_tips(jointed_text()).figures
    ((joint, site, parent),) = fig.walk()
    assert (joint.name, site.name, parent, joint.othersite, joint.pose_index) == (
        "hinge",
        "base",
        None,
        "lid.proximal",
        0,
    )
    assert [(d.kind, d.lower, d.upper) for d in joint.dofs] == [("R", -1.0, 1.0), ("T", -math.inf, math.inf)]
    assert joint.segment.name == "lid" and joint.segment.geometry is not None


# -- articulation parameters and the update table ---------------------------------------------------------


def test_artic_round_trip_and_update_table_agrees_with_the_server(
    tmp_path: Path, di: tuple[Figure, str]
) -> None:
    from server.soldier.synthetic import synthetic_motion_library
    from server.soldier.wire import update_table_for as server_table

    fig, text = di
    rifle = read_figure(FIGURES / "AK_47.fig")
    ours = [
        articulation(parse_tips(text).figures[0]),
        articulation(load_tips(SHIPPED / "AK_47.tips").figures[0]),
    ]
    assert parse_artic(format_artic(ours)) == ours
    soldier = ours[0]
    assert [j.name for j in soldier.joints] == list(fig.joints)
    assert [j.ndofs for j in soldier.joints] == [j.ndofs for j in fig.joints.values()]
    spine = next(j for j in soldier.joints if j.name == "spine_compression")
    pj = fig.joints["spine_compression"].dofs[0]
    assert spine.dofs == (("T", pj.lower / 100, pj.upper / 100),)  # metres
    table = update_table_for(ours[0], ours[1], table_id=3)
    library = synthetic_motion_library([[fig, rifle]])
    server = server_table(library, 3)
    assert table == server  # names, order, DOF counts and quantisation
    binding = bind_table(table, server)
    assert binding.agrees and not binding.missing
    np.testing.assert_array_equal(binding.dof_src, np.arange(table.ndofs))
    np.testing.assert_array_equal(binding.figure_src, [0, 1])


def test_bind_table_maps_by_name_when_the_wire_order_differs() -> None:
    from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable

    r = DofRange("R", -math.pi, math.pi)
    ours = UpdateTable(
        1, "DI.fig", "", (JointEntry("a", (r,)), JointEntry("b", (r, r)), FigureEntry("soldier"))
    )
    wire = UpdateTable(
        7, "DI.fig", "", (JointEntry("b", (r, r)), JointEntry("c", (r,)), FigureEntry("soldier"))
    )
    binding = bind_table(ours, wire)
    assert not binding.agrees and binding.missing == ("a",)
    assert binding.dof_src.tolist() == [0, 1] and binding.dof_dst.tolist() == [1, 2]


@pytest.mark.parametrize(
    "text",
    [
        "",
        "ttes-artic 2\nend\n",
        "ttes-artic 1\nfigure A A.fig 1 1\nend\n",
        "ttes-artic 1\nfigure A A.fig 1 1\njoint 0 j 1 X 0 1\nend\n",
        "ttes-artic 1\nfigure A A.fig 1 1\njoint 0 j 1 R 0 one\nend\n",
        "ttes-artic 1\nfigure A A.fig 0 0\n",
    ],
)
def test_malformed_artic_raises_artic_error(text: str) -> None:
    with pytest.raises(ArticError):
        parse_artic(text)


def test_spit_writes_environment_files(tmp_path: Path) -> None:
    env_file = tmp_path / "pair.env"
    env_file.write_text(
        f'figure s0 {{ file = "{FIGURES / "DI.fig"}"; }}\nfigure g0 {{ file = "{FIGURES / "M16.fig"}"; }}\n'
    )
    out = tmp_path / "pair.tips"
    env = spit([env_file], out)
    figs = load_tips(out).figures
    assert [f.name for f in figs] == list(env.figures) == ["s0", "g0"]
    assert [f.filename for f in figs] == ["DI.fig", "M16.fig"]
