"""Where a request's time goes across a front-end and its shards (bench only, off by default).

With ``TTES_TRACE=PREFIX`` in its environment, a process appends one line per stage a traced soldier
passes to ``PREFIX.<pid>``: ``<time.monotonic()> <stage> <indices> [<note>]``. Traced are the soldiers
whose index is below ``TTES_TRACE_BELOW`` (default 64: a probe creates them before a load generator
creates the rest). The monotonic clock is one per host, so the stamps of the processes of one machine
line up: ``bench/bench_shards.py --trace`` joins them into the legs of each probe request (client →
front-end → fabric → shard → fabric → front-end → client). Off, a stage costs one ``is None`` test.
"""

from __future__ import annotations

import os
import time

import numpy as np


class Tracer:
    """Appends the stamps of the traced soldiers to one file (line-buffered: a killed process keeps them)."""

    def __init__(self, path: str, below: int) -> None:
        self.below = below
        self._file = open(path, "a", buffering=1)  # noqa: SIM115 (lives as long as the process)

    def stamp(self, stage: str, indices: np.ndarray | list[int], note: str = "") -> None:
        """Stamp ``stage`` now for the traced soldiers among ``indices`` (nothing if none is)."""
        idx = np.asarray(indices)
        hit = idx[idx < self.below]
        if len(hit):
            line = f"{time.monotonic():.6f} {stage} {','.join(map(str, hit.tolist()))}"
            self._file.write(f"{line} {note}\n" if note else line + "\n")

    def close(self) -> None:
        self._file.close()


def from_env() -> Tracer | None:
    prefix = os.environ.get("TTES_TRACE")
    if not prefix:
        return None
    return Tracer(f"{prefix}.{os.getpid()}", int(os.environ.get("TTES_TRACE_BELOW", "64")))


TRACE = from_env()
