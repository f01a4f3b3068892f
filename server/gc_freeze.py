"""A server process's loaded data kept out of the cyclic garbage collector's full collections (issue 21).

The start-up (the motion library: channel sets, posture graphs, figures, the JCL's commands) leaves some
47,000 tracked Python objects, and every full (generation 2) collection walks them all: 30–37 ms of the loop
thread's CPU every 5–35 s in each shard and front-end of ``bench/bench_shards.py`` at 20,000 soldiers, while
the tick, the requests and the encodes wait (a 20 ms stall of a single server too). ``gc.freeze`` moves them
to the permanent generation, which no collection walks; what is made afterwards is collected as before.
Only for a server process (``ttes server``, ``ttes front``): a process that makes many servers (the tests)
would never collect the cycles of the ones it dropped.
"""

from __future__ import annotations

import gc


def freeze_loaded() -> None:
    """Collect, then freeze every object tracked now (the start-up's garbage first: a frozen cycle stays)."""
    gc.collect()
    gc.freeze()
