"""`ttes figure`: inspect Peabody figure files (`ttes figure info PATH`), write them for other tools
(`ttes figure export FIG [WEAPON] --gltf OUT.glb`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import ttes.paths


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("figure", help="inspect Peabody figure files", description=__doc__)
    actions = p.add_subparsers(dest="figure_command", metavar="ACTION")
    actions.required = True
    info = actions.add_parser(
        "info",
        help="counts, standing height and root of a figure file",
        description="Print segment/joint/DOF/site/polygon counts, the neutral-pose height and the root site.",
    )
    info.add_argument("path", type=Path, help="a .fig file")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(figure_func=_info)
    spit = actions.add_parser(
        "spit",
        help="write figures as a .tips file for the stub (Jack's spit)",
        description="Write every figure of the given .fig/.env files as a TIPS file (seed 002, section 7).",
    )
    spit.add_argument("inputs", nargs="+", type=Path, help=".fig or .env files (ENV_OR_FIG ...)")
    spit.add_argument("out", type=Path, help="the .tips file to write")
    spit.add_argument("--json", action="store_true", help="machine-readable output")
    spit.set_defaults(figure_func=_spit)
    export = actions.add_parser(
        "export",
        help="write a figure (and its weapon) as glTF 2.0 for any image generator",
        description="Write the soldier figure and optionally its weapon, in the neutral pose, as one .glb: "
        "nodes named as the server's update table, segment meshes, sites as empty nodes (docs/GLTF.md).",
    )
    export.add_argument("figure", type=Path, help="the soldier's .fig file (figures/DI.fig)")
    export.add_argument("weapon", type=Path, nargs="?", help="its weapon's .fig file (figures/AK_47.fig)")
    export.add_argument(
        "--gltf", type=Path, required=True, metavar="OUT.glb", help="the binary glTF to write"
    )
    export.add_argument("--json", action="store_true", help="machine-readable output")
    export.set_defaults(figure_func=_export)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return int(args.figure_func(args))


def _info(args: argparse.Namespace) -> int:
    from ttes.output import print_json

    summary = figure_summary(args.path)
    if args.json:
        print_json(summary)
        return 0
    print(f"{summary['file']}: figure {summary['name']}")
    for key in ("segments", "joints", "dofs", "sites", "polygons", "nodes", "edges"):
        print(f"  {key:<9} {summary[key]}")
    label = "length" if summary["segments"] == 1 else "height"
    print(f"  {label:<9} {summary['height_cm']:.1f} cm")
    print(f"  root      {summary['root']}")
    return 0


def _spit(args: argparse.Namespace) -> int:
    import sys

    from peabody.language import PeabodyError
    from peabody.tips import spit
    from ttes.output import print_json

    try:
        env = spit(args.inputs, args.out)
    except (PeabodyError, OSError, ValueError) as exc:
        print(f"ttes figure spit: {exc}", file=sys.stderr)
        return 1
    summary = {"out": str(args.out), "figures": list(env.figures), "bytes": args.out.stat().st_size}
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {summary['out']}: {len(env.figures)} figure(s) {', '.join(env.figures)}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from authoring.gltf_export import export_figures
    from peabody.loader import read_figure
    from ttes.output import print_json

    paths = [args.figure] + ([args.weapon] if args.weapon else [])
    rig = export_figures([read_figure(p) for p in paths], args.gltf)
    summary = {
        "out": str(args.gltf),
        "figures": list(rig.entry_names),
        "segments": sum(len(w.segment_names) for w in rig.wire),
        "sites": sum(len(w.site_names) for w in rig.wire),
        "bytes": args.gltf.stat().st_size,
    }
    if args.json:
        print_json(summary)
    else:
        print(
            f"wrote {args.gltf}: {', '.join(rig.entry_names)}; {summary['segments']} segments, "
            f"{summary['sites']} sites, {summary['bytes']} bytes"
        )
    return 0


def figure_summary(path: str | Path) -> dict[str, Any]:
    """One figure file's counts; ``height_cm`` is the +Y extent of its psurfs in the neutral pose (for a
    one-segment figure such as a rifle, its largest extent: the length)."""
    import numpy as np

    from peabody.fk import FigureKinematics
    from peabody.loader import read_figure
    from peabody.psurf import psurf_edges

    figure = read_figure(path)
    fk = FigureKinematics(figure)
    globals_ = fk.segment_globals(fk.neutral_pose())
    points = []
    polygons = nodes = edges = 0
    for i, segment in enumerate(figure.segments.values()):
        psurf = segment.psurf
        if psurf is None:
            continue
        polygons += psurf.polygon_count
        nodes += len(psurf.nodes)
        edges += len(psurf_edges(psurf))
        g = globals_[i]
        points.append(psurf.nodes @ g[:3, :3].T + g[:3, 3])
    height = 0.0
    if points:
        pts = np.concatenate(points)
        if len(pts):
            span = pts.max(axis=0) - pts.min(axis=0)
            height = float(span.max() if len(figure.segments) == 1 else span[1])
    return {
        "name": figure.name,
        "file": figure.filename,
        "segments": len(figure.segments),
        "joints": len(figure.joints),
        "dofs": figure.dof_count,
        "sites": sum(len(s.sites) for s in figure.segments.values()),
        "polygons": polygons,
        "nodes": nodes,
        "edges": edges,
        "height_cm": round(height, 3),
        "root": fk.root_name,
    }


def figure_summaries(directory: str | Path = ttes.paths.FIGURES) -> list[dict[str, Any]]:
    """``figure_summary`` of every ``*.fig`` in ``directory`` (sorted by file name)."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    return [figure_summary(p) for p in sorted(folder.glob("*.fig"))]
