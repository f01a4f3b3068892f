"""`ttes channelset`: inspect channelset files (seed 002, print_channelset_info) and write them for other
tools (`ttes channelset export CHSET --gltf OUT.glb --bvh OUT.bvh`, `ttes channelset import-bvh`)."""

from __future__ import annotations

import argparse
import sys
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
        help="write a channelset as a glTF 2.0 animation on its figures, or as BVH",
        description="Write the figures a channelset drives (found in --figures by their protofiletype) and "
        "the clip as one glTF animation: a key per stored frame, rotations per joint node, the figure "
        "entries' translation and rotation; --bvh: the soldier's skeleton and motion as BVH (docs/GLTF.md).",
    )
    export.add_argument("path", type=Path, help="a *.chset.env file")
    export.add_argument("--gltf", type=Path, metavar="OUT.glb", help="the binary glTF to write")
    export.add_argument("--bvh", type=Path, metavar="OUT.bvh", help="the BVH to write (the soldier only)")
    export.add_argument(
        "--figures", type=Path, default=None, help="where its .fig files are (default: figures/)"
    )
    export.add_argument("--json", action="store_true", help="machine-readable output")
    export.set_defaults(func=run_export)
    imp = cmds.add_parser(
        "import-bvh",
        help="read a BVH on a figure's skeleton (as export --bvh writes it) into a channelset",
        description="Read a BVH whose joints are the figure's (names, offsets and rest as `export --bvh` "
        "writes them) and write its motion as a .chset.env: joint angles per joint, the figure at its root.",
    )
    imp.add_argument("bvh", type=Path, help="the .bvh file")
    imp.add_argument("out", type=Path, help="the .chset.env to write")
    imp.add_argument("--figure", type=Path, required=True, help="the figure it moves (figures/DI.fig)")
    imp.add_argument("--name", help="the channelset's name (default: from OUT)")
    imp.add_argument("--json", action="store_true", help="machine-readable output")
    imp.set_defaults(func=run_import_bvh)


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

    if args.gltf is None and args.bvh is None:
        print("ttes channelset export: give --gltf OUT.glb and/or --bvh OUT.bvh", file=sys.stderr)
        return 2
    rig, frames = export_channelset(
        args.path, args.figures or ttes.paths.FIGURES, gltf=args.gltf, bvh=args.bvh
    )
    outs = [str(p) for p in (args.gltf, args.bvh) if p is not None]
    names = [f.name for f in rig.figures]
    summary = {"out": outs, "figures": names, "frames": frames}
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {', '.join(outs)}: {frames} frames on {', '.join(names)}")
    return 0


def run_import_bvh(args: argparse.Namespace) -> int:
    from authoring.bvh_io import bvh_to_channelset
    from authoring.gltf_export import rig_for
    from peabody.loader import read_figure
    from server.motion.channelset_file import save_channelset
    from ttes.output import print_json

    name = args.name or args.out.name.removesuffix(".env")
    chset = bvh_to_channelset(args.bvh, rig_for([read_figure(args.figure)]), name)
    save_channelset(chset, args.out)
    summary = {"out": str(args.out), "name": chset.name, "frames": chset.nframes, "fps": chset.fps}
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {args.out}: {chset.nframes} frames at {chset.fps:g} fps")
    return 0
