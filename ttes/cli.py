"""`ttes` entry point.

Each subcommand lives in its own module under :mod:`ttes.commands` and exposes
``register(subparsers)``; modules are discovered, so adding a command never edits
this file. Command modules import their heavy dependencies inside their handlers,
so ``ttes --help`` stays fast.

One exit-status convention for every command (``EXIT_STATUS``), and one log format for every process:
the server's ``key=value`` lines (:mod:`server.logging`), so a stub's and its server's lines read alike.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Sequence

import ttes.commands
from ttes.arguments import UsageError
from ttes.extras import missing_extra_message

EXIT_STATUS = """exit status (every command):
  0    done
  1    it failed at run time: a file that cannot be read, an address in use, no server, ...
  2    usage: a bad option or value (named), or a missing extra (named, with its pip install)
  3    ttes stub: the server was lost and did not come back
  130  interrupted (Ctrl-C)
`ttes author check` and `author figures --check` exit 1 when the data fail their check; `author check`
exits 2 when it could check nothing (a missing file too), as grep does."""


def version() -> str:
    """The installed distribution's version and the wire protocol's."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    from protocol.events import PROTOCOL_VERSION

    try:
        ours = dist_version("jack-ttes")
    except PackageNotFoundError:  # run from a checkout that was never installed
        ours = "unknown (not installed)"
    return f"ttes (jack-ttes) {ours}, protocol {PROTOCOL_VERSION}"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ttes",
        description="Jack/TTES: real-time human-figure animation service for distributed simulation.",
        epilog=EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=version())
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(ttes.commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"ttes.commands.{info.name}")
        module.register(sub)
    return parser


def configure_logging(verbose: int) -> None:
    """Every ``ttes.*`` logger not configured by its command writes the server's ``key=value`` lines to
    stderr (``logging.basicConfig``: a no-op where the root logger already has handlers, as under pytest)."""
    from server.logging import KeyValueFormatter

    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(KeyValueFormatter())
    logging.basicConfig(level=logging.WARNING - 10 * min(verbose, 2), handlers=[handler])


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(args.verbose)
    try:
        result = args.func(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return 0
    except ModuleNotFoundError as exc:
        message = missing_extra_message(args.command, exc)
        if message is None:
            raise
        print(message, file=sys.stderr)
        return 2
    except UsageError as exc:
        print(f"ttes {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as exc:
        print(f"ttes {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return int(result or 0)
