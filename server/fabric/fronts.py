"""Several front-ends (``ttes front --front K/M``): each allots soldier indices from its own share of the
one index space, and tells the others on ``ttes/fronts`` what it created and removed.

A front-end allots indices as a single server does, lowest free first, but only the indices of its share:
with N shards, index ``i`` is front-end ``(i // N) % M``'s, so each front-end's soldiers spread evenly over
the shards (``i % N``) and two front-ends creating soldiers at once never pick the same index. The
start-up script's soldiers are created before the share applies, at the same indices in every process.
An index asked for by number must be in the front-end's share (another front-end could allot it).
"""

from __future__ import annotations

import heapq
from collections.abc import Callable


class IndexShare:
    """Front-end ``k`` of ``m``'s free indices below ``max_soldiers`` among ``shards`` shards."""

    def __init__(self, k: int, m: int, shards: int, max_soldiers: int) -> None:
        self.k, self.m, self.shards = k, m, shards
        self._free = [i for i in range(max_soldiers) if self.mine(i)]  # ascending: a heap

    def mine(self, index: int) -> bool:
        return (int(index) // self.shards) % self.m == self.k

    def allot(self, index: int | None, live: Callable[[int], bool]) -> int:
        """``index`` if it is in this share, else the lowest free one of the share (not taken until
        :meth:`taken`: a creation may still fail); ValueError if there is none, or ``index`` is another's."""
        if index is not None:
            if not self.mine(index):
                raise ValueError(f"soldier index {index} is another front-end's (this is {self.k}/{self.m})")
            return int(index)
        while self._free and live(self._free[0]):  # taken by number since (the start-up script's)
            heapq.heappop(self._free)
        if not self._free:
            raise ValueError(f"no free soldier index in front-end {self.k}/{self.m}'s share")
        return self._free[0]

    def taken(self, index: int) -> None:
        if self._free and self._free[0] == index:
            heapq.heappop(self._free)

    def freed(self, index: int) -> None:
        if self.mine(index):
            heapq.heappush(self._free, int(index))
