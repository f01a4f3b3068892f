"""Writing figures and environments as Peabody text (seed 000, 7.9), and comparing them.

Numbers are written with six decimals: lengths in ``cm``, angles in ``deg``; transforms as
``xyz(a, b, c) * trans(x, y, z)`` (or just ``trans(...)`` when unrotated, ``matrix(...)`` when not rigid).
Reading back what was written therefore reproduces lengths to ~1e-6 cm and angles to ~1e-8 rad:
:func:`figures_equal` / :func:`environments_equal` compare with a tolerance (default ``1e-5``) for that.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from peabody import language as L
from peabody import values as V
from peabody.model import Dof, Environment, Figure, Joint, Psurf, Segment

INDENT = "    "
_PRECEDENCE = {"+": 1, "-": 1, "*": 2, "/": 2, "^": 3}


# --- numbers and values -------------------------------------------------------------------------------------


def fmt_number(x: float, unit: str = "") -> str:
    """``%.6f`` without trailing zeros, with the unit glued on; infinities as ``inf`` / ``-inf``."""
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    s = f"{x:.6f}".rstrip("0").rstrip(".")
    if s in ("-0", ""):
        s = "0"
    return s + unit


def fmt_length(x: float) -> str:
    return fmt_number(x, "cm")


def fmt_angle(x: float) -> str:
    return fmt_number(math.degrees(x) if math.isfinite(x) else x, "deg")


def format_transform(m: np.ndarray) -> str:
    """A 4x4 transform as ``xyz(..) * trans(..)`` (see :mod:`peabody.values` for the reading)."""
    m = np.asarray(m, dtype=np.float64)
    if not V.is_rigid(m, atol=1e-7):
        return "matrix(" + ", ".join(fmt_number(v) for v in m.reshape(16)) + ")"
    p = m[:3, 3]
    trans = f"trans({fmt_length(p[0])}, {fmt_length(p[1])}, {fmt_length(p[2])})"
    if np.allclose(m[:3, :3], np.eye(3), atol=1e-12):
        return trans
    a, b, c = V.matrix_to_xyz(m)
    return f"xyz({fmt_angle(a)}, {fmt_angle(b)}, {fmt_angle(c)}) * {trans}"


def _quote(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def format_value(value: object) -> str:
    """Peabody text for a syntax-tree value or a plain value (float, str, tuple, 4x4 array, DOF list)."""
    if isinstance(value, L.Number):
        return fmt_number(value.value, value.unit or "")
    if isinstance(value, L.String):
        return _quote(value.value)
    if isinstance(value, L.Name):
        return value.name
    if isinstance(value, L.Vector):
        return "(" + ", ".join(format_value(v) for v in value.items) + ")"
    if isinstance(value, L.Call):
        return f"{value.name}(" + ", ".join(format_value(v) for v in value.args) + ")"
    if isinstance(value, L.BinOp):
        mine = _PRECEDENCE[value.op]
        left, right = format_value(value.left), format_value(value.right)
        if isinstance(value.left, L.BinOp) and _PRECEDENCE[value.left.op] < mine:
            left = f"({left})"
        if isinstance(value.right, L.BinOp) and _PRECEDENCE[value.right.op] <= mine:
            right = f"({right})"
        return f"{left} {value.op} {right}"
    if isinstance(value, L.Neg):
        inner = format_value(value.operand)
        return f"-({inner})" if isinstance(value.operand, L.BinOp) else f"-{inner}"
    if isinstance(value, L.Unsupplied):
        return "$"
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, int | float | np.integer | np.floating):
        return fmt_number(float(value))
    if isinstance(value, str):
        return _quote(value)
    if isinstance(value, np.ndarray) and value.shape == (4, 4):
        return format_transform(value)
    if isinstance(value, list) and value and all(isinstance(d, Dof) for d in value):
        return format_dofs(value)
    if isinstance(value, tuple | list | np.ndarray):
        return "(" + ", ".join(format_value(v) for v in value) + ")"
    raise TypeError(f"cannot write {type(value).__name__} as a Peabody value")


def _axis_text(axis: np.ndarray) -> str:
    for name, unit in V.AXES.items():
        if np.allclose(axis, unit, atol=1e-12):
            return name
        if np.allclose(axis, -np.asarray(unit), atol=1e-12):
            return "-" + name
    return ", ".join(fmt_number(v) for v in axis)


def format_dofs(dofs: list[Dof]) -> str:
    """A joint ``type``: ``R(z) * R(x) * T(0.6, 0.8, 0)``."""
    return " * ".join(f"{d.kind}({_axis_text(d.axis)})" for d in dofs)


def _dof_values(dofs: list[Dof], attr: str) -> str:
    vals = [getattr(d, attr) for d in dofs]
    return (
        "("
        + ", ".join(fmt_angle(v) if d.kind == "R" else fmt_length(v) for d, v in zip(dofs, vals, strict=True))
        + ")"
    )


# --- figures ------------------------------------------------------------------------------------------------


def _psurf_ref(segment: Segment, base_dir: Path | None) -> str | None:
    psurf: Psurf | None = segment.psurf
    if base_dir is not None and psurf is not None and psurf.filename and os.path.isabs(psurf.filename):
        return os.path.relpath(psurf.filename, base_dir).replace(os.sep, "/")
    if segment.psurf_file is not None:
        return segment.psurf_file
    if psurf is not None:
        raise ValueError(f"segment {segment.fullname!r} has a psurf but no psurf_file to reference")
    return None


def _segment_lines(segment: Segment, level: int, base_dir: Path | None) -> list[str]:
    pad, pad1 = INDENT * level, INDENT * (level + 1)
    out = [f"{pad}segment {segment.name} {{"]
    ref = _psurf_ref(segment, base_dir)
    if ref is not None:
        text = f"{pad1}psurf = {_quote(ref)}"
        if segment.psurf_transform is not None:
            m = np.asarray(segment.psurf_transform)
            diag = np.diag(m)[:3]
            if np.allclose(m, np.diag([*diag, 1.0]), atol=1e-12):
                text += " * scale(" + ", ".join(fmt_number(v) for v in diag) + ")"
            else:
                text += " * " + format_transform(m)
        out.append(text + ";")
    for key, value in segment.attributes.items():
        out.append(f"{pad1}{key} = {format_value(value)};")
    for site in segment.sites.values():
        out.append(f"{pad1}site {site.name}->location = {format_transform(site.location)};")
    out.append(f"{pad}}}")
    return out


def _site_ref(joint_site: object) -> str:
    seg = joint_site.segment  # type: ignore[attr-defined]
    return f"{seg.name}.{joint_site.name}"  # type: ignore[attr-defined]


def _joint_lines(joint: Joint, level: int, connect: bool = True) -> list[str]:
    pad, pad1 = INDENT * level, INDENT * (level + 1)
    out = [f"{pad}joint {joint.name} {{"]
    if connect:
        out.append(f"{pad1}connect {_site_ref(joint.site1)} to {_site_ref(joint.site2)};")
    if joint.dofs:
        if connect:
            out.append(f"{pad1}type = {format_dofs(joint.dofs)};")
            if any(math.isfinite(d.lower) for d in joint.dofs):
                out.append(f"{pad1}lower_limits = {_dof_values(joint.dofs, 'lower')};")
            if any(math.isfinite(d.upper) for d in joint.dofs):
                out.append(f"{pad1}upper_limits = {_dof_values(joint.dofs, 'upper')};")
        out.append(f"{pad1}displacement = {_dof_values(joint.dofs, 'value')};")
    elif connect or not np.allclose(joint.displacement, np.eye(4)):
        out.append(f"{pad1}displacement = {format_transform(joint.displacement)};")
    out.append(f"{pad}}}")
    return out


def _root_ref(figure: Figure) -> str | None:
    root = figure.root
    if root is None or root.segment is None:
        return None
    return f"{root.segment.name}.{root.name}"


def _figure_lines(figure: Figure, level: int, base_dir: Path | None, protofiletype: bool) -> list[str]:
    pad, pad1 = INDENT * level, INDENT * (level + 1)
    out = [f"{pad}figure {figure.name} {{"]
    if protofiletype and figure.filename:
        out.append(f"{pad1}protofiletype = {_quote(figure.filename)};")
    for segment in figure.segments.values():
        out.extend(_segment_lines(segment, level + 1, base_dir))
    for joint in figure.joints.values():
        out.extend(_joint_lines(joint, level + 1))
    root = _root_ref(figure)
    if root is not None:
        out.append(f"{pad1}root = {root};")
    out.append(f"{pad1}location = {format_transform(figure.location)};")
    out.append(f"{pad}}}")
    return out


def format_figure(figure: Figure, base_dir: str | os.PathLike[str] | None = None) -> str:
    """A figure file's text.  With ``base_dir`` (where the file will live), psurfs loaded from known absolute
    paths are referenced relative to it; otherwise ``segment.psurf_file`` is written as it is."""
    base = None if base_dir is None else Path(base_dir).resolve()
    lines = [
        f"/* figure {figure.name}: {len(figure.segments)} segments, {len(figure.joints)} joints, "
        f"{figure.dof_count} DOFs (jack-ttes) */"
    ]
    lines.extend(_figure_lines(figure, 0, base, protofiletype=False))
    return "\n".join(lines) + "\n"


def write_figure(figure: Figure, path: str | os.PathLike[str]) -> None:
    p = Path(path)
    p.write_text(format_figure(figure, base_dir=p.parent), encoding="utf-8")


# --- environments -------------------------------------------------------------------------------------------


def format_environment(
    env: Environment, base_dir: str | os.PathLike[str] | None = None, *, inline: bool = False
) -> str:
    """An environment file's text (``WriteEnvironment``).

    Figures read from a figure file are written by reference (``file = ...``) plus their state: root,
    location and joint displacements (``WriteFigureLocation`` / ``WriteJointDisplacement``).  The reference is
    relative to ``base_dir`` when given, else the file's base name (resolved by the reader's search path).
    With ``inline=True``, or for figures with no file, the whole figure is written, keeping its
    ``protofiletype``.  Extension objects (``env.extensions``) are written by their registered writers.
    """
    from peabody.loader import block_writer

    base = None if base_dir is None else Path(base_dir).resolve()
    out = ["/* environment (jack-ttes) */"]
    world_sites = [
        s for name, s in env.world.sites.items() if name != "base" or not np.allclose(s.location, np.eye(4))
    ]
    if world_sites:
        out.append("segment world {")
        out.extend(f"{INDENT}site {s.name}->location = {format_transform(s.location)};" for s in world_sites)
        out.append("}")
    for figure in env.figures.values():
        if figure.source and not inline:
            ref = os.path.relpath(figure.source, base).replace(os.sep, "/") if base else figure.filename
            out.append(f"figure {figure.name} {{")
            out.append(f"{INDENT}file = {_quote(ref or figure.source)};")
            for joint in figure.joints.values():
                if joint.dofs or not np.allclose(joint.displacement, np.eye(4)):
                    out.extend(_joint_lines(joint, 1, connect=False))
            root = _root_ref(figure)
            if root is not None:
                out.append(f"{INDENT}root = {root};")
            out.append(f"{INDENT}location = {format_transform(figure.location)};")
            out.append("}")
        else:
            out.extend(_figure_lines(figure, 0, base, protofiletype=True))
    for keyword, objects in env.extensions.items():
        writer = block_writer(keyword)
        if writer is None:
            continue
        for name, obj in objects.items():
            out.append(writer(name, obj).rstrip("\n"))
    return "\n".join(out) + "\n"


def write_environment(env: Environment, path: str | os.PathLike[str], *, inline: bool = False) -> None:
    p = Path(path)
    p.write_text(format_environment(env, base_dir=p.parent, inline=inline), encoding="utf-8")


# --- comparison ---------------------------------------------------------------------------------------------


def _close(a: object, b: object, atol: float) -> bool:
    return bool(np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), atol=atol, rtol=0))


def _values_equal(a: object, b: object, atol: float) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    if isinstance(a, int | float | np.number) and isinstance(b, int | float | np.number):
        return (math.isinf(a) and a == b) or abs(float(a) - float(b)) <= atol
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        return a.shape == b.shape and _close(a, b, atol)
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return len(a) == len(b) and all(_values_equal(x, y, atol) for x, y in zip(a, b, strict=True))
    return L.strip_locations(a) == L.strip_locations(b)


def _limit_equal(a: float, b: float, atol: float) -> bool:
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= atol


def figure_differences(a: Figure, b: Figure, atol: float = 1e-5, *, psurfs: bool = True) -> list[str]:
    """Human-readable differences between two figures (empty when equal within ``atol``)."""
    diffs: list[str] = []
    if a.name != b.name:
        diffs.append(f"name {a.name!r} != {b.name!r}")
    if (a.filename or None) != (b.filename or None):
        diffs.append(f"filename {a.filename!r} != {b.filename!r}")
    if list(a.segments) != list(b.segments):
        diffs.append(f"segments {list(a.segments)} != {list(b.segments)}")
        return diffs
    for name, sa in a.segments.items():
        diffs += _segment_differences(name, sa, b.segments[name], atol, psurfs)
    if list(a.joints) != list(b.joints):
        diffs.append(f"joints {list(a.joints)} != {list(b.joints)}")
        return diffs
    for name, ja in a.joints.items():
        diffs += _joint_differences(name, ja, b.joints[name], atol)
    if _root_ref(a) != _root_ref(b):
        diffs.append(f"root {_root_ref(a)} != {_root_ref(b)}")
    if not _close(a.location, b.location, atol):
        diffs.append("location differs")
    return diffs


def _segment_differences(name: str, sa: Segment, sb: Segment, atol: float, psurfs: bool) -> list[str]:
    from peabody.psurf import psurfs_equal

    if list(sa.sites) != list(sb.sites):
        return [f"segment {name}: sites {list(sa.sites)} != {list(sb.sites)}"]
    diffs = [
        f"site {name}.{site_name}: location differs"
        for site_name, site in sa.sites.items()
        if not _close(site.location, sb.sites[site_name].location, atol)
    ]
    fa = sa.psurf.filename if sa.psurf is not None else None
    fb = sb.psurf.filename if sb.psurf is not None else None
    if fa and fb and os.path.isabs(fa) and os.path.isabs(fb):
        if Path(fa).resolve() != Path(fb).resolve():  # references may be relative to different folders
            diffs.append(f"segment {name}: psurf file {fa!r} != {fb!r}")
    elif sa.psurf_file != sb.psurf_file:
        diffs.append(f"segment {name}: psurf {sa.psurf_file!r} != {sb.psurf_file!r}")
    ta, tb = sa.psurf_transform, sb.psurf_transform
    if (ta is None) != (tb is None) or (ta is not None and not _close(ta, tb, atol)):
        diffs.append(f"segment {name}: psurf transform differs")
    if psurfs and (sa.psurf is None) != (sb.psurf is None):
        diffs.append(f"segment {name}: psurf loaded on one side only")
    elif psurfs and sa.psurf is not None and not psurfs_equal(sa.psurf, sb.psurf, atol):  # type: ignore[arg-type]
        diffs.append(f"segment {name}: psurf geometry differs")
    if set(sa.attributes) != set(sb.attributes):
        diffs.append(f"segment {name}: attributes {sorted(sa.attributes)} != {sorted(sb.attributes)}")
    else:
        diffs += [
            f"segment {name}: attribute {key} differs"
            for key, va in sa.attributes.items()
            if not _values_equal(va, sb.attributes[key], atol)
        ]
    return diffs


def _joint_differences(name: str, ja: Joint, jb: Joint, atol: float) -> list[str]:
    diffs = []
    if (_site_ref(ja.site1), _site_ref(ja.site2)) != (_site_ref(jb.site1), _site_ref(jb.site2)):
        diffs.append(f"joint {name}: connects different sites")
    if ja.ndofs != jb.ndofs:
        return [*diffs, f"joint {name}: {ja.ndofs} DOFs != {jb.ndofs}"]
    for k, (da, db) in enumerate(zip(ja.dofs, jb.dofs, strict=True)):
        if da.kind != db.kind or not _close(da.axis, db.axis, atol):
            diffs.append(f"joint {name}: DOF {k} axis/kind differs")
        if not (_limit_equal(da.lower, db.lower, atol) and _limit_equal(da.upper, db.upper, atol)):
            diffs.append(f"joint {name}: DOF {k} limits differ")
        if abs(da.value - db.value) > atol:
            diffs.append(f"joint {name}: DOF {k} value {da.value} != {db.value}")
    if not ja.dofs and not _close(ja.displacement, jb.displacement, atol):
        diffs.append(f"joint {name}: displacement differs")
    return diffs


def figures_equal(a: Figure, b: Figure, atol: float = 1e-5, *, psurfs: bool = True) -> bool:
    return not figure_differences(a, b, atol, psurfs=psurfs)


def environment_differences(a: Environment, b: Environment, atol: float = 1e-5) -> list[str]:
    diffs: list[str] = []
    if list(a.figures) != list(b.figures):
        return [f"figures {list(a.figures)} != {list(b.figures)}"]
    for name, fa in a.figures.items():
        diffs.extend(f"{name}: {d}" for d in figure_differences(fa, b.figures[name], atol))
    if list(a.world.sites) != list(b.world.sites):
        diffs.append(f"world sites {list(a.world.sites)} != {list(b.world.sites)}")
    else:
        for n, s in a.world.sites.items():
            if not _close(s.location, b.world.sites[n].location, atol):
                diffs.append(f"world site {n}: location differs")
    if set(a.extensions) != set(b.extensions):
        diffs.append(f"extensions {sorted(a.extensions)} != {sorted(b.extensions)}")
    return diffs


def environments_equal(a: Environment, b: Environment, atol: float = 1e-5) -> bool:
    return not environment_differences(a, b, atol)
