"""Argument types every command shares, so a bad value is a usage error (exit 2) that names it while parsing.

``type=port`` rather than ``type=int``: argparse then says ``argument --port: 99999 is outside 1..65535``
before anything connects, where ``int`` let ``socket`` wrap 99999 to port 34463 and report "Connection
refused". A check that needs two options together raises :class:`UsageError` from the command; ``ttes``
exits 2 on it, and 1 on every runtime error (a file that cannot be read, an address in use, no server).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import re
from collections.abc import Callable
from pathlib import Path

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi", ".gif")
IMAGE_SUFFIXES = (".png",)
HEADLESS_NEEDS_OUT = (
    f"--headless needs --out FILE: a video ({', '.join(VIDEO_SUFFIXES)}) or a .png (the last frame)"
)
_HOST_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


class UsageError(Exception):
    """A command line that cannot work, found after parsing (two options that exclude each other): exit 2."""


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def _float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def port(text: str) -> int:
    """A port to connect to: 1..65535."""
    value = _int(text)
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{value} is outside 1..65535")
    return value


def listen_port(text: str) -> int:
    """A port to listen on: 0..65535 (0: any free port)."""
    value = _int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{value} is outside 0..65535 (0: any free port)")
    return value


def host(text: str) -> str:
    """An IP address or a host name (its syntax only: nothing is looked up while parsing)."""
    name = text.strip()
    try:
        ipaddress.ip_address(name.split("%")[0])
        return name
    except ValueError:
        pass
    labels = name.rstrip(".").split(".")
    if not name or len(name) > 253 or not all(_HOST_LABEL.fullmatch(x) for x in labels):
        raise argparse.ArgumentTypeError(f"{text!r} is not an IP address or a host name")
    return name


def host_port(text: str, parse_port: Callable[[str], int] = port) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6addr]:PORT`` for IPv6): a host (:func:`host`) and a port (:func:`port`)."""
    name, sep, num = text.strip().rpartition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT")
    return host(name.removeprefix("[").removesuffix("]")), parse_port(num)


def listen_host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT`` to bind: as :func:`host_port`, with port 0 (any free port) allowed."""
    return host_port(text, listen_port)


def number(lo: float, hi: float = math.inf, *, open_low: bool = False) -> Callable[[str], float]:
    """A finite float in ``[lo, hi]`` (``(lo, hi]`` with ``open_low``)."""

    def parse(text: str) -> float:
        value = _float(text)
        if value < lo or (open_low and value == lo) or value > hi:
            if hi == math.inf:
                raise argparse.ArgumentTypeError(f"{text} must be {'>' if open_low else '>='} {lo:g}")
            raise argparse.ArgumentTypeError(f"{text} is outside {'(' if open_low else '['}{lo:g}, {hi:g}]")
        return value

    return parse


def count(lo: int = 1, hi: int | None = None) -> Callable[[str], int]:
    """A whole number in ``[lo, hi]``."""

    def parse(text: str) -> int:
        value = _int(text)
        if value < lo or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(
                f"{value} must be >= {lo}" if hi is None else f"{value} is outside {lo}..{hi}"
            )
        return value

    return parse


positive = number(0.0, open_low=True)
non_negative = number(0.0)


def size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` in pixels, each 16..8192."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT (e.g. 640x480)") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"{text} is outside 16x16..8192x8192")
    return w, h


def output_file(*suffixes: str) -> Callable[[str], Path]:
    """A file to write whose suffix is one of ``suffixes`` (the ones the command can write)."""

    def parse(text: str) -> Path:
        path = Path(text)
        if path.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(
                f"{text}: cannot write {path.suffix or 'a file without a suffix'}; use {', '.join(suffixes)}"
            )
        return path

    return parse


video_or_png = output_file(*VIDEO_SUFFIXES, *IMAGE_SUFFIXES)
