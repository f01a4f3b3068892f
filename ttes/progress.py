"""Progress bars for the long jobs (the headless stub, `ttes demo`, `ttes loadtest`): tqdm on stderr, with the
total and the ETA, never on stdout (where --json goes).

Shown when stderr is a terminal; ``TTES_PROGRESS=1`` shows them anyway (a log file, a test), ``=0`` never.
The jobs report absolute positions (scene seconds, a stage's seconds), so :class:`ProgressBar` is a callable
``bar(done, total, stage="")``: a new stage (a load-test ramp's next N) restarts the bar under its name.
"""

from __future__ import annotations

import os
import sys
from types import TracebackType
from typing import Any

ENV = "TTES_PROGRESS"
BAR_FORMAT = "{l_bar}{bar}| {n:.1f}/{total:.1f} {unit} [{elapsed}<{remaining}]"  # l_bar: "desc:  45%|"


def wanted() -> bool:
    """Whether to draw bars: ``$TTES_PROGRESS`` (1/0) if set, else whether stderr is a terminal."""
    setting = os.environ.get(ENV, "").strip()
    if setting:
        return setting not in ("0", "no", "false")
    return sys.stderr.isatty()


WAIT_FORMAT = "{desc}: {n:.1f} {unit}"  # a wait of unknown length: the seconds so far


class ProgressBar:
    """``ttes stub:  45%|████      | 18.0/40.0 s [00:09<00:11]``; a no-op when bars are not wanted. A wait of
    unknown length (``total`` None: a spawned server loading its library) shows the seconds so far."""

    def __init__(self, desc: str, unit: str = "s", *, enabled: bool | None = None) -> None:
        self.desc = desc
        self.unit = unit
        self.stage = ""
        self.bar: Any = None
        self.wait_bar: Any = None
        self.enabled = wanted() if enabled is None else enabled

    def __call__(self, done: float, total: float | None, stage: str = "") -> None:
        if not self.enabled:
            return
        if total is None:
            self._wait(done, stage)
            return
        if self.wait_bar is not None:
            self.wait_bar.close()
            self.wait_bar = None
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=self._label(stage), unit=self.unit, file=sys.stderr,
                            bar_format=BAR_FORMAT, dynamic_ncols=True)  # fmt: skip
            self.stage = stage
        elif stage != self.stage or total != self.bar.total:
            self.bar.refresh()  # the stage's last position, before the bar starts again
            self.bar.reset(total=total)
            self.bar.set_description(self._label(stage))
            self.stage = stage
        self.bar.update(max(0.0, min(done, total) - self.bar.n))

    def waited(self, seconds: float) -> None:
        """The seconds waited so far on something of unknown length (a callback for ``spawn_server``)."""
        self(seconds, None)

    def _wait(self, seconds: float, stage: str) -> None:
        if self.wait_bar is None:
            from tqdm import tqdm

            self.wait_bar = tqdm(total=None, desc=self._label(stage), unit=self.unit, file=sys.stderr,
                                 bar_format=WAIT_FORMAT, mininterval=0.5)  # fmt: skip
        self.wait_bar.update(max(0.0, seconds - self.wait_bar.n))

    def _label(self, stage: str) -> str:
        return f"{self.desc} {stage}" if stage else self.desc

    def close(self) -> None:
        if self.wait_bar is not None:
            self.wait_bar.close()
            self.wait_bar = None
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
