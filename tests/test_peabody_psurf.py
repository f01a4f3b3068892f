"""Psurf (.pss) files: the manual's example, csurfs, attributes, errors, round trips, trimesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from peabody.language import PeabodyError
from peabody.psurf import (
    PsurfError,
    fan_triangles,
    format_psurf,
    parse_psurf,
    psurf_bounds,
    psurf_edges,
    psurf_from_trimesh,
    psurf_to_trimesh,
    psurfs_equal,
    read_psurf,
    transform_psurf,
    write_psurf,
)

DATA = Path(__file__).parent / "data" / "peabody"


def test_the_manuals_cube() -> None:
    cube = read_psurf(DATA / "cube.pss")
    assert cube.nodes.shape == (8, 3) and cube.polygon_count == 6
    assert np.array_equal(cube.faces[0], [0, 1, 2, 3])  # "1 2 3 4" is 1-based in the file
    assert cube.face_attributes.tolist() == [0, 0, 0, 1, 1, 1]  # [attribute 1] carries over
    assert cube.edges is None and cube.csurfs == []
    assert len(psurf_edges(cube)) == 12
    lo, hi = psurf_bounds(cube)
    assert np.array_equal(lo, [0, 0, 0]) and np.array_equal(hi, [1, 1, 1])
    assert cube.filename == str((DATA / "cube.pss").resolve())


def test_csurfs_edges_and_attribute_definitions() -> None:
    p = read_psurf(DATA / "two_csurfs.pss")
    assert p.csurfs == [(3, 3, 1), (4, 0, 1)]
    assert np.array_equal(p.faces[1], [3, 4, 5, 6])  # local indices 1..4 of csurf 2 resolved globally
    assert p.edges.tolist() == [[0, 1], [1, 2], [2, 0]]
    assert p.face_attributes.tolist() == [0, 2]
    assert p.attributes[0] == {"name": "skin", "diffuse": (0.69, 0.5, 0.69), "ambient": (0.17, 0.13, 0.17)}
    assert p.attributes[1] == {} and p.attributes[2]["name"] == "olive"


def test_syntax_details() -> None:
    p = parse_psurf("0 0 0, .5 -.5 1e1 , -1. 2 +3;\n;\n1,2,3;;")
    assert np.allclose(p.nodes, [[0, 0, 0], [0.5, -0.5, 10], [-1, 2, 3]])
    assert p.polygon_count == 1
    empty = parse_psurf("{ nothing at all } ; ; ;")
    assert empty.nodes.shape == (0, 3) and empty.faces == []


@pytest.mark.parametrize(
    ("text", "line", "col", "words"),
    [
        ("0 0 0\n0 0\n;;;", 3, 1, "triplets"),
        ("0 0 0; 1 2;;", 1, 10, "edge node 2"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2 4;;", 2, 5, "outside 1..3"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2;;", 2, 4, "at least 3"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2 3 [attr 1];;", 2, 7, "attribute"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2 3 [attribute 1] 4;;", 2, 21, "expected ';'"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2.5 3;;", 2, 3, "integer"),
        ("0 0 0 { never closed", 1, 7, "unterminated comment"),
        ("0 0 x;", 1, 5, "expected a node coordinate"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2 3", 2, 6, "expected ';' to end the face"),
        ("0 0 1e999;;;", 1, 5, "not finite"),
        ("{}", 1, 1, "empty psurf"),
        ("0 0 0 1 0 0 0 1 0;;\n[attribute 1];;", 2, 1, "needs a face"),
        ("0 0 0 1 0 0 0 1 0;;\n1 2 3 @;;", 2, 7, "unexpected character"),
    ],
)
def test_located_errors(text: str, line: int, col: int, words: str) -> None:
    with pytest.raises(PsurfError) as info:
        parse_psurf(text, "bad.pss")
    err = info.value
    assert isinstance(err, PeabodyError) and isinstance(err, ValueError)
    assert (err.file, err.line, err.column) == ("bad.pss", line, col)
    assert words in err.message


@pytest.mark.parametrize("name", ["cube.pss", "two_csurfs.pss"])
def test_round_trip(name: str, tmp_path: Path) -> None:
    p = read_psurf(DATA / name)
    assert psurfs_equal(p, parse_psurf(format_psurf(p, comment="written by a test")))
    write_psurf(p, tmp_path / name)
    assert psurfs_equal(p, read_psurf(tmp_path / name))


def test_trimesh_conversion() -> None:
    cube = read_psurf(DATA / "cube.pss")
    mesh = psurf_to_trimesh(cube)
    assert isinstance(mesh, trimesh.Trimesh) and mesh.faces.shape == (12, 3)
    assert mesh.is_watertight and mesh.volume == pytest.approx(1.0)  # counter-clockwise faces point outwards
    assert mesh.metadata["psurf_face"].tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5]
    back = psurf_from_trimesh(mesh, attributes=[{"name": "grey"}], filename="tri.pss")
    assert back.polygon_count == 12 and back.attributes == [{"name": "grey"}]
    assert psurfs_equal(back, parse_psurf(format_psurf(back)))
    box = psurf_from_trimesh(trimesh.creation.box(extents=(2, 4, 6)))
    assert psurf_to_trimesh(box).volume == pytest.approx(48.0)


def test_trimesh_colours_from_attribute_diffuse() -> None:
    p = read_psurf(DATA / "two_csurfs.pss")
    mesh = psurf_to_trimesh(p)
    colours = mesh.visual.face_colors
    assert colours[0, :3].tolist() == [175, 127, 175]  # skin, 0.69*255 -> 175
    assert colours[-1, :3].tolist() == [76, 102, 51]  # olive


def test_fan_triangles_of_mixed_polygons() -> None:
    p = parse_psurf("0 0 0 1 0 0 1 1 0 0 1 0 2 0 0;;\n1 2 3 4 5;\n1 2 3;;")
    tris, face_of = fan_triangles(p)
    assert tris.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 1, 2]]
    assert face_of.tolist() == [0, 0, 0, 1]


def test_transform_psurf() -> None:
    cube = read_psurf(DATA / "cube.pss")
    big = transform_psurf(cube, np.diag([2.0, 3.0, 4.0, 1.0]))
    assert np.allclose(psurf_bounds(big)[1], (2, 3, 4)) and big.faces is cube.faces


# --- fuzz ---------------------------------------------------------------------------------------------------

_SAMPLES = sorted(p.read_text() for p in DATA.glob("*.pss"))
_PIECES = [
    ";",
    ",",
    " ",
    "\n",
    "0",
    "1",
    "9",
    "-",
    ".",
    "e",
    "{",
    "}",
    "[",
    "]",
    "attribute",
    "(",
    ")",
    '"',
    "x",
]


@given(st.binary(max_size=200))
def test_random_bytes(data: bytes) -> None:
    try:
        parse_psurf(data.decode("latin-1"), "r.pss")
    except PsurfError as err:
        assert err.line >= 1 and err.column >= 1


@pytest.mark.fuzz
@given(
    st.sampled_from(_SAMPLES),
    st.lists(
        st.tuples(st.integers(0, 10**6), st.integers(0, 6), st.sampled_from(_PIECES)), min_size=1, max_size=6
    ),
)
def test_mutated_psurfs(sample: str, edits: list[tuple[int, int, str]]) -> None:
    text = sample
    for pos, cut, insert in edits:
        i = pos % (len(text) + 1)
        text = text[:i] + insert + text[i + cut :]
    try:
        p = parse_psurf(text, "m.pss")
    except PsurfError as err:
        assert err.file == "m.pss" and err.line >= 1 and err.column >= 1
        return
    assert psurfs_equal(p, parse_psurf(format_psurf(p)))
