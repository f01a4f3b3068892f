"""``ttes author build``: record the whole motion library (seed 002, 3.4: record, organise, slave, re-record).

1. Solve the key postures (:mod:`~server.authoring.postures`) on ``soldier.fig`` with the ``AK_47.fig`` rifle.
2. Record every clip on soldier.fig at 60 fps — the 17 static transitions
   (:mod:`~server.authoring.transitions`), walking / backward walking / running
   (:mod:`~server.authoring.gait`)
   and crawling (:mod:`~server.authoring.crawl`) — into ``channelsets/NAME.chset.env``.
3. Slave a ``DI.fig`` to a soldier.fig master (:mod:`~server.authoring.slaving`) and re-record each clip into
   ``channelsets/NAME_low.chset.env``.
4. Write the posture graph files of both figure types and the TTES start-up script and environment into
   ``posture_graphs/``.

Everything is deterministic (no randomness, fixed iteration counts), so a rebuild gives the same bytes.
``only`` (a shell pattern on clip names) limits steps 2-3; ``figure`` picks the figure sets written
(``"DI"`` re-slaves the committed soldier.fig channelsets without recording them again).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from server.authoring import crawl, deaths, gait, postures, transitions
from server.authoring.motion import KeyPosture
from server.authoring.slaving import MasterSlavePair
from server.authoring.transitions import ClipFrames, clip_to_channelset
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from server.motion.channelset_file import format_channelset, parse_channelsets, save_channelset
from server.motion.posture_graph import Arc, PostureGraph, format_posture_graph
from server.peabody.fk import FigureKinematics
from server.peabody.loader import read_figure
from server.peabody.model import Figure

FIGURE_SETS = ("soldier", "DI", "all")
SLAVE_PARAMETERS = ("yes", "yes", "yes", "yes", 0.50, "yes", 0.50, "yes", "yes")  # seed 002, 3.4.4
SOLDIERS = 10  # soldier/rifle pairs in the start-up environment (seed 002, 3.6)


@dataclass
class BuildContext:
    """The figures and the (lazily solved) key postures every clip generator needs."""

    soldier: Figure
    rifle: Figure
    di: Figure
    _keys: dict[str, KeyPosture] = field(default_factory=dict)

    @classmethod
    def load(cls, figures_dir: Path) -> BuildContext:
        return cls(
            read_figure(figures_dir / "soldier.fig"),
            read_figure(figures_dir / "AK_47.fig"),
            read_figure(figures_dir / "DI.fig"),
        )

    @property
    def keys(self) -> dict[str, KeyPosture]:
        if not self._keys:
            self._keys.update(postures.build_postures(self.soldier, self.rifle))
        return self._keys


@dataclass(frozen=True)
class Clip:
    """A recorded clip: its frames and, for locomotion, stride length (cm) and ground speed (cm/s)."""

    frames: ClipFrames
    stride_length: float | None = None
    ground_speed: float | None = None
    release_frame: int | None = None  # deaths: the frame the hands let go of the rifle


@dataclass(frozen=True)
class ClipJob:
    """One channelset of the library: file stem, the graph that lists it, and how to record it."""

    name: str
    graph: str  # "static", "loco" or "crawl"
    make: Callable[[BuildContext], Clip]


def clip_jobs() -> list[ClipJob]:
    """Every clip of the library, in build order."""
    dying = deaths.death_specs()
    jobs = [
        ClipJob(
            t.name,
            "static",
            lambda ctx, t=t: Clip(transitions.record_transition(t, ctx.keys, (ctx.soldier, ctx.rifle))),
        )
        if t.name not in dying
        else ClipJob(t.name, "static", lambda ctx, d=dying[t.name]: _death(d, ctx))
        for t in transitions.TRANSITIONS
    ]
    for name, make in gait.locomotion_clips().items():
        jobs.append(ClipJob(name, "loco", lambda ctx, make=make: Clip(*make(ctx))))
    for name, make in crawl.crawl_clips().items():
        jobs.append(ClipJob(name, "crawl", lambda ctx, make=make: Clip(*make(ctx))))
    return jobs


def _death(spec: deaths.DeathSpec, ctx: BuildContext) -> Clip:
    clip = deaths.simulate(spec, ctx.keys, (ctx.soldier, ctx.rifle))
    return Clip(clip.frames, release_frame=clip.release_frame)


def record(job: ClipJob, ctx: BuildContext) -> Channelset:
    """The soldier.fig channelset of one clip."""
    clip = job.make(ctx)
    chset = clip_to_channelset(f"{job.name}.chset", clip.frames, ctx.soldier, ctx.rifle)
    if clip.stride_length is not None or clip.ground_speed is not None:
        chset = replace(
            chset,
            stride_length=None if clip.stride_length is None else round(clip.stride_length, 2),
            ground_speed=None if clip.ground_speed is None else round(clip.ground_speed, 2),
        )
    if clip.release_frame is not None:
        chset = replace(chset, release_frame=clip.release_frame)
    return chset


def lift_off_ground(chset: Channelset, body: Figure) -> None:
    """Raise every figure channel (soldier and rifle) in frames where the body's mesh would sink below the
    ground (the slave's torso is shaped differently from the master's, so a lying DI can dip where the
    soldier did not). In place."""
    from server.authoring.postures import lowest_point
    from server.motion.binding import bind_channelset

    bound = bind_channelset(chset, [body])
    bf = bound.figures[0]
    poses = np.tile(bf.neutral.astype(np.float64), (chset.nframes, 1))
    poses[:, bf.dst] = chset.joint_data[:, bf.src]
    chan = next(c for c in chset.figure_channels() if c.column == bf.figure_channel)
    lift = np.maximum(0.0, -lowest_point(FigureKinematics(body), poses, chset.transforms(chan)))
    if lift.any():
        held = np.ones(chset.nframes, bool)  # the rifle rises with the hands only while they hold it
        if chset.release_frame is not None:
            held[chset.release_frame :] = False
        lifted = np.where(held[:, None], lift[:, None], 0.0)
        lifted[:, chan.column] = lift
        chset.fig_pos[:, :, 1] += lifted.astype(np.float32)


def slave_pair(ctx: BuildContext) -> MasterSlavePair:
    pair = MasterSlavePair(ctx.soldier, ctx.di, ctx.rifle)
    pair.slave_parameters(*SLAVE_PARAMETERS)
    return pair


# --- graphs and start-up files ------------------------------------------------------------------------------


def _end_node(t: transitions.TransitionSpec) -> str:
    """The graph node a transition ends in: a death's own DEAD variant (``DEAD@ststow``), else its posture."""
    return deaths.dead_node(t.name) if t.name in deaths.death_specs() else t.end


def static_graph(suffix: str) -> PostureGraph:
    """Figure 7: the postures, the 17 transition files and their arcs (reverse arcs play backwards).

    Each simulated death ends in its own DEAD variant node (``DEAD@<start>``, :mod:`server.authoring.deaths`)
    and plays at its recorded length (``-1``); getting up from it replays that death backwards, slowly
    (:data:`server.authoring.deaths.GET_UP_SECONDS`)."""
    files = [f"../channelsets/{t.name}{suffix}.chset.env" for t in transitions.TRANSITIONS]
    arcs: list[Arc] = []
    dying = deaths.death_specs()
    for i, t in enumerate(transitions.TRANSITIONS):
        if t.name in dying:
            arcs.append(Arc(t.start, _end_node(t), i, True, -1.0))
            arcs.append(Arc(_end_node(t), t.start, i, False, deaths.GET_UP_SECONDS))
            continue
        arcs.append(Arc(t.start, t.end, i, True, t.duration))
        arcs.append(Arc(t.end, t.start, i, False, t.duration))
    nodes = [p for p in postures.POSTURES if p != deaths.DEAD]
    nodes += [deaths.dead_node(d.name) for d in deaths.DEATHS]
    return PostureGraph(nodes, files, arcs)


def _container_graph(
    nodes: Sequence[str], arcs: Iterable[tuple[str, str, str, bool]], suffix: str
) -> PostureGraph:
    files: list[str] = []
    out: list[Arc] = []
    for a, b, clip, forward in arcs:
        path = f"../channelsets/{clip}{suffix}.chset.env"
        if path not in files:
            files.append(path)
        out.append(Arc(a, b, files.index(path), forward, -1.0))
    return PostureGraph(list(nodes), files, out)


def loco_graph(suffix: str) -> PostureGraph:
    return _container_graph(gait.LOCO_NODES, gait.loco_arcs(), suffix)


def crawl_graph(suffix: str) -> PostureGraph:
    return _container_graph(crawl.CRAWL_NODES, crawl.crawl_arcs(), suffix)


GRAPH_FILES: dict[str, dict[str, str]] = {
    "DI": {"static": "soldier_low.graph", "loco": "soldier_loco.graph", "crawl": "soldier_crawl.graph"},
    "soldier": {
        "static": "soldier_hi.graph",
        "loco": "soldier_loco_hi.graph",
        "crawl": "soldier_crawl_hi.graph",
    },
}
_GRAPH_HEADERS = {
    "static": "static posture transitions (seed 002, Figures 3 and 7)",
    "loco": "walking, backward walking and running (seed 002, 3.3 and Figure 5): a container of channelsets",
    "crawl": "crawling (seed 002, 3.3): a container of channelsets; crawl_start backwards ends a crawl",
}


def graph_text(kind: str, figure_set: str) -> str:
    suffix = "_low" if figure_set == "DI" else ""
    graph = {"static": static_graph, "loco": loco_graph, "crawl": crawl_graph}[kind](suffix)
    fig = "DI.fig + AK_47.fig" if figure_set == "DI" else "soldier.fig + AK_47.fig"
    head = f"// {_GRAPH_HEADERS[kind]}; {fig}. Generated by `ttes author build`.\n"
    return head + format_posture_graph(graph)


def environment_text() -> str:
    """``jack-ttes-soldier_low.env``: the soldier/rifle pairs ``Di2_i`` / ``AK_47_i``, two metres apart."""
    lines = [
        "// TTES start-up environment (seed 002, 3.6): 10 DI.fig soldiers with AK-47s, read by",
        "// jack-ttes-soldier_low.jcl. Generated by `ttes author build`.",
    ]
    for i in range(SOLDIERS):
        x = 200 * i
        lines.append(
            f'figure Di2_{i} {{ file = "../figures/DI.fig"; root = lower_torso.proximal; '
            f"location = trans({x}cm, 103.58cm, 0cm); }}"
        )
        lines.append(
            f'figure AK_47_{i} {{ file = "../figures/AK_47.fig"; root = rifle.proximal; '
            f"location = trans({x + 26}cm, 89cm, -2cm); }}"
        )
    return "\n".join(lines) + "\n"


def startup_jcl() -> str:
    """``jack-ttes-soldier_low.jcl`` (seed 002, 3.6). Our channelsets are recorded facing -Z, so the three
    heading offsets (posture, walking, crawling channelsets) are 0 where the seed's had 256."""
    lines = ['read_file("jack-ttes-soldier_low.env");']
    lines += [f'create_soldier_state("s{i}","Di2_{i}","AK_47_{i}");' for i in range(SOLDIERS)]
    lines += [
        'set_channelset_parameters("no");',
        "set_ttes_report_interval(10.00);",
        "set_ttes_heading_offset(0.00,0.00,0.00);",
        "set_ttes_soldier_throttle(0.04);",
        "set_ttes_report_interval(30.00);",
        "start_ttes_socket_simulation();",
        "disable_graphics();",
    ]
    return "\n".join(lines) + "\n"


def write_graphs(root: Path, figure: str = "all") -> list[Path]:
    out_dir = root / "posture_graphs"
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    sets = ("soldier", "DI") if figure == "all" else (figure,)
    for fs in sets:
        for kind, fname in GRAPH_FILES[fs].items():
            p = out_dir / fname
            p.write_text(graph_text(kind, fs), encoding="utf-8")
            written.append(p)
    if "DI" in sets:
        for fname, text in (
            ("jack-ttes-soldier_low.env", environment_text()),
            ("jack-ttes-soldier_low.jcl", startup_jcl()),
        ):
            p = out_dir / fname
            p.write_text(text, encoding="utf-8")
            written.append(p)
    return written


# --- the build ----------------------------------------------------------------------------------------------


def select(jobs: Sequence[ClipJob], only: str | None) -> list[ClipJob]:
    if not only:
        return list(jobs)
    return [j for j in jobs if fnmatch.fnmatchcase(j.name, only)]


def _graph_endpoints(kind: str) -> dict[str, list[tuple[str, int]]]:
    """Per posture node of a graph kind: the (clip, frame) where its arcs arrive or leave (-1 = last)."""
    if kind == "static":
        arcs = [(t.start, _end_node(t), t.name, True) for t in transitions.TRANSITIONS]
    elif kind == "loco":
        arcs = gait.loco_arcs()
    else:
        arcs = crawl.crawl_arcs()
    out: dict[str, list[tuple[str, int]]] = {}
    for a, b, clip, forward in arcs:
        out.setdefault(a, []).append((clip, 0 if forward else -1))
        out.setdefault(b, []).append((clip, -1 if forward else 0))
    return out


def snap_endpoints(chsets: dict[str, Channelset]) -> None:
    """Make the clips meeting at a posture node agree exactly there (joint channels, in place).

    Recorded soldier clips already meet exactly; re-slaved DI clips can differ by the slave solver's
    tolerance, so the first clip's pose at each node is copied to the others' endpoints."""
    nodes: dict[str, list[tuple[str, int]]] = {}
    for kind in ("static", "loco", "crawl"):  # a node of several graphs (STAND_STOWED, CRAWL) is one pose
        for node, ends in _graph_endpoints(kind).items():
            nodes.setdefault(node, []).extend(ends)
    for ends in nodes.values():
        have = [(c, f) for c, f in ends if c in chsets]
        if len(have) < 2:
            continue
        ref = chsets[have[0][0]].joint_data[have[0][1]].copy()
        for c, f in have[1:]:
            chsets[c].joint_data[f] = ref


def build(
    root: Path,
    figures_dir: Path,
    only: str | None = None,
    figure: str = "all",
    progress: bool = True,
) -> list[Path]:
    """Record the library under ``root`` (``channelsets/``, ``posture_graphs/``); returns files written."""
    if figure not in FIGURE_SETS:
        raise ValueError(f"figure must be one of {', '.join(FIGURE_SETS)}, not {figure!r}")
    ctx = BuildContext.load(figures_dir)
    jobs = select(clip_jobs(), only)
    if only and not jobs:
        raise ValueError(f"no clip matches {only!r}")
    chdir = root / "channelsets"
    chdir.mkdir(parents=True, exist_ok=True)
    hi: dict[str, Channelset] = {}
    low: dict[str, Channelset] = {}
    pair = slave_pair(ctx) if figure in ("DI", "all") else None
    bar = _progress(jobs, progress)
    for job in bar:
        if hasattr(bar, "set_postfix_str"):
            bar.set_postfix_str(job.name)
        if figure == "DI":
            hi[job.name] = load_channelset(chdir / f"{job.name}.chset.env", use_cache=False)
        else:  # slave what the file will hold, so a DI-only rebuild from the files gives the same bytes
            hi[job.name] = parse_channelsets(
                format_channelset(record(job, ctx)), str(chdir / f"{job.name}.chset.env")
            )[0]
        if pair is not None:
            from server.authoring.slaving import reslave_channelset

            low[job.name] = reslave_channelset(hi[job.name], pair, f"{job.name}_low.chset")
            lift_off_ground(low[job.name], ctx.di)
    snap_endpoints(low)
    written: list[Path] = []
    for name in (j.name for j in jobs):
        if figure != "DI":
            save_channelset(hi[name], chdir / f"{name}.chset.env")
            written.append(chdir / f"{name}.chset.env")
        if name in low:
            save_channelset(low[name], chdir / f"{name}_low.chset.env")
            written.append(chdir / f"{name}_low.chset.env")
    written += write_graphs(root, figure)
    return written


def _progress(jobs: Sequence[ClipJob], enabled: bool) -> Iterable[ClipJob]:
    if not enabled:
        return jobs
    from tqdm import tqdm

    return tqdm(jobs, desc="ttes author build", unit="clip")
