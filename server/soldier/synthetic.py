"""A small synthetic motion library with the real library's names, for tests, benches and demos.

The static graph is the seed's Figure 7 graph (the same postures, files and arcs as
``tests/data/motion/soldier_low.graph``); ``soldier_loco.graph`` holds ``walk_*``, ``bwalk_*``, ``run_*``,
``walk2run`` and ``run2walk`` and ``soldier_crawl.graph`` ``crawl_start`` and ``crawl_cycle`` (both graphs are
only containers of channelsets). All clips are 60 fps and join exactly: each posture has a fixed pose, a
static clip moves smoothly (smoothstep) from its start posture's pose to its end posture's; every locomotion
step starts and ends in its base posture's pose (STAND_STOWED or CRAWL) and swings the joints by ``amplitude``
radians in between (``sin(pi u)``), the two feet mirrored. Locomotion clips travel forwards (Jack -Z; backward
walking +Z) by a stride length, so the library's in-place stripping and ground-speed measurement have work to
do. Joint motion stays gentle (a few degrees per 30 Hz tick) so blending tests can tell a pop from motion."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from peabody.model import Figure
from server.motion.channelset import Channelset, FigureTrack, JointTrack, make_channelset
from server.motion.posture_change import LoadedPostureGraph
from server.motion.posture_graph import Arc, PostureGraph
from server.motion.synthetic import make_figure, make_soldier
from server.soldier.library import MotionLibrary

FPS = 60.0
POSTURES = [
    "STAND_STOWED",
    "STAND_FIRE",
    "KNEEL_STOWED",
    "KNEEL_FIRE",
    "PRONE_STOWED",
    "PRONE_FIRE",
    "CRAWL",
    "DEAD",
]
SS, SF, KS, KF, PS, PF, CR, DE = POSTURES
# token: (file stem, start, end, seconds); played forwards start -> end
STATIC_FILES: list[tuple[str, str, str, float]] = [
    ("ststow2stfire", SS, SF, 0.8),
    ("ststow2kstow", SS, KS, 1.6),
    ("ststow2crawl", SS, CR, 2.0),
    ("ststow2kfire", SS, KF, 1.8),
    ("ststow2dead", SS, DE, 1.5),
    ("stfire2kfire", SF, KF, 1.2),
    ("stfire2dead", SF, DE, 1.2),
    ("kstow2kfire", KS, KF, 0.8),
    ("kstow2crawl", KS, CR, 1.4),
    ("kstow2dead", KS, DE, 1.0),
    ("kfire2dead", KF, DE, 1.0),
    ("crawl2prstow", CR, PS, 0.8),
    ("prstow2prfire", PS, PF, 0.8),
    ("crawl2dead", CR, DE, 1.0),
    ("prstow2dead", PS, DE, 1.0),
    ("prfire2dead", PF, DE, 0.8),
    ("stfire2kstow", SF, KS, 1.6),
]
ONE_WAY = {DE}
DEAD_TO_STAND_SECONDS = 10.0
ROOT_HEIGHT = {SS: 100.0, SF: 100.0, KS: 60.0, KF: 62.0, PS: 15.0, PF: 16.0, CR: 35.0, DE: 10.0}
# loco clip stem: (seconds, travel cm (+ forwards), amplitude scale, foot sign or 0 for footless)
LOCO_CLIPS: dict[str, tuple[float, float, float, int]] = {
    "walk_start_l": (0.6, 50.0, 0.6, 1),
    "walk_start_r": (0.6, 50.0, 0.6, -1),
    "walk_cycle_l": (0.5, 70.0, 1.0, 1),
    "walk_cycle_r": (0.5, 70.0, 1.0, -1),
    "walk_end_l": (0.6, 40.0, 0.6, 1),
    "walk_end_r": (0.6, 40.0, 0.6, -1),
    "bwalk_start_l": (0.6, -30.0, 0.5, 1),
    "bwalk_start_r": (0.6, -30.0, 0.5, -1),
    "bwalk_cycle_l": (0.6, -50.0, 0.8, 1),
    "bwalk_cycle_r": (0.6, -50.0, 0.8, -1),
    "bwalk_end_l": (0.6, -30.0, 0.5, 1),
    "bwalk_end_r": (0.6, -30.0, 0.5, -1),
    "run_start_l": (0.5, 100.0, 1.0, 1),
    "run_start_r": (0.5, 100.0, 1.0, -1),
    "run_cycle_l": (0.4, 150.0, 1.2, 1),
    "run_cycle_r": (0.4, 150.0, 1.2, -1),
    "run_end_l": (0.6, 90.0, 0.8, 1),
    "run_end_r": (0.6, 90.0, 0.8, -1),
    "walk2run": (0.5, 110.0, 1.0, 1),
    "run2walk": (0.5, 110.0, 1.0, -1),
}
CRAWL_CLIPS: dict[str, tuple[float, float, float, int]] = {
    "crawl_start": (1.0, 20.0, 0.8, 1),
    "crawl_cycle": (1.2, 48.0, 1.0, 1),
}


def synthetic_figures(ndof: int = 50) -> list[Figure]:
    """A chain soldier of ``ndof`` DOFs read as ``DI.fig`` and a jointless ``AK_47.fig`` rifle."""
    return [make_soldier("soldier", "DI.fig", ndof), make_figure("rifle", "AK_47.fig", [])]


def _root_site(fig: Figure) -> str:
    site = fig.root
    seg = getattr(site, "segment", None)
    return f"{seg.name}.{site.name}" if site is not None and seg is not None else "s0.proximal"


def _placement(height: np.ndarray, forward: np.ndarray, lateral: float = 0.0) -> np.ndarray:
    tr = np.tile(np.eye(4), (len(height), 1, 1))
    tr[:, 0, 3] = lateral
    tr[:, 1, 3] = height
    tr[:, 2, 3] = -forward  # Jack: forwards is -Z
    return tr


class _Builder:
    def __init__(self, figures: Sequence[Figure], amplitude: float, seed: int) -> None:
        self.figures = list(figures)
        rng = np.random.default_rng(seed)
        self.joints = [(f, name, j.ndofs) for f in self.figures for name, j in f.joints.items()]
        width = sum(n for _, _, n in self.joints)
        self.pose = {p: rng.uniform(-0.4, 0.4, width) for p in POSTURES}
        self.swing = rng.uniform(-1.0, 1.0, width) * amplitude

    def _tracks(
        self, angles: np.ndarray, height: np.ndarray, forward: np.ndarray
    ) -> list[JointTrack | FigureTrack]:
        tracks: list[JointTrack | FigureTrack] = []
        col = 0
        for fig, name, n in self.joints:
            tracks.append(JointTrack(name, fig.filename or "", name, angles[:, col : col + n]))
            col += n
        for k, fig in enumerate(self.figures):
            lateral = 0.0 if k == 0 else 20.0
            h = height if k == 0 else height + 30.0
            nfr = len(height)
            tracks.append(
                FigureTrack(
                    fig.name,
                    fig.filename or "",
                    fig.name,
                    [_root_site(fig)] * nfr,
                    _placement(h, forward, lateral),
                )
            )
        return tracks

    def static(self, stem: str, a: str, b: str, seconds: float) -> Channelset:
        n = round(seconds * FPS) + 1
        u = np.linspace(0.0, 1.0, n)
        s = (u * u * (3 - 2 * u))[:, None]
        angles = self.pose[a] + (self.pose[b] - self.pose[a]) * s
        height = ROOT_HEIGHT[a] + (ROOT_HEIGHT[b] - ROOT_HEIGHT[a]) * s[:, 0]
        return make_channelset(f"{stem}_low.chset", FPS, self._tracks(angles, height, np.zeros(n)))

    def step(
        self, stem: str, base: str, seconds: float, travel: float, scale: float, foot: int
    ) -> Channelset:
        n = round(seconds * FPS) + 1
        u = np.linspace(0.0, 1.0, n)
        bump = np.sin(np.pi * u)[:, None]
        angles = self.pose[base] + foot * scale * self.swing * bump
        height = ROOT_HEIGHT[base] + 2.0 * bump[:, 0]
        return make_channelset(f"{stem}.chset", FPS, self._tracks(angles, height, travel * u))


def synthetic_graphs(
    figures: Sequence[Figure] | None = None, *, amplitude: float = 0.2, seed: int = 7
) -> tuple[LoadedPostureGraph, LoadedPostureGraph, LoadedPostureGraph]:
    """``(soldier_low, soldier_loco, soldier_crawl)`` loaded graphs built in memory."""
    figs = list(figures) if figures is not None else synthetic_figures()
    b = _Builder(figs, amplitude, seed)
    files = [f"{stem}_low.chset.env" for stem, *_ in STATIC_FILES]
    arcs: list[Arc] = []
    for tok, (_, a, z, secs) in enumerate(STATIC_FILES):
        arcs.append(Arc(a, z, tok, True, secs))
        if z not in ONE_WAY:
            arcs.append(Arc(z, a, tok, False, secs))
    arcs.append(Arc(DE, SS, 4, False, DEAD_TO_STAND_SECONDS))
    static = LoadedPostureGraph(
        "soldier_low",
        PostureGraph(list(POSTURES), files, arcs, "soldier_low.graph"),
        [b.static(stem, a, z, secs) for stem, a, z, secs in STATIC_FILES],
    )
    loco = LoadedPostureGraph(
        "soldier_loco",
        PostureGraph([SS], [f"{k}.chset.env" for k in LOCO_CLIPS], [], "soldier_loco.graph"),
        [b.step(k, SS, *v) for k, v in LOCO_CLIPS.items()],
    )
    crawl = LoadedPostureGraph(
        "soldier_crawl",
        PostureGraph([CR], [f"{k}.chset.env" for k in CRAWL_CLIPS], [], "soldier_crawl.graph"),
        [b.step(k, CR, *v) for k, v in CRAWL_CLIPS.items()],
    )
    return static, loco, crawl


def synthetic_motion_library(
    figure_sets: Sequence[Sequence[Figure]] | None = None,
    *,
    amplitude: float = 0.2,
    seed: int = 7,
    ndof: int = 50,
) -> MotionLibrary:
    """A :class:`MotionLibrary` of the synthetic graphs (default: 50-DOF ``DI.fig`` + ``AK_47.fig``)."""
    sets = [list(s) for s in figure_sets] if figure_sets is not None else [synthetic_figures(ndof)]
    static, loco, crawl = synthetic_graphs(sets[0], amplitude=amplitude, seed=seed)
    return MotionLibrary(static, sets, loco, crawl)


def write_synthetic_library(
    directory: str | Path, figures: Sequence[Figure] | None = None, *, amplitude: float = 0.2, seed: int = 7
) -> dict[str, Path]:
    """Write the three ``.graph`` files and their ``.chset.env`` channelsets into ``directory``.

    Returns ``{"static": ..., "loco": ..., "crawl": ...}`` graph paths (load with
    ``server.motion.load_posture_graph``).
    """
    from server.motion.channelset_file import save_channelset
    from server.motion.posture_graph import write_posture_graph

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for key, loaded in zip(
        ("static", "loco", "crawl"), synthetic_graphs(figures, amplitude=amplitude, seed=seed), strict=True
    ):
        for fname, cs in zip(loaded.graph.files, loaded.channelsets, strict=True):
            save_channelset(cs, out / fname)
        path = out / f"{loaded.name}.graph"
        write_posture_graph(loaded.graph, path)
        paths[key] = path
    return paths
