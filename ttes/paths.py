"""Where the shipped data folders live: the checkout's root, or an install's copy (``server.data_root``)."""

from __future__ import annotations

from server.data_root import DATA_ROOT

ROOT = DATA_ROOT
FIGURES = ROOT / "figures"
CHANNELSETS = ROOT / "channelsets"
POSTURE_GRAPHS = ROOT / "posture_graphs"
