"""What every bench report states about the run: the machine's CPUs, its load average before the bench
started (timings on a shared machine measure the neighbours too), and the bench's wall time."""

from __future__ import annotations

import os
import time


class Machine:
    """Taken at a bench's start; :meth:`facts` at its end."""

    def __init__(self) -> None:
        self.load_before = os.getloadavg()
        self.t0 = time.perf_counter()

    def facts(self) -> dict[str, object]:
        return {
            "cpus": os.cpu_count(),
            "loadavg_before": [round(x, 2) for x in self.load_before],
            "wall_s": round(time.perf_counter() - self.t0, 1),
        }
