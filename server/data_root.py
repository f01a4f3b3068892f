"""Where the shipped data lives: ``figures/``, ``channelsets/``, ``posture_graphs/`` and the start-up script.

The one answer for the server's default data dir (``server.config``) and for ``ttes``' paths (``ttes.paths``).
In a checkout, or an editable install, it is the repository root, whose folders ``ttes author`` writes. A
wheel has no repository root, so it carries copies of the folders in this package's ``data/`` (setup.py), and
an install reads those. If neither holds the data the checkout root is still the answer, so that whatever
fails to load names a path.
"""

from __future__ import annotations

from pathlib import Path

SEARCH_SUBDIRS = ("figures", "channelsets", "posture_graphs")  # read_file's search path below the data dir
CHECKOUT_ROOT = Path(__file__).resolve().parent.parent
WHEEL_DATA = Path(__file__).resolve().parent / "data"


def find_data_root(candidates: tuple[Path, ...] = (WHEEL_DATA, CHECKOUT_ROOT)) -> Path:
    """The first candidate holding every shipped data folder (else the last candidate)."""
    for root in candidates:
        if all((root / sub).is_dir() for sub in SEARCH_SUBDIRS):
            return root
    return candidates[-1]


DATA_ROOT = find_data_root()
