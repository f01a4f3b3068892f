"""Evaluating Peabody values (seed 000, 7.6): units, transforms and DOF products.

Units: lengths become centimetres (``cm``, ``mm``, ``m``, ``in``), angles radians (``deg``, ``rad``),
masses kilograms (``kg``, ``g``, ``lb``).  A bare number is already in the base unit (cm, radians, kg), which
is what channelset frames use for joint angles.

Transforms are 4x4 float64 arrays for column vectors (see :mod:`peabody.model`):

* ``trans(x, y, z)``: a translation.
* ``xyz(a, b, c)``: Jack's ``xyztomatrix``: rotate ``a`` about x, then ``b`` about the *rotated* y, then ``c``
  about the twice-rotated z, i.e. ``Rx(a) @ Ry(b) @ Rz(c)``.  :func:`matrix_to_xyz` inverts it.
* ``scale(s)`` / ``scale(sx, sy, sz)``; ``rot(x|y|z, angle)`` / ``rot(ax, ay, az, angle)``;
  ``matrix(m00, m01, ..., m33)`` (16 numbers, row-major, column-vector convention) for arbitrary matrices.
* A product ``A * B`` keeps Jack's row-vector reading: *A first, then B, both in the parent frame*.
  In column-vector terms its matrix is ``B @ A``.  So ``xyz(a,b,c) * trans(x,y,z)`` (what the writer
  emits) is the frame oriented by ``xyz`` and placed at ``(x, y, z)``: ``[R | p]``.

DOF products (a joint's ``type``) are products of ``R(axis)`` and ``T(axis)`` terms, where ``axis`` is
``x``, ``y``, ``z`` (optionally negated, ``-x``) or three numbers ``R(1, 0, 0)`` (normalised).  Unlike
transforms they compose *left to right in local frames* (7.2.5.2): ``D = dof[0] @ dof[1] @ ...``.

Every failure raises :class:`~peabody.language.PeabodyError` located at the offending node.
"""

from __future__ import annotations

import math

import numpy as np

from peabody.language import (
    BinOp,
    Call,
    Name,
    Neg,
    Number,
    PeabodyError,
    String,
    Unsupplied,
    Value,
    Vector,
)
from peabody.model import Dof
from peabody.rotations import axis_angle

LENGTH_UNITS = {"cm": 1.0, "mm": 0.1, "m": 100.0, "in": 2.54}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
MASS_UNITS = {"kg": 1.0, "g": 0.001, "lb": 0.45359237}
UNITS = {**LENGTH_UNITS, **ANGLE_UNITS, **MASS_UNITS}
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
_TRANSFORM_FUNCS = frozenset({"trans", "xyz", "scale", "rot", "matrix"})


def _err(node: Value, message: str) -> PeabodyError:
    return PeabodyError.at(node.loc, message)


# --- numbers ------------------------------------------------------------------------------------------------


def number(node: Value) -> float:
    """A scalar in base units (cm, radians, kg); 1-vectors ``(x)`` count as scalars."""
    if isinstance(node, Number):
        if node.unit is None:
            return node.value
        factor = UNITS.get(node.unit)
        if factor is None:
            raise _err(node, f"unknown unit {node.unit!r} (known: {', '.join(UNITS)})")
        return node.value * factor
    if isinstance(node, Neg):
        return -number(node.operand)
    if isinstance(node, Vector) and len(node.items) == 1:
        return number(node.items[0])
    if isinstance(node, Name) and node.name in ("inf", "infinity"):
        return math.inf
    if isinstance(node, BinOp):
        a, b = number(node.left), number(node.right)
        try:
            if node.op == "+":
                r = a + b
            elif node.op == "-":
                r = a - b
            elif node.op == "*":
                r = a * b
            elif node.op == "/":
                r = a / b
            else:
                r = float(a**b)
        except (ZeroDivisionError, OverflowError, ValueError, TypeError):
            raise _err(node, f"arithmetic error in {node.op!r}") from None
        if isinstance(r, complex):
            raise _err(node, "arithmetic gives a complex number")
        return float(r)
    raise _err(node, f"expected a number, found {describe(node)}")


def numbers(node: Value, count: int | None = None, what: str = "values", finite: bool = True) -> list[float]:
    """A vector (or a lone number) of scalars, optionally of an exact length (``inf`` only if not finite)."""
    items = node.items if isinstance(node, Vector) else (node,)
    out = [number(item) for item in items]
    if count is not None and len(out) != count:
        raise _err(node, f"expected {count} {what}, found {len(out)}")
    for item, v in zip(items, out, strict=True):
        if math.isnan(v) or (finite and math.isinf(v)):
            raise _err(item, f"{v} is not allowed here")
    return out


def string(node: Value) -> str:
    """A string or a (dotted) name used as a string (``valtostring``)."""
    if isinstance(node, String):
        return node.value
    if isinstance(node, Name):
        return node.name
    raise _err(node, f"expected a string or a name, found {describe(node)}")


def describe(node: Value) -> str:
    if isinstance(node, Number):
        return f"number {node.value:g}{node.unit or ''}"
    if isinstance(node, String):
        return f"string {node.value!r}"
    if isinstance(node, Name):
        return f"name {node.name!r}"
    if isinstance(node, Vector):
        return f"a {len(node.items)}-vector"
    if isinstance(node, Call):
        return f"{node.name}(...)"
    if isinstance(node, BinOp):
        return f"an expression with {node.op!r}"
    if isinstance(node, Neg):
        return "a negated value"
    if isinstance(node, Unsupplied):
        return "'$'"
    return type(node).__name__


# --- transforms ---------------------------------------------------------------------------------------------


def translation(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]], dtype=np.float64)


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]], dtype=np.float64)


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=np.float64)


def xyz_matrix(a: float, b: float, c: float) -> np.ndarray:
    """``xyztomatrix``: ``Rx(a) @ Ry(b) @ Rz(c)`` (intrinsic x, then y', then z'')."""
    return rot_x(a) @ rot_y(b) @ rot_z(c)


def matrix_to_xyz(m: np.ndarray) -> tuple[float, float, float]:
    """Angles ``(a, b, c)`` with ``xyz_matrix(a, b, c)`` equal to the rotation part of ``m``."""
    r = np.asarray(m, dtype=np.float64)[:3, :3]
    sb = float(np.clip(r[0, 2], -1.0, 1.0))
    b = math.asin(sb)
    if abs(sb) < 1.0 - 1e-12:
        a = math.atan2(-r[1, 2], r[2, 2])
        c = math.atan2(-r[0, 1], r[0, 0])
    else:  # gimbal lock: only a +- c is determined; put it all in a
        a = math.atan2(r[2, 1], r[1, 1])
        c = 0.0
    return a, b, c


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation about the unit ``axis`` by ``angle`` (``axisangletomatrix``), as a 4x4 transform."""
    m = np.eye(4)
    m[:3, :3] = axis_angle(axis, angle)
    return m


def is_rigid(m: np.ndarray, atol: float = 1e-9) -> bool:
    """Whether ``m`` is a rotation plus translation (what ``xyz(..) * trans(..)`` can express)."""
    r = m[:3, :3]
    return bool(
        np.allclose(m[3], (0, 0, 0, 1), atol=atol)
        and np.allclose(r @ r.T, np.eye(3), atol=atol)
        and np.linalg.det(r) > 0
    )


def _call_transform(node: Call) -> np.ndarray:
    name, args = node.name, node.args
    if name == "trans":
        return translation(*_flat_numbers(node, 3))
    if name == "xyz":
        return xyz_matrix(*_flat_numbers(node, 3))
    if name == "scale":
        vals = _flat_numbers(node, None)
        if len(vals) == 1:
            vals = vals * 3
        if len(vals) != 3:
            raise _err(node, f"scale takes 1 or 3 numbers, found {len(vals)}")
        return np.diag([*vals, 1.0])
    if name == "rot":
        if len(args) == 2 and isinstance(args[0], Name | Neg):
            axis = _axis(args[0])
            return axis_angle_matrix(axis, number(args[1]))
        vals = _flat_numbers(node, 4)
        return axis_angle_matrix(_unit(node, np.array(vals[:3])), vals[3])
    if name == "matrix":
        m = np.array(_flat_numbers(node, 16), dtype=np.float64).reshape(4, 4)
        return m
    raise _err(node, f"unknown transform function {name!r}")


def _flat_numbers(node: Call, count: int | None) -> list[float]:
    args = node.args
    if len(args) == 1 and isinstance(args[0], Vector):
        args = args[0].items
    vals = [number(a) for a in args]
    if not all(math.isfinite(v) for v in vals):
        raise _err(node, f"{node.name}() needs finite numbers")
    if count is not None and len(vals) != count:
        raise _err(node, f"{node.name}() takes {count} numbers, found {len(vals)}")
    return vals


def transform(node: Value) -> np.ndarray:
    """Evaluate a transform expression to a 4x4 matrix (``A * B`` is ``B @ A``, see the module docstring)."""
    if isinstance(node, Call):
        return _call_transform(node)
    if isinstance(node, BinOp) and node.op == "*":
        return transform(node.right) @ transform(node.left)
    if isinstance(node, Vector) and len(node.items) == 1:
        return transform(node.items[0])
    raise _err(node, f"expected a transform (trans/xyz/scale/rot/matrix), found {describe(node)}")


def is_transform(node: Value) -> bool:
    """Syntactic test: a product of transform function calls."""
    if isinstance(node, Call):
        return node.name in _TRANSFORM_FUNCS
    if isinstance(node, BinOp) and node.op == "*":
        return is_transform(node.left) and is_transform(node.right)
    return False


# --- DOFs ---------------------------------------------------------------------------------------------------


def _unit(node: Value, v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not math.isfinite(n) or n < 1e-12:
        raise _err(node, "an axis must be a non-zero finite vector")
    return v / n


def _axis(node: Value) -> np.ndarray:
    if isinstance(node, Name) and node.name in AXES:
        return np.array(AXES[node.name])
    if isinstance(node, Neg):
        return -_axis(node.operand)
    raise _err(node, f"expected an axis x, y, z or three numbers, found {describe(node)}")


def dof_term(node: Value) -> Dof:
    """One ``R(axis)`` / ``T(axis)`` term."""
    if not isinstance(node, Call) or node.name not in ("R", "T"):
        raise _err(node, f"expected a DOF term R(axis) or T(axis), found {describe(node)}")
    args = node.args
    if len(args) == 1 and isinstance(args[0], Vector):
        args = args[0].items
    if len(args) == 1:
        axis = _axis(args[0])
    elif len(args) == 3:
        axis = _unit(node, np.array([number(a) for a in args], dtype=np.float64))
    else:
        raise _err(node, f"{node.name}() takes an axis name or 3 numbers, found {len(args)} arguments")
    return Dof(node.name, axis)  # type: ignore[arg-type]


def dofs(node: Value) -> list[Dof]:
    """A DOF product ``R(z) * R(y) * T(1,0,0)`` -> DOFs in written (left to right, local) order."""
    if isinstance(node, BinOp) and node.op == "*":
        return dofs(node.left) + dofs(node.right)
    if isinstance(node, Vector) and len(node.items) == 1:
        return dofs(node.items[0])
    return [dof_term(node)]


def dof_matrix(dof: Dof, value: float) -> np.ndarray:
    """The 4x4 transform of one DOF at ``value`` (radians about / cm along its axis)."""
    if dof.kind == "R":
        return axis_angle_matrix(dof.axis, value)
    return translation(*(dof.axis * value))


def dofs_matrix(dof_list: list[Dof], values: list[float] | np.ndarray | None = None) -> np.ndarray:
    """``dof[0] @ dof[1] @ ...`` at ``values`` (default: each DOF's current value)."""
    m = np.eye(4)
    for i, d in enumerate(dof_list):
        m = m @ dof_matrix(d, d.value if values is None else float(values[i]))
    return m


# --- generic values -----------------------------------------------------------------------------------------


def to_python(node: Value) -> object:
    """A plain Python/numpy value for fields the loader keeps verbatim (segment attributes).

    Numbers -> float (base units), strings and names -> str, vectors -> tuple, transform products ->
    4x4 array.  Anything else stays a syntax-tree node, which the writer can print back.
    """
    if isinstance(node, Number | Neg) or (isinstance(node, BinOp) and not is_transform(node)):
        return number(node)
    if isinstance(node, String):
        return node.value
    if isinstance(node, Name):
        return node.name
    if isinstance(node, Vector):
        return tuple(to_python(item) for item in node.items)
    if is_transform(node):
        return transform(node)
    return node
