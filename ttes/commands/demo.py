"""`ttes demo`: the main job on embedded defaults.

Prints the shipped figures, then starts `ttes server` on a free loopback port and renders the TTES stub
headless (EGL) while it tours every posture and locomotion mode: a video plus its last frame as a PNG. Both
processes are stopped cleanly at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Iterable

    import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the demo on the shipped data", description=__doc__)
    p.add_argument("--out-dir", type=Path, default=Path("out"), help="where demo.mp4 and demo.png go (out/)")
    p.add_argument(
        "--seconds", type=float, default=40.0, help="wall-clock length of the tour (default 40: all of it)"
    )
    p.add_argument("--figures-only", action="store_true", help="print the figure summary and stop")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ttes.commands.figure import figure_summaries
    from ttes.output import print_json

    summaries = figure_summaries()
    if args.json and args.figures_only:
        print_json({"figures": summaries})
    elif not args.json:
        print("Jack/TTES demo: the shipped figures")
        for s in summaries:
            print(
                f"  {s['file']:<12} segments={s['segments']:>3} joints={s['joints']:>3} dofs={s['dofs']:>4} "
                f"sites={s['sites']:>4} polygons={s['polygons']:>5} height={s['height_cm']:.1f} cm "
                f"root={s['root']}"
            )
    if args.figures_only:
        return 0
    from ttes.cli import main as ttes_main

    video = args.out_dir / "demo.mp4"
    print(f"Starting the server and rendering {args.seconds:g} s of the stub to {video} ...", file=sys.stderr)
    stub_args = [
        "stub",
        "--headless",
        "--spawn-server",
        "--seconds",
        str(args.seconds),
        "--fps",
        "10",
        "--out",
        str(video),
    ]
    stub_json = io.StringIO()
    if args.json:  # one JSON object on stdout: the figures, the stub's summary, the last frame
        stub_args.append("--json")
        with contextlib.redirect_stdout(stub_json):
            rc = ttes_main(stub_args)
    else:
        rc = ttes_main(stub_args)
    if rc != 0:
        return rc
    import imageio.v2 as imageio

    last = None
    with imageio.get_reader(video) as reader:
        # imageio's stub types the Reader's __iter__ as returning one Array; it yields the frames.
        for last in cast("Iterable[np.ndarray]", reader):  # noqa: B007 - we want the final frame
            pass
    png = args.out_dir / "demo.png"
    if last is not None:
        imageio.imwrite(png, last)
        print(f"wrote {png} (the last frame)", file=sys.stderr)
    if args.json:
        stub = json.loads(stub_json.getvalue() or "{}")
        print_json({"figures": summaries, "stub": stub, "png": str(png) if last is not None else None})
    return 0
