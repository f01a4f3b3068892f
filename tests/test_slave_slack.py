"""A dead slave's feet go slack as the master's do (authoring/slave_slack.py, issue 14): once he has come to
rest, its ankles and toes go to his angles as far along as his feet have gone, and end as his."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.quality_frames import FigureSet, play
from authoring.slave_slack import JOINTS, STILL_FRAMES, follow_slack, slack_progress
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES


def _master(n_land: int = 30, n_still: int = 20, n_slack: int = 40, n_end: int = 10) -> np.ndarray:
    """Two foot angles (radians): moving as he lands, still, going slack (eased), still to the end."""
    land = np.linspace(0.0, 0.5, n_land)
    u = np.linspace(0.0, 1.0, n_slack + 1)[1:]
    slack = 0.5 + 0.4 * u * u * (3.0 - 2.0 * u)
    a = np.concatenate([land, np.full(n_still, 0.5), slack, np.full(n_end, 0.9)])
    return np.stack([a, -a], axis=1)


def test_the_slack_starts_after_he_lies_still_and_follows_his_feet() -> None:
    m = _master()
    w = slack_progress(m)
    assert (w[:50] == 0.0).all()  # landing and lying still: not yet
    assert (np.diff(w) >= 0.0).all() and w[-1] == pytest.approx(1.0)
    assert (w[90:] == 1.0).all()  # done when his feet are
    change = np.abs(np.diff(m[:, 0]))
    assert w[70] == pytest.approx(change[49:70].sum() / change[49:90].sum())


def test_no_slack_without_rest_before_it() -> None:
    assert not slack_progress(_master(n_still=STILL_FRAMES - 3)).any()
    assert not slack_progress(np.zeros((50, 2))).any()


def test_the_slave_foot_ends_as_his_and_moves_only_with_his() -> None:
    m = _master()
    own = np.full_like(m, 0.2)
    own[:50] = np.linspace(0.0, 0.2, 50)[:, None]
    own[50:] += 0.3 * np.sin(np.arange(len(m) - 50))[:, None]  # its own solve swung it after he lay still
    out = follow_slack(own, m)
    np.testing.assert_array_equal(out[:50], own[:50])
    np.testing.assert_allclose(out[-1], m[-1])
    np.testing.assert_allclose(out[90:], np.broadcast_to(m[-1], out[90:].shape))  # still once his are


def test_the_di_crawler_dies_with_his_feet() -> None:
    """crawl2dead's DI and M16 slaves end with the master's ankles and toes (his everted 30 degrees, the
    toes a little up; solved to his foot points they ended everted the other way, toes curled to 70)."""
    figs = FigureSet.from_dir(FIGURES, ("soldier.fig", "DI.fig", "AK_47.fig", "M16.fig"))
    master = play(load_channelset(CHANNELSETS / "crawl2dead.chset.env", use_cache=False), figs)
    mq = master.poses["soldier.fig"]
    for name in ("crawl2dead_low", "crawl2dead_m16_low"):
        slave = play(load_channelset(CHANNELSETS / f"{name}.chset.env", use_cache=False), figs)
        q = slave.poses["DI.fig"]
        for side in ("left", "right"):
            for j in JOINTS:
                joint = f"{side}_{j}"
                ms, ss = figs.kin["soldier.fig"].dof_slices[joint], figs.kin["DI.fig"].dof_slices[joint]
                np.testing.assert_allclose(q[-1, ss], mq[-1, ms], atol=1e-4, err_msg=f"{name} {joint}")
