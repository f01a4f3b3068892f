"""The spitter: write a Peabody environment as a ``.tips`` file (seed 002, section 7; Jack's ``spit``).

A ``.tips`` file records a depth-first traversal of every figure, starting at its root site and following
joint connections, so an image generator can build its run-time scene graph without a Peabody parser.
The layout is section 7.1's, line for line; the seed's cube example (7.2) reproduces byte for byte.

Where the seed is silent we chose (and ``client_stub/stub/tips.py`` reads):

* Numbers are ``%f`` (six decimals); units are Jack's (cm, radians) and axes Jack's (+Y up, facing -Z):
  the file is a dump of the Peabody environment, the loader converts to Performer.
* A 4x4 matrix is four lines in Jack's and Performer's **row-vector** layout (translation in the fourth
  row), i.e. the transpose of our column-vector matrices.
* ``[DOF type]`` is ``R|T ax ay az lower upper``: the kind, the unit axis in the joint's frame and the
  joint limits (radians or cm; ``inf`` / ``-inf`` when unlimited), then the comment ``(dof)``.
* The comment before a joint's matrix reads ``JOINT #k``: k is the joint's place in the figure's joint list,
  i.e. in the project-wide pose vector (``peabody/fk.py``), which a traversal order does not keep.
* ``[ROOTJOINT FLAG]`` is always 0 (the traversal starts at the root site, so no joint leads to it);
  ``[REVERSE JOINT FLAG]`` is 1 when the traversal walks a joint from its site2 to its site1. The joint
  matrix is always the displacement from site1 to site2 (``D`` at the current DOF values).
* ``[OTHERSITE name]`` is qualified, ``segment.site``, which names the segment the joint leads to; the root
  segment's name is not in the format. Site names under ``[SITE]`` are plain, as in the seed.
* An attribute without an ``ambient`` colour gets a quarter of its diffuse (the seed's cube: 0.173333 =
  0.693333 / 4); specular defaults to black. A segment whose psurf has no attributes gets one grey
  attribute. Face colours are written black, as in the seed: the attributes carry the colour.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from peabody.model import Environment, Figure, Joint, Psurf, Segment, Site
from peabody.values import dofs_matrix

DEFAULT_DIFFUSE = (0.8, 0.8, 0.8)


def _f(x: float) -> str:
    """``%f`` as C's printf: six decimals, ``inf``/``-inf``, no negative zero."""
    x = float(x)
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    s = f"{x + 0.0:f}"
    return "0.000000" if s == "-0.000000" else s


def _vector(values: Iterable[float]) -> str:
    return " ".join(_f(v) for v in values)


def _matrix(m: np.ndarray) -> list[str]:
    """Four lines, row-vector layout (the transpose of our column-vector matrix)."""
    t = np.asarray(m, dtype=np.float64).T
    return [_vector(row) for row in t]


def _colour(entry: dict, key: str) -> tuple[float, float, float] | None:
    value = entry.get(key)
    if isinstance(value, tuple | list) and len(value) >= 3:
        return float(value[0]), float(value[1]), float(value[2])
    return None


def _attribute_lines(entry: dict) -> list[str]:
    diffuse = _colour(entry, "diffuse") or DEFAULT_DIFFUSE
    ambient = _colour(entry, "ambient") or tuple(c / 4.0 for c in diffuse)
    specular = _colour(entry, "specular") or (0.0, 0.0, 0.0)
    return [_vector(ambient), _vector(diffuse), _vector(specular), "0 (texture flag)"]


def _geometry_lines(psurf: Psurf) -> list[str]:
    nfaces = len(psurf.faces)
    face_attr = (
        np.zeros(nfaces, dtype=np.int64)
        if psurf.face_attributes is None
        else np.asarray(psurf.face_attributes, dtype=np.int64)
    )
    nattr = max(len(psurf.attributes), int(face_attr.max()) + 1 if nfaces else 0, 1)
    entries = [*psurf.attributes, *([{}] * (nattr - len(psurf.attributes)))]
    lines = [f"{nattr} (# attributes)"]
    for entry in entries:
        lines += _attribute_lines(entry or {})
    lines.append(f"{len(psurf.nodes)} total nodes")
    lines += [_vector(p) for p in np.asarray(psurf.nodes, dtype=np.float64)]
    lines.append(f"{nfaces} faces")
    for face, attr in zip(psurf.faces, face_attr, strict=True):
        lines.append(f"{int(attr)} attribnum")
        lines.append(f"{len(face)} vertices")
        lines.append(_vector((0.0, 0.0, 0.0)))
        lines += [str(int(i)) for i in face]
    return lines


class _Traversal:
    """Depth-first walk of one figure from its root site, writing section 7.1's segment descriptions."""

    def __init__(self, figure: Figure) -> None:
        self.figure = figure
        self.pose_index = {name: k for k, name in enumerate(figure.joints)}
        self.used: set[str] = set()
        self.at_site: dict[int, list[Joint]] = {}
        for joint in figure.joints.values():
            self.at_site.setdefault(id(joint.site1), []).append(joint)
            self.at_site.setdefault(id(joint.site2), []).append(joint)

    def segment(self, segment: Segment) -> list[str]:
        lines: list[str] = []
        if segment.psurf is not None:
            lines.append("1 (psurf flag)")
            lines += _geometry_lines(segment.psurf)
        else:
            lines.append("0 (psurf flag)")
        sites = list(segment.sites.values())
        lines.append(f"{len(sites)} sites")
        for number, site in enumerate(sites, start=1):
            children = [j for j in self.at_site.get(id(site), []) if j.name not in self.used]
            self.used.update(j.name for j in children)
            lines.append(f"{len(children)} joints")
            lines += ["SITE", site.name, f"Site {number} matrix", *_matrix(site.location)]
            for joint in children:
                lines += self.joint(joint, site)
        return lines

    def joint(self, joint: Joint, near: Site) -> list[str]:
        reverse = near is joint.site2 and near is not joint.site1
        far = joint.site1 if reverse else joint.site2
        if far.segment is None:
            raise ValueError(f"joint {joint.name!r}: site {far.name!r} has no segment")
        lines = ["0 (rootjoint flag)", f"JOINT #{self.pose_index[joint.name]}"]
        lines += _matrix(_displacement(joint))
        lines.append(f"{int(reverse)} (reverse flag)")
        lines.append(f"{len(joint.dofs)} dofs")
        for dof in joint.dofs:
            lines.append(f"{dof.kind} {_vector(dof.axis)} {_f(dof.lower)} {_f(dof.upper)} (dof)")
        lines += ["JOINT NAME", joint.name, "OTHERSITE", f"{far.segment.name}.{far.name}"]
        lines += ["Othersite inverse matrix", *_matrix(np.linalg.inv(far.location))]
        lines += self.segment(far.segment)
        return lines


def _displacement(joint: Joint) -> np.ndarray:
    """The joint's current site1 -> site2 transform: ``D = dof[0] @ dof[1] @ ...`` or the fixed one."""
    if not joint.dofs:
        return np.asarray(joint.displacement, dtype=np.float64)
    return dofs_matrix(joint.dofs)


def format_figure_tips(figure: Figure, number: int) -> list[str]:
    root = figure.root
    if root is None:
        sites = figure.sites()
        if not sites:
            raise ValueError(f"figure {figure.name!r} has no sites")
        root = sites[0]
    if root.segment is None:
        raise ValueError(f"figure {figure.name!r}: root site has no segment")
    lines = [f"FIGURE #{number}", figure.name, f"FIGURE #{number}", figure.filename or f"{figure.name}.fig"]
    lines += ["Global position matrix", *_matrix(figure.location)]
    lines += ["Root site inverse matrix", *_matrix(np.linalg.inv(root.location))]
    traversal = _Traversal(figure)
    lines += traversal.segment(root.segment)
    if len(traversal.used) != len(figure.joints):
        missing = sorted(set(figure.joints) - traversal.used)
        raise ValueError(f"figure {figure.name!r}: joints {missing} are not reachable from the root site")
    return lines


def format_tips(env: Environment) -> str:
    """The ``.tips`` text of every figure of ``env`` (Jack's ``spit``; an environment has no cameras)."""
    figures = list(env.figures.values())
    lines = [f"{len(figures)} figures"]
    for number, figure in enumerate(figures):
        lines += format_figure_tips(figure, number)
    return "\n".join(lines) + "\n"


def load_for_spit(paths: Iterable[str | os.PathLike[str]]) -> Environment:
    """One environment holding every figure of the given ``.fig`` and ``.env`` files, in order."""
    from peabody.loader import read_environment, read_figure

    env = Environment()
    for path in paths:
        p = Path(path)
        if p.suffix == ".fig":
            figure = read_figure(p)
            env.add_figure(figure)
        else:
            read_environment(p, env)
    return env


def spit(paths: Iterable[str | os.PathLike[str]], out: str | os.PathLike[str]) -> Environment:
    """``spit("file.tips")``: write the figures of the given files to ``out``; returns what was written."""
    env = load_for_spit(paths)
    Path(out).write_text(format_tips(env), encoding="utf-8")
    return env
