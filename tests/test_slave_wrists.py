"""A slave's wrist eased where it flicks and the master's does not (authoring/slave_wrists.py, issue 16)."""

from __future__ import annotations

import numpy as np

from authoring import slave_wrists
from authoring.quality import frame_flicks


def _wrist(n: int = 90) -> np.ndarray:
    """Two DOFs of a wrist turning smoothly (radians, ``(n, 2)``)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.radians(np.hstack([-60.0 + 10.0 * t, -30.0 + 5.0 * t]))


def _flick_deg(q: np.ndarray) -> float:
    return float(
        frame_flicks(q, np.ones(q.shape[1], bool), {"left_wrist": slice(0, q.shape[1])})[
            "max_frame_flick_deg"
        ]
    )


def test_a_wrist_flicking_off_its_limits_where_the_master_is_still_is_eased() -> None:
    """crawlarc_l135_low's left wrist: off its limits and back in one frame (8-14 degrees), the arm above it
    smooth; eased, its flick is under the check's 15 degrees by far, and the clip's ends are untouched (every
    clip meeting at CRAWL shares them)."""
    master = _wrist()
    slave = master.copy()
    slave[45] += np.radians([9.0, 5.0])
    slave[47] += np.radians([12.0, 7.0])
    assert _flick_deg(slave) > 15.0
    out, w = slave_wrists.eased(slave, master)
    assert _flick_deg(out) < 5.0 and w[45] == 1.0
    np.testing.assert_array_equal(out[[0, -1]], slave[[0, -1]])


def test_a_wrist_the_master_flicks_too_or_that_turns_smoothly_is_left_alone() -> None:
    smooth = _wrist()
    out, w = slave_wrists.eased(smooth, smooth)
    assert not w.any() and out is smooth
    flicking = smooth.copy()
    flicking[45] += np.radians([12.0, 7.0])
    out, w = slave_wrists.eased(flicking, flicking)
    assert not w.any()
