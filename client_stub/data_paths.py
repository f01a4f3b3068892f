"""The clients' own data files, kept inside this package so that a wheel carries them (setup.py's package
data): the village terrain and the figures' TIPS geometry (``data/``), the crowd's near level
(``crowd/data/``)."""

from __future__ import annotations

from pathlib import Path

STUB_DATA = Path(__file__).resolve().parent / "data"
CROWD_DATA = Path(__file__).resolve().parent / "crowd" / "data"
DEFAULT_TERRAIN = STUB_DATA / "village.glb"
