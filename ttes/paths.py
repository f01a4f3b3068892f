"""Where the shipped data folders live (the repository root, or an installed checkout)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIGURES = ROOT / "figures"
CHANNELSETS = ROOT / "channelsets"
POSTURE_GRAPHS = ROOT / "posture_graphs"
