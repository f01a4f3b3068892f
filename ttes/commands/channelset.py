"""`ttes channelset`: inspect channelset files (seed 002, print_channelset_info)."""

from __future__ import annotations

import argparse


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
