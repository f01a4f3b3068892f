"""Evaluating Peabody values: units, transforms (order conventions), DOF products."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from peabody import values as V
from peabody.language import PeabodyError, parse_value
from peabody.writer import format_dofs, format_transform


def num(text: str) -> float:
    return V.number(parse_value(text))


def tf(text: str) -> np.ndarray:
    return V.transform(parse_value(text))


def test_units_convert_to_cm_radians_kg() -> None:
    assert num("2m") == pytest.approx(200.0)
    assert num("10mm") == pytest.approx(1.0)
    assert num("1in") == pytest.approx(2.54)
    assert num("180deg") == pytest.approx(math.pi)
    assert num("1.5rad") == 1.5
    assert num("7") == 7.0  # bare numbers are base units
    assert num("500g") == pytest.approx(0.5)
    assert num("-(3cm)") == -3.0
    assert num("(1 + 2) * 3") == 9.0
    assert num("2 ^ 3") == 8.0
    assert num("-inf") == -math.inf


def test_unit_and_arithmetic_errors_are_located() -> None:
    with pytest.raises(PeabodyError, match="unknown unit 'furlong'") as info:
        num("  3furlong")
    assert (info.value.line, info.value.column) == (1, 3)
    with pytest.raises(PeabodyError, match="arithmetic"):
        num("1 / 0")
    with pytest.raises(PeabodyError, match="expected a number"):
        num('"text"')


def test_trans_and_xyz_order() -> None:
    t = tf("trans(1cm, 2cm, 3m)")
    assert np.allclose(t[:3, 3], (1, 2, 300)) and np.allclose(t[:3, :3], np.eye(3))
    # xyz: x first, then about the rotated y, then the twice-rotated z == Rx @ Ry @ Rz
    a, b, c = 0.3, -0.7, 1.1
    assert np.allclose(tf("xyz(0.3, -0.7, 1.1)"), V.rot_x(a) @ V.rot_y(b) @ V.rot_z(c))
    # a quarter turn about z maps x to y
    assert np.allclose(tf("xyz(0deg, 0deg, 90deg)")[:3, :3] @ (1, 0, 0), (0, 1, 0))


def test_products_read_left_to_right_in_the_parent_frame() -> None:
    # xyz(..) * trans(p): oriented by xyz, placed at p (the writer's form)
    m = tf("xyz(0deg, 0deg, 90deg) * trans(10cm, 0cm, 0cm)")
    assert np.allclose(m[:3, 3], (10, 0, 0))
    assert np.allclose(m[:3, :3] @ (1, 0, 0), (0, 1, 0))
    # the other order rotates the translation too: column matrix B @ A
    m = tf("trans(10cm, 0cm, 0cm) * xyz(0deg, 0deg, 90deg)")
    assert np.allclose(m[:3, 3], (0, 10, 0))


def test_scale_rot_matrix() -> None:
    assert np.allclose(tf("scale(2)"), np.diag([2, 2, 2, 1]))
    assert np.allclose(tf("scale(1, 2, 3)"), np.diag([1, 2, 3, 1]))
    assert np.allclose(tf("rot(z, 90deg)")[:3, :3] @ (1, 0, 0), (0, 1, 0))
    assert np.allclose(tf("rot(0, 0, 2, 90deg)"), tf("rot(z, 90deg)"))
    m = np.arange(16.0).reshape(4, 4)
    assert np.allclose(tf("matrix(" + ", ".join(str(v) for v in m.reshape(16)) + ")"), m)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("trans(1, 2)", "takes 3 numbers"),
        ("scale(1, 2)", "1 or 3 numbers"),
        ("frobnicate(1)", "unknown transform function"),
        ("trans(inf, 0, 0)", "finite"),
        ("5", "expected a transform"),
        ("rot(w, 1)", "expected an axis"),
        ("matrix(1, 2)", "takes 16 numbers"),
    ],
)
def test_transform_errors(text: str, words: str) -> None:
    with pytest.raises(PeabodyError, match=words):
        tf(text)


def test_dof_products() -> None:
    dofs = V.dofs(parse_value("R(z) * R(y) * T(-x) * R(1, 1, 0)"))
    assert [d.kind for d in dofs] == ["R", "R", "T", "R"]
    assert np.allclose(dofs[0].axis, (0, 0, 1)) and np.allclose(dofs[2].axis, (-1, 0, 0))
    assert np.allclose(dofs[3].axis, np.array([1, 1, 0]) / math.sqrt(2))
    assert format_dofs(dofs) == "R(z) * R(y) * T(-x) * R(0.707107, 0.707107, 0)"
    # left to right in local frames: D = R(z)(a) @ R(y)(b)
    a, b = 0.4, -1.2
    two = V.dofs(parse_value("R(z) * R(y)"))
    assert np.allclose(V.dofs_matrix(two, [a, b]), V.rot_z(a) @ V.rot_y(b))
    slide = V.dofs(parse_value("T(y)"))
    assert np.allclose(V.dofs_matrix(slide, [5.0])[:3, 3], (0, 5, 0))


@pytest.mark.parametrize(
    "text", ["R(w)", "R(0, 0, 0)", "R(1, 2)", "trans(1,2,3)", "R(z) + R(y)", "5", 'R("x")']
)
def test_bad_dof_specs(text: str) -> None:
    with pytest.raises(PeabodyError):
        V.dofs(parse_value(text))


def test_to_python() -> None:
    assert V.to_python(parse_value("3.5kg")) == 3.5
    assert V.to_python(parse_value('("a", b, 2cm)')) == ("a", "b", 2.0)
    assert np.allclose(V.to_python(parse_value("trans(1,2,3)")), tf("trans(1,2,3)"))  # type: ignore[arg-type]


angles = st.floats(-math.pi, math.pi, allow_nan=False)
coords = st.floats(-500, 500, allow_nan=False)


@given(angles, st.floats(-math.pi / 2, math.pi / 2), angles, coords, coords, coords)
def test_matrix_to_xyz_and_format_round_trip(
    a: float, b: float, c: float, x: float, y: float, z: float
) -> None:
    m = V.xyz_matrix(a, b, c)
    m[:3, 3] = (x, y, z)
    back = V.xyz_matrix(*V.matrix_to_xyz(m))
    assert np.allclose(back[:3, :3], m[:3, :3], atol=1e-9)
    assert np.allclose(tf(format_transform(m)), m, atol=2e-6)
