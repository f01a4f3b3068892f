"""``print_channelset_info`` (seed 002): memory use and contents of channelsets and their bindings."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any, TextIO

from server.motion.binding import BoundChannelset
from server.motion.channelset import Channelset


def channelset_info(chset: Channelset) -> dict[str, Any]:
    """The summary ``ttes channelset info --json`` prints."""
    return {
        "name": chset.name,
        "size": chset.size,
        "frames": chset.nframes,
        "fps": chset.fps,
        "count": chset.count,
        "duration_s": chset.duration,
        "bytes": chset.nbytes,
        "channels": [
            {"name": c.name, "type": c.type, "object": c.object, "protofiletype": c.protofiletype}
            for c in chset.channels
        ],
    }


def print_channelset_info(
    chset: Channelset, bound: Sequence[BoundChannelset] = (), verbosity: int = 1, file: TextIO | None = None
) -> None:
    """Print a channelset's size and memory (verbosity 0), its channels (1) and per-frame extents (2), and
    the bytes each binding adds beside the bytes of the shared data."""
    out = file or sys.stdout
    print(
        f"channelset {chset.name}: {chset.nframes} frames (size {chset.size}) at {chset.fps:g} fps = "
        f"{chset.duration:.3f} s, {chset.count} sharedchannels, {chset.nbytes} bytes",
        file=out,
    )
    for b in bound:
        figs = ", ".join(f.figure for f in b.figures)
        print(f"  bound channelset {b.name} ({figs}): {b.nbytes} bytes", file=out)
    if verbosity < 1:
        return
    for c in chset.channels:
        if c.is_joint:
            a = chset.angles(c)
            extra = f"{c.width} angle(s)"
            if verbosity >= 2:
                extra += f", range [{a.min():.4f}, {a.max():.4f}] rad"
        else:
            roots = sorted(set(chset.roots(c)))
            extra = f"root site(s) {', '.join(roots)}"
        print(
            f"  {c.type:<12} {c.name:<24} object={c.object} protofiletype={c.protofiletype} {extra}", file=out
        )
