"""`ttes channelset`: inspect channelset files (seed 002, print_channelset_info) and write them for other
tools (`ttes channelset export CHSET --gltf OUT.glb`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("channelset", help="inspect channelset (*.chset.env) files", description=__doc__)
    cmds = p.add_subparsers(dest="channelset_command", metavar="SUBCOMMAND")
    cmds.required = True
    info = cmds.add_parser(
        "info",
        help="size, fps, duration, memory and sharedchannels of a channelset file",
        description="Print a channelset's summary (loads through its .npz cache unless --no-cache).",
    )
    info.add_argument("path", help="a *.chset.env file")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.add_argument("--no-cache", action="store_true", help="parse the text even when a fresh cache exists")
    info.add_argument("-V", "--verbosity", type=int, default=1, help="0: summary, 1: channels, 2: ranges")
    info.set_defaults(func=run_info)
    export = cmds.add_parser(
        "export",
        help="write a channelset as a glTF 2.0 animation on its figures",
        description="Write the figures a channelset drives (found in --figures by their protofiletype) and the "
        "clip as one glTF animation: a key per stored frame, rotations per joint node, the figure entries' "
        "translation and rotation (docs/GLTF.md).",
    )
    export.add_argument("path", type=Path, help="a *.chset.env file")
    export.add_argument(
        "--gltf", type=Path, required=True, metavar="OUT.glb", help="the binary glTF to write"
    )
    export.add_argument(
        "--figures", type=Path, default=None, help="where its .fig files are (default: figures/)"
    )
    export.add_argument("--json", action="store_true", help="machine-readable output")
    export.set_defaults(func=run_export)


def run_info(args: argparse.Namespace) -> int:
    from server.motion.cache import load_channelset
    from server.motion.info import channelset_info, print_channelset_info
    from ttes.output import print_json

    chset = load_channelset(args.path, use_cache=not args.no_cache)
    if args.json:
        print_json(channelset_info(chset))
    else:
        print_channelset_info(chset, verbosity=args.verbosity)
    return 0


def run_export(args: argparse.Namespace) -> int:
    import ttes.paths
    from authoring.gltf_export import export_channelset
    from ttes.output import print_json

    rig, frames = export_channelset(args.path, args.gltf, args.figures or ttes.paths.FIGURES)
    summary = {
        "out": str(args.gltf),
        "figures": [f.name for f in rig.figures],
        "frames": frames,
        "bytes": args.gltf.stat().st_size,
    }
    if args.json:
        print_json(summary)
    else:
        print(
            f"wrote {args.gltf}: {frames} frames on {', '.join(summary['figures'])}, {summary['bytes']} bytes"
        )
    return 0
