"""Building the motion library from what is loaded and bound (seed 002, 3.6).

"The first soldier state create triggers the loading of all the posture graph files and associated
channelset files. Also, the channels are bound to the soldiers at this point." The three graphs are the
ones loaded under the names ``soldier_low`` (static postures), ``soldier_loco`` and ``soldier_crawl``
(loaded from the files of those names on the search path if a script did not load them first), and, when
present, ``soldier_turn`` (turns in place, side-steps) and ``soldier_react`` (recoil, flinch).

The *figure sets* (soldier figure type + weapon type) the library is bound to are, in order of preference:
the figures of every posture graph bound from ``soldier_low`` (``bind_posture_graph``), else one figure of
each type the graphs drive found in the environment (every soldier type × every weapon type), plus the
figures of the ``create_soldier_state`` that asked for the library.

**Weapon variants** (issue 16): a rifle model the graphs do not drive (``M16.fig``; the models are
``protocol.dis.RIFLE_FIGURES``) whose own graphs are on the search path (``soldier_low_m16.graph``,
``soldier_loco_m16.graph``, ...) is bound too: every soldier figure type of the sets
above with that weapon (its figure from the environment, else its ``.fig`` file) plays those graphs, so a
client may create soldiers with either rifle.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path

from peabody.model import Figure
from protocol.dis import RIFLE_FIGURES
from server.logging import get_logger
from server.motion.binding import protofiletype
from server.motion.errors import BindingError, PostureGraphError
from server.motion.posture_change import LoadedPostureGraph
from server.soldier.library import GraphSet, MotionLibrary, weapon_suffix
from server.world.store import MotionStore, StoreError

log = get_logger("library")

# (name, file) of the static, loco, crawl, turn and react graphs
GRAPHS: tuple[tuple[str, str], ...] = tuple(
    (g, f"{g}.graph")
    for g in ("soldier_low", "soldier_loco", "soldier_crawl", "soldier_turn", "soldier_react")
)


def _graph(
    store: MotionStore, resolve: Callable[[str], Path], key: str, filename: str
) -> LoadedPostureGraph | None:
    if key in store.graphs:
        return store.graphs[key]
    path = resolve(filename)
    return store.load_graph(path, key) if path.is_file() else None


def _split(figures: list[Figure]) -> tuple[dict[str, Figure], dict[str, Figure]]:
    soldiers: dict[str, Figure] = {}
    weapons: dict[str, Figure] = {}
    for fig in figures:
        (soldiers if fig.dof_count > 0 else weapons).setdefault(protofiletype(fig), fig)
    return soldiers, weapons


def figure_sets(
    store: MotionStore, types: set[str], wanted: tuple[Figure, Figure | None] | None = None
) -> list[list[Figure]]:
    """The [soldier, weapon] figure lists the library is bound to (see the module docstring)."""
    sets: dict[tuple[str, ...], list[Figure]] = {}
    for bound in store.bound_graphs.values():
        if bound.loaded is store.graphs.get(GRAPHS[0][0]):
            figs = store.figures([b.figure for b in bound.bound[0].figures]) if bound.bound else []
            soldiers, weapons = _split(figs)
            for pair in itertools.product(soldiers.values(), weapons.values() or [None]):
                figs_ = [f for f in pair if f is not None]
                sets.setdefault(tuple(protofiletype(f) for f in figs_), figs_)
    if not sets:
        soldiers, weapons = _split(
            [f for f in store.environment.figures.values() if protofiletype(f) in types]
        )
        for pair in itertools.product(soldiers.values(), weapons.values() or [None]):
            figs_ = [f for f in pair if f is not None]
            sets.setdefault(tuple(protofiletype(f) for f in figs_), figs_)
    if wanted is not None:
        figs_ = [f for f in wanted if f is not None]
        sets.setdefault(tuple(protofiletype(f) for f in figs_), figs_)
    return list(sets.values())


def build_library(
    store: MotionStore, resolve: Callable[[str], Path], wanted: tuple[Figure, Figure | None] | None = None
) -> MotionLibrary:
    """Load the five graphs (the static one is required) and bind them to the figure sets."""
    static = _graph(store, resolve, *GRAPHS[0])
    if static is None:
        raise StoreError(
            f"posture graph {GRAPHS[0][1]!r} not found (in the data directory or its search path)"
        )
    loco = _graph(store, resolve, *GRAPHS[1])
    crawl = _graph(store, resolve, *GRAPHS[2])
    turn = _graph(store, resolve, *GRAPHS[3])
    react = _graph(store, resolve, *GRAPHS[4])
    types = set(static.protofiletypes)
    for g in (loco, crawl, turn, react):
        if g is not None:
            types.update(g.protofiletypes)
    sets = figure_sets(store, types, wanted)
    if not sets:
        raise StoreError(f"no soldier figure of a type the posture graphs drive ({sorted(types)}) is loaded")
    variants = weapon_variants(store, resolve, types)
    if variants:
        try:
            return MotionLibrary(
                static,
                _with_weapons(sets, variants),
                loco,
                crawl,
                turn=turn,
                react=react,
                weapon_graphs={w: g for w, (g, _) in variants.items()},
            )
        except (BindingError, PostureGraphError, ValueError) as exc:  # serve the base weapon rather than none
            log.warning("weapon_variants_skipped", weapons=sorted(variants), error=str(exc))
    try:
        return MotionLibrary(static, sets, loco, crawl, turn=turn, react=react)
    except (BindingError, PostureGraphError, ValueError) as exc:
        raise StoreError(f"binding the posture graphs: {exc}") from None


def _with_weapons(
    sets: list[list[Figure]], variants: dict[str, tuple[GraphSet, Figure]]
) -> list[list[Figure]]:
    """``sets`` plus each soldier figure type in them with each variant weapon, last (table ids stay)."""
    out = list(sets)
    have = {tuple(protofiletype(f) for f in s) for s in sets}
    soldiers = {protofiletype(s[0]): s[0] for s in sets}
    for weapon, (_, figure) in variants.items():
        for stype, soldier in soldiers.items():
            if (stype, weapon) not in have:
                out.append([soldier, figure])
    return out


def weapon_variants(
    store: MotionStore, resolve: Callable[[str], Path], driven: set[str]
) -> dict[str, tuple[GraphSet, Figure]]:
    """Per rifle model the base graphs do not drive but whose own graphs exist: its graphs and a figure."""
    out: dict[str, tuple[GraphSet, Figure]] = {}
    for weapon in RIFLE_FIGURES:
        if weapon in driven:
            continue
        suffix = weapon_suffix(weapon)
        static, loco, crawl, turn, react = (
            _graph(store, resolve, g + suffix, f"{g}{suffix}.graph") for g, _ in GRAPHS
        )
        if static is None:
            continue
        figure = next((f for f in store.environment.figures.values() if protofiletype(f) == weapon), None)
        if figure is None:
            path = resolve(weapon)
            if not path.is_file():
                continue
            from peabody.language import PeabodyError
            from peabody.loader import read_figure

            try:
                figure = read_figure(path, load_psurfs=False)
            except (PeabodyError, OSError) as exc:
                raise StoreError(f"weapon figure {weapon}: {exc}") from None
        out[weapon] = ((static, loco, crawl, turn, react), figure)
    return out
