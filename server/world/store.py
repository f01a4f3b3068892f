"""The loaded data of one server: the Peabody environment, channelsets, posture graphs and what is bound.

Seed 002, 3.4.1-3.4.2 and 3.6: ``read_file`` of an ``.env`` adds figures; ``load_channelset`` and
``load_posture_graph`` (which loads the graph's channelsets too) fill the named tables; ``bind_channelset``
and ``bind_posture_graph`` bind them to figures of the environment. The bound tables are read: the motion
library takes its figure sets from the bound posture graphs (:mod:`server.world.library`), and the JCL
commands ``play_bound_channelset``, ``step_bound_channelset``, ``write_channelset`` and ``posture_change`` act
on what is bound. Loading the same file again (the start-up script run twice) is a no-op, and loading it under
another name shares the loaded object: files are keyed by resolved path, size and modification time, so a JCL
frame that loads one graph under a thousand names costs a thousand dictionary entries, not a thousand copies
(issue 17). The names are bounded too (:data:`MAX_CHANNELSETS`, :data:`MAX_GRAPHS`): a load past the limit is
a StoreError saying so. Channelset caches go to ``cache_dir`` (None: :func:`server.motion.cache.cache_dir`).

Errors are :class:`StoreError` (a ``ValueError``); the JCL adapter turns them into located JCL errors.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from peabody.model import Environment, Figure
from server.logging import get_logger
from server.motion.binding import BoundChannelset, bind_channelset
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from server.motion.errors import BindingError, ChannelsetError, PostureGraphError
from server.motion.posture_change import (
    BoundPostureGraph,
    LoadedPostureGraph,
    bind_posture_graph,
    load_posture_graph,
)

log = get_logger("store")
T = TypeVar("T")
MAX_CHANNELSETS = 4096  # names in the channelset table (the shipped library loads 171)
MAX_GRAPHS = 256  # names in the posture graph table (the shipped library loads 21)
FileKey = tuple[str, int, int]  # resolved path, size, mtime_ns: the same file unchanged


def file_key(path: Path) -> FileKey:
    """What identifies a loaded file: its resolved path and its size and modification time now."""
    st = path.stat()
    return (str(path.resolve()), st.st_size, st.st_mtime_ns)


class StoreError(ValueError):
    """A file that cannot be read, a name that is not loaded, figures that do not fit."""


@dataclass
class MotionStore:
    """Figures, channelsets and posture graphs by name, loaded and bound."""

    environment: Environment = field(default_factory=Environment)
    env_files: set[Path] = field(default_factory=set)
    channelsets: dict[str, Channelset] = field(default_factory=dict)
    graphs: dict[str, LoadedPostureGraph] = field(default_factory=dict)
    graph_paths: dict[str, Path] = field(default_factory=dict)
    bound_channelsets: dict[str, BoundChannelset] = field(default_factory=dict)
    bound_graphs: dict[str, BoundPostureGraph] = field(default_factory=dict)
    cache_dir: Path | None = None  # channelset caches (None: the user's cache directory)
    max_channelsets: int = MAX_CHANNELSETS
    max_graphs: int = MAX_GRAPHS
    loaded_files: dict[FileKey, Channelset | LoadedPostureGraph] = field(default_factory=dict)

    # -- loading -----------------------------------------------------------------------------------------
    def read_env(self, path: Path, search_path: Sequence[Path] = ()) -> None:
        """The figures of an ``.env`` file (once per file; a ``.chset.env`` is a channelset)."""
        if path.name.endswith(".chset.env"):
            self.load_channelset(path)
            return
        if path in self.env_files:  # the start-up script run again: the figures are there already
            log.debug("env_already_read", file=str(path))
            return
        from peabody.language import PeabodyError
        from peabody.loader import read_environment

        try:
            read_environment(path, self.environment, load_psurfs=False, search_path=list(search_path))
        except PeabodyError as exc:
            raise StoreError(str(exc)) from None
        self.env_files.add(path)
        log.info("environment_read", file=path.name, figures=len(self.environment.figures))

    def load_channelset(self, path: Path, name: str | None = None) -> Channelset:
        """A channelset file under its own name or ``name``; the same file again shares the loaded one."""
        _room(self.channelsets, name, 1, self.max_channelsets, "channelsets")
        try:
            cs = self._channelset_file(path)
        except (ChannelsetError, OSError) as exc:
            raise StoreError(str(exc)) from None
        _room(self.channelsets, name or cs.name, 1, self.max_channelsets, "channelsets")
        self.channelsets[name or cs.name] = cs
        return cs

    def _channelset_file(self, path: Path) -> Channelset:
        """The channelset of a file: the one loaded before when the file is unchanged, else read now."""
        key = file_key(path)
        cs = self.loaded_files.get(key)
        if not isinstance(cs, Channelset):
            cs = load_channelset(path, directory=self.cache_dir)
            self.loaded_files[key] = cs
        return cs

    def load_graph(self, path: Path, name: str | None = None) -> LoadedPostureGraph:
        """A posture graph and its channelsets (registered by their names too, as Jack did); the same file
        again (under any name) shares the loaded graph and its channelsets."""
        key = name or path.stem
        if key in self.graphs and self.graph_paths.get(key) == path:
            return self.graphs[key]  # the start-up script run again
        _room(self.graphs, key, 1, self.max_graphs, "posture graphs")
        try:
            fkey = file_key(path)
            loaded = self.loaded_files.get(fkey)
            if isinstance(loaded, LoadedPostureGraph):  # same graph and channelsets, its own name
                loaded = dataclasses.replace(loaded, name=key)
            else:
                loaded = load_posture_graph(path, key, loader=self._channelset_file)
        except (PostureGraphError, ChannelsetError, OSError) as exc:
            raise StoreError(str(exc)) from None
        new = [cs.name for cs in loaded.channelsets if cs.name not in self.channelsets]
        _room(self.channelsets, None, len(new), self.max_channelsets, "channelsets")
        self.loaded_files[fkey] = loaded
        self.graphs[key] = loaded
        self.graph_paths[key] = path
        for cs in loaded.channelsets:
            self.channelsets.setdefault(cs.name, cs)
        log.info(
            "posture_graph_loaded",
            graph=key,
            postures=len(loaded.graph.postures),
            channelsets=len(loaded.channelsets),
        )
        return loaded

    # -- lookups -----------------------------------------------------------------------------------------
    def figures(self, names: Sequence[str]) -> list[Figure]:
        missing = [n for n in names if n not in self.environment.figures]
        if missing:
            raise StoreError(f"no figure(s) {missing} in the environment")
        return [self.environment.figures[n] for n in names]

    def channelset(self, name: str) -> Channelset:
        return _named(self.channelsets, name, "channelset", "loaded")

    def graph(self, name: str) -> LoadedPostureGraph:
        return _named(self.graphs, name, "posture graph", "loaded")

    def bound_channelset(self, name: str) -> BoundChannelset:
        return _named(self.bound_channelsets, name, "bound channelset", "(bind_channelset first)")

    def bound_graph(self, name: str) -> BoundPostureGraph:
        return _named(self.bound_graphs, name, "bound posture graph", "(bind_posture_graph first)")

    # -- binding -----------------------------------------------------------------------------------------
    def bind_channelset(self, chset: str, name: str, figures: Sequence[str]) -> BoundChannelset:
        """Bind a loaded channelset to figures (all of the environment's if none are named)."""
        cs = self.channelset(chset)
        figs = self.figures(figures) if figures else list(self.environment.figures.values())
        try:
            bound = bind_channelset(cs, figs, name or f"{chset}/bound")
        except BindingError as exc:
            raise StoreError(str(exc)) from None
        self.bound_channelsets[bound.name] = bound
        return bound

    def bind_posture_graph(self, graph: str, name: str, figures: Sequence[str]) -> BoundPostureGraph:
        """Bind a loaded posture graph to figures, one of each type its channelsets drive (seed 3.4.2: "it
        prompts you to pick a figure of each kind"); without figures, the first of each type loaded."""
        loaded = self.graph(graph)
        if figures:
            figs = self.figures(figures)
        else:
            from server.motion.binding import protofiletype

            by_type: dict[str, Figure] = {}
            for fig in self.environment.figures.values():
                by_type.setdefault(protofiletype(fig), fig)
            figs = [by_type[t] for t in loaded.protofiletypes if t in by_type]
            figs.sort(key=lambda f: f.dof_count == 0)  # the soldier first, then its weapon
        if not figs:
            raise StoreError(f"no figures of type {loaded.protofiletypes} in the environment")
        try:
            bound = bind_posture_graph(loaded, figs, name or None)
        except BindingError as exc:
            raise StoreError(str(exc)) from None
        self.bound_graphs[bound.name] = bound
        return bound


def _room(table: dict[str, T], name: str | None, count: int, limit: int, what: str) -> None:
    """StoreError when ``count`` new names (``name`` replaced in place costs none) would exceed ``limit``."""
    if name is not None and name in table:
        return
    if len(table) + count > limit:
        raise StoreError(f"too many {what}: {len(table)} loaded, the limit is {limit}")


def _named(table: dict[str, T], name: str, what: str, hint: str) -> T:
    if name not in table:
        raise StoreError(f"no {what} {name!r} {hint}")
    return table[name]
