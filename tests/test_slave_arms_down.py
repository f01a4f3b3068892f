"""A dying slave's arms do not rise once its body is down (authoring/slave_arms_down.py, issue 14: DI
kfire2dead's hand, under the master's early-falling top arm, rose 14.3 cm after it lay)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring.build import BuildContext, slaving_context
from authoring.quality_frames import FigureSet, play
from authoring.quality_rest import ARM_PARTS, _heights, rest_frame
from authoring.slave_arms_down import keep_slave_arms_down
from server.motion.binding import bind_channelset
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES

LIFT = slice(110, 150)  # frames over which the right arm is made to swing up and down again


def _arm_rise(cs, figs: FigureSet, start: int) -> float:
    """From ``start`` on, the most any right arm part's lowest node rises above its lowest since (cm)."""
    h = _heights(play(cs, figs), figs)
    arms = [h[f"right_{p}"][start:] for p in ARM_PARTS]
    return max(float((y - np.minimum.accumulate(y)).max()) for y in arms)


def _lifted(name: str) -> tuple[object, object, FigureSet, int]:
    master = load_channelset(CHANNELSETS / f"{name}.chset.env", use_cache=False)
    slave = load_channelset(CHANNELSETS / f"{name}_low.chset.env", use_cache=False)
    figs = slaving_context(BuildContext.load(FIGURES), name, master).figure_set
    bf = bind_channelset(slave, [figs.figures["DI.fig"]]).figures[0]
    kin = figs.kin["DI.fig"]
    col = bf.src[list(bf.dst).index(kin.dof_slices["right_shoulder"].start)]
    f = np.arange(LIFT.start, min(LIFT.stop, slave.nframes))
    slave.joint_data[f, col] += np.radians(15.0) * np.sin((f - LIFT.start) * np.pi / len(f))
    start = rest_frame(_heights(play(master, figs), figs))
    assert start is not None
    return master, slave, figs, start


def test_an_arm_swinging_up_after_the_body_is_down_is_kept_down() -> None:
    """kfire2dead's DI slave, its right shoulder swung 15 degrees and back once its body is down: its arm
    rises over the check's 3 cm; kept down, no part of it rises more than the check allows, and the frames
    before the master is down are untouched."""
    master, lifted, figs, start = _lifted("kfire2dead")
    assert _arm_rise(lifted, figs, start) > 3.0
    kept = copy.deepcopy(lifted)
    keep_slave_arms_down(master, kept, figs)
    assert _arm_rise(kept, figs, start) < 3.0
    early = start - 12  # the change is smoothed over a few frames before it
    np.testing.assert_allclose(kept.joint_data[:early], lifted.joint_data[:early], atol=1e-6)


def test_a_death_that_does_not_ask_is_left_alone() -> None:
    """kstow2dead does not ask (DeathSpec.slave_arms_down): its slave is unchanged."""
    master, lifted, figs, _ = _lifted("kstow2dead")
    kept = copy.deepcopy(lifted)
    assert keep_slave_arms_down(master, kept, figs) == 0.0
    np.testing.assert_array_equal(kept.joint_data, lifted.joint_data)
