"""`ttes graph`: posture graph files (seed 002, 3.4.2): shortest paths in time, summaries, glTF export."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from server.motion.posture_graph import PostureGraph


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("graph", help="posture graph (.graph) files: paths and summaries", description=__doc__)
    cmds = p.add_subparsers(dest="graph_command", metavar="SUBCOMMAND")
    cmds.required = True
    path = cmds.add_parser(
        "path",
        help="quickest sequence of transitions between two postures",
        description="Dijkstra over arc times; arcs with time -1 use their channelset's stored duration.",
    )
    path.add_argument("graph", help="a .graph file")
    path.add_argument("start", metavar="FROM", help="starting posture")
    path.add_argument("goal", metavar="TO", help="goal posture")
    path.add_argument("--json", action="store_true", help="machine-readable output")
    path.set_defaults(func=run_path)
    info = cmds.add_parser(
        "info", help="postures, channelset files and arcs of a graph", description="Summarise a .graph file."
    )
    info.add_argument("graph", help="a .graph file")
    info.add_argument("--load", action="store_true", help="also load (and cache) every channelset it lists")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(func=run_info)
    export = cmds.add_parser(
        "export",
        help="every channelset of a graph as glTF 2.0 animations on one soldier",
        description="Write the figures a graph's channelsets drive and one glTF animation per channelset "
        "(its arcs in the animation's extras) as one .glb (docs/GLTF.md).",
    )
    export.add_argument("graph", type=Path, help="a .graph file")
    export.add_argument(
        "--gltf", type=Path, required=True, metavar="OUT.glb", help="the binary glTF to write"
    )
    export.add_argument(
        "--figures", type=Path, default=None, help="where its .fig files are (default: figures/)"
    )
    export.add_argument("--json", action="store_true", help="machine-readable output")
    export.set_defaults(func=run_export)


def _durations(graph_path: str, graph: PostureGraph) -> list[float] | None:
    """Stored channelset durations, loaded only when some arc needs them (time -1)."""
    if all(a.time > 0 for a in graph.arcs):
        return None
    from server.motion.posture_change import load_posture_graph

    return load_posture_graph(graph_path).durations


def _check_posture(graph: PostureGraph, name: str, where: str) -> None:
    """A usage error naming the graph's postures (and the likeliest one) when ``name`` is not among them."""
    import difflib

    from ttes.arguments import UsageError

    if name in graph.postures:
        return
    upper = {p.upper(): p for p in graph.postures}
    close = [p for u, p in upper.items() if u.startswith(name.upper())]
    close = close or [upper[u] for u in difflib.get_close_matches(name.upper(), list(upper), n=1, cutoff=0.5)]
    hint = f" (did you mean {' or '.join(close)}?)" if close else ""
    raise UsageError(f"{where}: unknown posture {name!r}{hint}; its postures: {', '.join(graph.postures)}")


def run_path(args: argparse.Namespace) -> int:
    from server.motion.posture_graph import read_posture_graph
    from ttes.output import print_json

    graph = read_posture_graph(args.graph)
    for name in (args.start, args.goal):
        _check_posture(graph, name, args.graph)
    durations = _durations(args.graph, graph)
    arcs = graph.shortest_path(args.start, args.goal, durations)
    result: dict[str, Any] = {
        "path": [args.start, *(a.end for a in arcs)],
        "arcs": [
            {
                "from": a.start,
                "to": a.end,
                "channelset": graph.files[a.channelset],
                "direction": a.direction,
                "time": graph.arc_time(a, durations),
            }
            for a in arcs
        ],
        "time_s": graph.path_time(arcs, durations),
    }
    if args.json:
        print_json(result)
        return 0
    print(" -> ".join(result["path"]) + f"  ({result['time_s']:.3f} s)")
    for a in result["arcs"]:
        print(f"  {a['from']:<14} {a['to']:<14} {a['channelset']:<32} {a['direction']:<8} {a['time']:g} s")
    return 0


def run_info(args: argparse.Namespace) -> int:
    from server.motion.posture_graph import read_posture_graph
    from ttes.output import print_json

    graph = read_posture_graph(args.graph)
    result: dict[str, object] = {
        "file": args.graph,
        "postures": graph.postures,
        "channelsets": graph.files,
        "arcs": [
            {
                "from": a.start,
                "to": a.end,
                "channelset": a.channelset,
                "direction": a.direction,
                "time": a.time,
            }
            for a in graph.arcs
        ],
    }
    if args.load:
        from server.motion.posture_change import load_posture_graph

        loaded = load_posture_graph(args.graph)
        result["channelset_durations_s"] = loaded.durations
        result["channelset_bytes"] = sum(c.nbytes for c in loaded.channelsets)
        result["protofiletypes"] = loaded.protofiletypes
    if args.json:
        print_json(result)
        return 0
    counts = f"{len(graph.postures)} postures, {len(graph.files)} channelsets, {len(graph.arcs)} arcs"
    print(f"{args.graph}: {counts}")
    print("  postures: " + ", ".join(graph.postures))
    if args.load:
        print(f"  channelset data: {result['channelset_bytes']} bytes")
    return 0


def run_export(args: argparse.Namespace) -> int:
    import ttes.paths
    from authoring.gltf_export import export_posture_graph
    from ttes.output import print_json

    rig, clips = export_posture_graph(args.graph, args.figures or ttes.paths.FIGURES, args.gltf)
    names = [f.name for f in rig.figures]
    if args.json:
        print_json({"out": str(args.gltf), "figures": names, "animations": clips})
    else:
        print(f"wrote {args.gltf}: {clips} animations on {', '.join(names)}")
    return 0
