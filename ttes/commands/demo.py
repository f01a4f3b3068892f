"""`ttes demo`: the main job on embedded defaults (grows with each capability)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the demo on the shipped data", description=__doc__)
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        from ttes.commands.figure import figure_summaries
    except ImportError:  # until the Peabody figures land
        print("Jack/TTES demo: no figures yet")
        return 0
    from ttes.output import print_json

    summaries = figure_summaries()
    if args.json:
        print_json(summaries)
        return 0
    print("Jack/TTES demo: the shipped figures")
    for s in summaries:
        print(
            f"  {s['file']:<12} segments={s['segments']:>3} joints={s['joints']:>3} dofs={s['dofs']:>4} "
            f"sites={s['sites']:>4} polygons={s['polygons']:>5} height={s['height_cm']:.1f} cm "
            f"root={s['root']}"
        )
    return 0
