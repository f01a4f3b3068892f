"""Reading figure (``.fig``) and environment (``.env``) files into the model (seed 000, 7.5).

Figure files hold exactly one ``figure NAME { ... }`` block (``docs/PEABODY.md`` has the full syntax).
Environment files hold any of::

    figure Di2_0 { file = "DI.fig"; root = lower_torso.proximal; location = trans(0cm, 0cm, 500cm); }
    figure Di2_0 { joint waist { displacement = (0deg, 10deg, 0deg); } }   // re-opens the figure
    joint Di2_0.waist { displacement = (0deg, 10deg, 0deg); }               // same, addressed by full name
    figure cube { segment box { psurf = "cube.pss"; site base->location = trans(0,0,0); } }   // inline
    segment world { site dock->location = trans(100cm, 0cm, 0cm); }          // sites on the world
    connect world.dock to cube.box.base;       // root cube at box.base and put that site on world.dock
    include "other.env";
    channelset walk { ... }                    // handed to the handler registered for "channelset"

As in Jack, a block names a construct and creates it on first reference; a later block with the same name
re-opens it (so a file can be read twice).  Defining the same construct twice *within one body*, or the
same field twice in one block, is an error.  Unknown keywords are errors unless :func:`register_block`
registered a handler for them (the ``DefinePeabodyBlock`` extension point).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from peabody import values as V
from peabody.language import (
    Assign,
    BinOp,
    Block,
    Loc,
    Name,
    PeabodyError,
    Statement,
    Stmt,
    String,
    Value,
    parse,
)
from peabody.model import Environment, Figure, Joint, Psurf, Segment, Site

BlockHandler = Callable[[Block, Environment, "LoadContext"], None]
BlockWriter = Callable[[str, object], str]


@dataclass
class _Extension:
    handler: BlockHandler
    writer: BlockWriter | None


_EXTENSIONS: dict[str, _Extension] = {}
RESERVED = frozenset({"figure", "segment", "site", "joint", "connect", "include", "world"})
MAX_INCLUDE_DEPTH = 16


def register_block(keyword: str, handler: BlockHandler, writer: BlockWriter | None = None) -> None:
    """Hand top-level ``keyword NAME { ... }`` blocks to ``handler(block, env, ctx)``.

    The handler stores what it builds under ``env.extensions[keyword][name]``.  ``writer(name, obj)``, when
    given, returns the Peabody text for one stored object so :func:`format_environment` can write it back.
    Exceptions other than :class:`PeabodyError` raised by a handler are reported at the block's location.
    """
    if keyword in RESERVED:
        raise ValueError(f"{keyword!r} is a built-in Peabody keyword")
    _EXTENSIONS[keyword] = _Extension(handler, writer)


def unregister_block(keyword: str) -> None:
    _EXTENSIONS.pop(keyword, None)


def block_writer(keyword: str) -> BlockWriter | None:
    ext = _EXTENSIONS.get(keyword)
    return None if ext is None else ext.writer


@dataclass
class LoadContext:
    """Where the text being loaded came from, and caches shared by nested loads (figure files, psurfs)."""

    filename: str = "<string>"
    base_dir: Path = field(default_factory=Path.cwd)
    search_path: tuple[Path, ...] = ()
    load_psurfs: bool = True
    depth: int = 0
    parsed: dict[Path, list[Stmt]] = field(default_factory=dict)
    psurfs: dict[tuple[Path, bytes], Psurf] = field(default_factory=dict)

    def child(self, path: Path) -> LoadContext:
        return LoadContext(
            str(path),
            path.parent,
            self.search_path,
            self.load_psurfs,
            self.depth + 1,
            self.parsed,
            self.psurfs,
        )

    def resolve(self, name: str, loc: Loc, what: str) -> Path:
        """A file named in the text: relative to the file's folder, then the search path."""
        for folder in (self.base_dir, *self.search_path):
            try:
                candidate = (folder / name).resolve()
                if candidate.is_file():
                    return candidate
            except (OSError, ValueError):  # unrepresentable or over-long names
                continue
        raise PeabodyError.at(loc, f"cannot find {what} {name!r} (looked in {self.base_dir})")

    def parse_file(self, path: Path, loc: Loc | None) -> list[Stmt]:
        stmts = self.parsed.get(path)
        if stmts is None:
            stmts = parse(_read_text(path, loc), str(path))
            self.parsed[path] = stmts
        return stmts


def _read_text(path: Path, loc: Loc | None = None) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        if loc is None:
            raise
        raise PeabodyError.at(loc, f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise PeabodyError(str(path), line, col, "not UTF-8 text") from None


# --- public entry points ------------------------------------------------------------------------------------


def read_figure(
    path: str | os.PathLike[str],
    name: str | None = None,
    *,
    load_psurfs: bool = True,
    search_path: Iterable[str | os.PathLike[str]] = (),
) -> Figure:
    """``ReadFigure``: build the figure defined in a ``.fig`` file, optionally under a new name."""
    p = Path(path).resolve()
    ctx = LoadContext(str(path), p.parent, tuple(Path(s) for s in search_path), load_psurfs)
    stmts = ctx.parse_file(p, None)
    return _figure_from_file(stmts, ctx, name, p)


def read_environment(
    path: str | os.PathLike[str],
    env: Environment | None = None,
    *,
    load_psurfs: bool = True,
    search_path: Iterable[str | os.PathLike[str]] = (),
) -> Environment:
    """``ReadEnvironment``: load an environment file (into ``env``, or a new environment)."""
    p = Path(path).resolve()
    text = _read_text(p)
    return load_text(text, env, str(path), p.parent, load_psurfs=load_psurfs, search_path=search_path)


def load_text(
    text: str,
    env: Environment | None = None,
    filename: str = "<string>",
    base_dir: str | os.PathLike[str] | None = None,
    *,
    load_psurfs: bool = True,
    search_path: Iterable[str | os.PathLike[str]] = (),
) -> Environment:
    """``ReadPeabodyString``: load environment text; files it names resolve against ``base_dir``."""
    env = Environment() if env is None else env
    base = Path.cwd() if base_dir is None else Path(base_dir)
    ctx = LoadContext(filename, base, tuple(Path(s) for s in search_path), load_psurfs)
    _load_statements(parse(text, filename), env, ctx)
    return env


# --- environment level --------------------------------------------------------------------------------------


def _load_statements(stmts: list[Stmt], env: Environment, ctx: LoadContext) -> None:
    for stmt in stmts:
        if isinstance(stmt, Block):
            _env_block(stmt, env, ctx)
        elif isinstance(stmt, Statement) and stmt.keyword == "connect":
            _env_connect(stmt, env)
        elif isinstance(stmt, Statement) and stmt.keyword == "include":
            _include(stmt, env, ctx)
        elif isinstance(stmt, Assign) and stmt.owner is not None:
            _env_block(Block(stmt.owner[0], stmt.owner[1], (_unowned(stmt),), stmt.loc), env, ctx)
        else:
            what = stmt.target if isinstance(stmt, Assign) else stmt.keyword
            raise PeabodyError.at(stmt.loc, f"unknown top-level statement {what!r}")


def _unowned(stmt: Assign) -> Assign:
    return Assign(stmt.target, stmt.index, stmt.value, stmt.loc)


def _env_block(block: Block, env: Environment, ctx: LoadContext) -> None:
    kw = block.keyword
    if kw == "figure":
        _env_figure(block, env, ctx)
    elif kw == "joint":
        fig_name, _, joint_name = block.name.partition(".")
        figure = _existing_figure(env, fig_name, block.loc)
        if not joint_name or "." in joint_name:
            raise PeabodyError.at(block.loc, f"expected joint FIGURE.JOINT, found {block.name!r}")
        _joint_block(block, figure, joint_name)
        _finish_figure(figure, block.loc)
    elif kw == "segment":
        if block.name == "world":
            _segment_body(block, env.world, ctx, world=True)
            return
        fig_name, _, seg_name = block.name.partition(".")
        figure = _existing_figure(env, fig_name, block.loc)
        if not seg_name or "." in seg_name:
            raise PeabodyError.at(
                block.loc, f"expected segment FIGURE.SEGMENT or world, found {block.name!r}"
            )
        _segment_block(block, figure, seg_name, ctx)
        _finish_figure(figure, block.loc)
    elif kw in _EXTENSIONS:
        try:
            _EXTENSIONS[kw].handler(block, env, ctx)
        except PeabodyError:
            raise
        except (ValueError, KeyError, TypeError, IndexError, ArithmeticError) as exc:
            raise PeabodyError.at(block.loc, f"in {kw} {block.name!r}: {exc}") from exc
    else:
        raise PeabodyError.at(block.loc, f"unknown block keyword {kw!r} (no handler registered)")


def _existing_figure(env: Environment, name: str, loc: Loc) -> Figure:
    figure = env.figures.get(name)
    if figure is None:
        raise PeabodyError.at(loc, f"no figure named {name!r}")
    return figure


def _env_figure(block: Block, env: Environment, ctx: LoadContext) -> None:
    name = block.name
    _plain_name(name, block.loc, "figure")
    body = list(block.body)
    file_assign = next((s for s in body if isinstance(s, Assign) and s.target == "file"), None)
    if file_assign is not None:
        if name in env.figures:
            raise PeabodyError.at(block.loc, f"figure {name!r} already exists")
        path = ctx.resolve(_string(file_assign.value), file_assign.loc, "figure file")
        stmts = ctx.parse_file(path, file_assign.loc)
        figure = _figure_from_file(stmts, ctx.child(path), name, path)
        body.remove(file_assign)
        env.add_figure(figure)
        reopened = True
    else:
        reopened = name in env.figures
        figure = env.figures.get(name) or env.add_figure(Figure(name))
    _figure_body(block, tuple(body), figure, ctx, keep_in_place=reopened)


def _env_connect(stmt: Statement, env: Environment) -> None:
    a, b = _connect_args(stmt)
    target_global = _env_site_global(env, a, stmt.args[0].loc)
    fig_name, _, local = b.partition(".")
    figure = _existing_figure(env, fig_name, stmt.args[2].loc)
    site = _find_site(figure, local, stmt.args[2].loc)
    if a.partition(".")[0] == fig_name:
        raise PeabodyError.at(stmt.loc, "connect: both sites are on the same figure (use a joint)")
    figure.root = site
    figure.location = target_global
    _finish_figure(figure, stmt.loc)


def _env_site_global(env: Environment, dotted: str, loc: Loc) -> np.ndarray:
    head, _, rest = dotted.partition(".")
    if head == "world":
        site = env.world.sites.get(rest)
        if site is None:
            raise PeabodyError.at(loc, f"the world has no site {rest!r}")
        return site.location.copy()
    figure = _existing_figure(env, head, loc)
    _find_site(figure, rest, loc)
    from peabody.fk import FigureKinematics

    try:
        return FigureKinematics(figure).site_global(rest)
    except ValueError as exc:
        raise PeabodyError.at(loc, str(exc)) from None


def _include(stmt: Statement, env: Environment, ctx: LoadContext) -> None:
    if len(stmt.args) != 1:
        raise PeabodyError.at(stmt.loc, "include takes one file name")
    if ctx.depth >= MAX_INCLUDE_DEPTH:
        raise PeabodyError.at(stmt.loc, f"includes nested deeper than {MAX_INCLUDE_DEPTH}")
    path = ctx.resolve(_string(stmt.args[0]), stmt.loc, "included file")
    child = ctx.child(path)
    _load_statements(parse(_read_text(path, stmt.loc), str(path)), env, child)


# --- figures ------------------------------------------------------------------------------------------------


def _figure_from_file(stmts: list[Stmt], ctx: LoadContext, name: str | None, path: Path) -> Figure:
    blocks = [s for s in stmts if isinstance(s, Block) and s.keyword == "figure"]
    others = [s for s in stmts if not (isinstance(s, Block) and s.keyword == "figure")]
    if others:
        raise PeabodyError.at(others[0].loc, "a figure file holds only one figure block")
    if len(blocks) != 1:
        loc = blocks[1].loc if blocks else Loc(str(path), 1, 1)
        raise PeabodyError.at(loc, f"a figure file holds exactly one figure block, found {len(blocks)}")
    block = blocks[0]
    figure = Figure(name or block.name)
    _plain_name(figure.name, block.loc, "figure")
    _figure_body(block, block.body, figure, ctx, keep_in_place=False)
    figure.filename = path.name
    figure.source = str(path)
    return figure


def _figure_body(
    block: Block, body: tuple[Stmt, ...], figure: Figure, ctx: LoadContext, keep_in_place: bool
) -> None:
    seen_blocks: dict[tuple[str, str], Loc] = {}
    fields: dict[str, Assign] = {}
    for stmt in body:
        if isinstance(stmt, Assign) and stmt.owner is not None:
            stmt = Block(stmt.owner[0], stmt.owner[1], (_unowned(stmt),), stmt.loc)
            nested = True
        else:
            nested = False
        if isinstance(stmt, Block):
            key = (stmt.keyword, stmt.name)
            if key in seen_blocks and not nested:
                raise PeabodyError.at(stmt.loc, f"{stmt.keyword} {stmt.name!r} defined twice in this figure")
            if not nested:
                seen_blocks[key] = stmt.loc
            if stmt.keyword == "segment":
                _plain_name(stmt.name, stmt.loc, "segment")
                _segment_block(stmt, figure, stmt.name, ctx)
            elif stmt.keyword == "joint":
                _plain_name(stmt.name, stmt.loc, "joint")
                _joint_block(stmt, figure, stmt.name)
            else:
                raise PeabodyError.at(stmt.loc, f"unknown block {stmt.keyword!r} in a figure")
        elif isinstance(stmt, Assign):
            _no_index(stmt)
            if stmt.target not in ("root", "location", "protofiletype"):
                raise PeabodyError.at(stmt.loc, f"unknown figure field {stmt.target!r}")
            _once(fields, stmt)
        else:
            raise PeabodyError.at(stmt.loc, f"unexpected {stmt.keyword!r} statement in a figure")
    if "protofiletype" in fields:
        figure.filename = _string(fields["protofiletype"].value)
    location = V.transform(fields["location"].value) if "location" in fields else None
    if "root" in fields:
        a = fields["root"]
        site = _find_site(figure, _string(a.value), a.value.loc)
        if keep_in_place and location is None and figure.root is not None and site is not figure.root:
            # SetFigureRoot: the figure must not move
            from peabody.fk import FigureKinematics

            try:
                location = FigureKinematics(figure).site_global(f"{site.segment.name}.{site.name}")  # type: ignore[union-attr]
            except ValueError as exc:
                raise PeabodyError.at(a.loc, str(exc)) from None
        figure.root = site
    if location is not None:
        figure.location = location
    _finish_figure(figure, block.loc)


def _finish_figure(figure: Figure, loc: Loc) -> None:
    """Default root (first site of the first segment) and the tree check: connected, no loops."""
    if figure.root is None:
        for seg in figure.segments.values():
            if seg.sites:
                figure.root = next(iter(seg.sites.values()))
                break
    if not figure.segments:
        return
    if figure.root is None:
        raise PeabodyError.at(loc, f"figure {figure.name!r} has no sites, so it has no root")
    from peabody.fk import FigureKinematics

    try:
        FigureKinematics(figure)
    except ValueError as exc:
        raise PeabodyError.at(loc, str(exc)) from None


def _segment_block(block: Block, figure: Figure, name: str, ctx: LoadContext) -> None:
    segment = figure.segments.get(name) or figure.add_segment(Segment(name))
    _segment_body(block, segment, ctx, world=False)


def _segment_body(block: Block, segment: Segment, ctx: LoadContext, world: bool) -> None:
    seen_sites: dict[str, Loc] = {}
    fields: dict[str, Assign] = {}
    for stmt in block.body:
        if isinstance(stmt, Assign) and stmt.owner is not None:
            if stmt.owner[0] != "site":
                raise PeabodyError.at(stmt.loc, f"unexpected {stmt.owner[0]!r} in a segment")
            stmt = Block("site", stmt.owner[1], (_unowned(stmt),), stmt.loc)
        if isinstance(stmt, Block):
            if stmt.keyword != "site":
                raise PeabodyError.at(stmt.loc, f"unknown block {stmt.keyword!r} in a segment")
            _plain_name(stmt.name, stmt.loc, "site")
            if stmt.name in seen_sites:
                raise PeabodyError.at(
                    stmt.loc, f"site {stmt.name!r} defined twice in segment {segment.name!r}"
                )
            seen_sites[stmt.name] = stmt.loc
            site = segment.sites.get(stmt.name) or segment.add_site(Site(stmt.name))
            _site_body(stmt, site)
        elif isinstance(stmt, Assign):
            _no_index(stmt)
            _once(fields, stmt)
        else:
            raise PeabodyError.at(stmt.loc, f"unexpected {stmt.keyword!r} statement in a segment")
    for target, a in fields.items():
        if world:
            raise PeabodyError.at(a.loc, "the world segment has only sites")
        if target == "psurf":
            _assign_psurf(a, segment, ctx)
        else:
            segment.attributes[target] = V.to_python(a.value)


def _site_body(block: Block, site: Site) -> None:
    fields: dict[str, Assign] = {}
    for stmt in block.body:
        if not isinstance(stmt, Assign) or stmt.owner is not None:
            raise PeabodyError.at(stmt.loc, "a site block holds only 'location = ...;'")
        _no_index(stmt)
        if stmt.target != "location":
            raise PeabodyError.at(stmt.loc, f"unknown site field {stmt.target!r}")
        _once(fields, stmt)
        site.location = V.transform(stmt.value)


def _assign_psurf(a: Assign, segment: Segment, ctx: LoadContext) -> None:
    value: Value = a.value
    transform: np.ndarray | None = None

    if isinstance(value, BinOp) and value.op == "*":  # "x.pss" * scale(...) * ...
        parts: list[Value] = []
        node: Value = value
        while isinstance(node, BinOp) and node.op == "*":
            parts.append(node.right)
            node = node.left
        if not isinstance(node, String | Name):
            raise PeabodyError.at(node.loc, 'expected psurf = "file.pss" [* transform]')
        product: Value = parts[-1]
        for p in reversed(parts[:-1]):
            product = BinOp("*", product, p, p.loc)
        transform = V.transform(product)
        value = node
    file = _string(value)
    segment.psurf_file = file
    segment.psurf_transform = transform
    segment.psurf = None
    if ctx.load_psurfs:
        segment.psurf = _load_psurf(file, transform, a.loc, ctx)


def _load_psurf(file: str, transform: np.ndarray | None, loc: Loc, ctx: LoadContext) -> Psurf:
    from peabody.psurf import read_psurf, transform_psurf

    path = ctx.resolve(file, loc, "psurf")
    key = (path, b"" if transform is None else transform.tobytes())
    cached = ctx.psurfs.get(key)
    if cached is not None:
        return cached
    base = ctx.psurfs.get((path, b""))
    if base is None:
        try:
            base = read_psurf(path)
        except OSError as exc:
            raise PeabodyError.at(loc, f"cannot read psurf {path}: {exc.strerror or exc}") from None
        ctx.psurfs[(path, b"")] = base
    psurf = base if transform is None else transform_psurf(base, transform)
    ctx.psurfs[key] = psurf
    return psurf


# --- joints -------------------------------------------------------------------------------------------------


def _joint_block(block: Block, figure: Figure, name: str) -> None:
    fields, connect = _joint_statements(block, name)
    joint = figure.joints.get(name)
    if connect is not None:
        joint = _connect(figure, name, connect, joint)
    if joint is None:
        raise PeabodyError.at(block.loc, f"joint {name!r} has no 'connect SITE to SITE;'")
    _joint_fields(joint, fields, name)


def _joint_statements(block: Block, name: str) -> tuple[dict[str, Assign], Statement | None]:
    """A joint block's fields (each at most once) and its ``connect`` statement."""
    fields: dict[str, Assign] = {}
    connect: Statement | None = None
    for stmt in block.body:
        if isinstance(stmt, Statement) and stmt.keyword == "connect":
            if connect is not None:
                raise PeabodyError.at(stmt.loc, f"joint {name!r} connected twice")
            connect = stmt
        elif isinstance(stmt, Assign) and stmt.owner is None:
            _no_index(stmt)
            if stmt.target not in ("type", "displacement", "lower_limits", "upper_limits"):
                raise PeabodyError.at(stmt.loc, f"unknown joint field {stmt.target!r}")
            _once(fields, stmt)
        else:
            what = stmt.keyword if isinstance(stmt, Block | Statement) else stmt.target
            raise PeabodyError.at(stmt.loc, f"unexpected {what!r} in a joint")
    return fields, connect


def _connect(figure: Figure, name: str, connect: Statement, joint: Joint | None) -> Joint:
    """``connect SITE to SITE;``: a new joint, or an existing one connected anew."""
    a, b = _connect_args(connect)
    s1 = _find_site(figure, a, connect.args[0].loc)
    s2 = _find_site(figure, b, connect.args[2].loc)
    if s1.segment is s2.segment:
        raise PeabodyError.at(connect.loc, "a joint connects sites on two different segments")
    if joint is None:
        return figure.add_joint(Joint(name, s1, s2))
    joint.site1, joint.site2 = s1, s2
    return joint


def _joint_fields(joint: Joint, fields: dict[str, Assign], name: str) -> None:
    """The joint's ``type`` (its DOFs), then limits and displacement, which depend on the DOF count."""
    if "type" in fields:
        try:
            joint.dofs = V.dofs(fields["type"].value)
        except PeabodyError as exc:
            raise PeabodyError(exc.file, exc.line, exc.column, f"bad DOF spec: {exc.message}") from None
    n = joint.ndofs
    for target, attr in (("lower_limits", "lower"), ("upper_limits", "upper")):
        if target in fields:
            if n == 0:
                raise PeabodyError.at(fields[target].loc, f"joint {name!r} has no DOFs to limit")
            vals = V.numbers(
                fields[target].value, n, f"{target.replace('_', ' ')} (one per DOF)", finite=False
            )
            for d, v in zip(joint.dofs, vals, strict=True):
                setattr(d, attr, v)
    if "displacement" in fields:
        disp = fields["displacement"]
        if n == 0:
            joint.displacement = V.transform(disp.value)
        else:
            vals = V.numbers(disp.value, n, "displacement values (one per DOF)")
            for d, v in zip(joint.dofs, vals, strict=True):
                d.value = v


def _connect_args(stmt: Statement) -> tuple[str, str]:
    args = stmt.args
    if len(args) != 3 or not (isinstance(args[1], Name) and args[1].name == "to"):
        raise PeabodyError.at(stmt.loc, "expected 'connect SITE to SITE;'")
    return _string(args[0]), _string(args[2])


def _find_site(figure: Figure, dotted: str, loc: Loc) -> Site:
    seg_name, dot, site_name = dotted.partition(".")
    segment = figure.segments.get(seg_name)
    if not dot or "." in site_name:
        raise PeabodyError.at(loc, f"expected SEGMENT.SITE, found {dotted!r}")
    if segment is None:
        raise PeabodyError.at(loc, f"figure {figure.name!r} has no segment {seg_name!r}")
    site = segment.sites.get(site_name)
    if site is None:
        raise PeabodyError.at(loc, f"segment {figure.name}.{seg_name} has no site {site_name!r}")
    return site


# --- small helpers ------------------------------------------------------------------------------------------


def _string(node: Value) -> str:
    if isinstance(node, String | Name):
        return node.value if isinstance(node, String) else node.name
    raise PeabodyError.at(node.loc, f"expected a string or a name, found {V.describe(node)}")


_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _plain_name(name: str, loc: Loc, what: str) -> None:
    if not _IDENTIFIER.fullmatch(name):
        raise PeabodyError.at(loc, f"bad {what} name {name!r}")


def _no_index(stmt: Assign) -> None:
    if stmt.index is not None:
        raise PeabodyError.at(stmt.loc, f"field {stmt.target!r} takes no index")


def _once(fields: dict[str, Assign], stmt: Assign) -> None:
    if stmt.target in fields:
        raise PeabodyError.at(stmt.loc, f"{stmt.target!r} assigned twice in this block")
    fields[stmt.target] = stmt
