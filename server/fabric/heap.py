"""Keep freed memory in the process: a fabric receiving large samples page-faulted anew for each.

Cyclone DDS reassembles each fragmented sample (a shard's whole batch, 1.33 MB at 10,000 soldiers) into a
fresh buffer on its receive thread, and the Python binding copies it into ``bytes``: a few buffers of that
size in flight, freed every tick. glibc gives the top of a thread's arena back to the kernel once the free
top exceeds its trim threshold (twice the largest block freed so far, 2.7 MB here), so each tick's buffers
were mapped, zeroed and page-faulted again: two thirds of the subscriber's CPU (``perf``: page faults,
``clear_page``, ``madvise``); the receive thread fell behind, the socket dropped datagrams, and each lost
datagram lost its whole sample (issue 21, docs/SCALING.md). A Zenoh shard's put of a whole batch paid the
same faults on the publishing side (3.1 ms a tick, 1.0-1.2 without them); :func:`server.fabric.open_fabric`
calls this for either engine. Raising both thresholds keeps up to :data:`TRIM` of freed memory an arena, and
blocks up to :data:`MMAP` in the heap. Nothing to do on a C library without ``mallopt`` (a no-op on musl).
"""

from __future__ import annotations

import ctypes

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's malloc.h
MMAP = 32 << 20  # glibc's largest mmap threshold on 64-bit: blocks below it come from the heap
TRIM = 64 << 20  # free memory at the top of an arena kept, not returned to the kernel


def keep_freed_memory() -> bool:
    """Set the process's malloc thresholds; True where the C library took them."""
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)
    if mallopt is None:
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM))
