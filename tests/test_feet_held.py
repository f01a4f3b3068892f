"""A falling soldier's foot stays where it leaves the ground: the shin does not kick up (authoring.feet_held,
issue 14: stfire2dead's shins swung up 45 degrees as his thighs came down flat)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.feet_held import held_feet, lift_off
from authoring.postures import lowest_point
from authoring.quality import CONTACT_HEIGHT_CM
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.loader import read_figure
from ttes.paths import FIGURES

N, KICK_FROM, KICK_TO = 40, 10, 30  # frames: the right knee bends between these
KICK_DEG = 90.0  # this far: the right shin swings up behind him, the foot off the ground


@pytest.fixture(scope="module")
def kick() -> tuple[FigureSet, ClipFrames]:
    """soldier.fig standing, his feet on the ground, then his right knee bending: the shin kicks up."""
    figs = FigureSet({"body": read_figure(FIGURES / "soldier.fig")})
    kin = figs.kin["body"]
    poses = np.zeros((N, kin.ndof))
    bend = np.clip((np.arange(N) - KICK_FROM) / (KICK_TO - KICK_FROM), 0.0, 1.0)
    poses[:, kin.dof_slices["right_knee"].start] = np.radians(KICK_DEG) * bend
    roots = np.tile(np.eye(4), (N, 1, 1))
    roots[:, 1, 3] = -float(lowest_point(kin, poses[0], np.eye(4)))  # standing on the ground
    return figs, ClipFrames(poses, roots, roots.copy(), 60.0)


def _foot_low(figs: FigureSet, frames: ClipFrames, side: str) -> np.ndarray:
    kin = figs.kin["body"]
    nodes, segs = figs.nodes("body")
    sel = figs.node_parts("body") == f"{side}_foot"
    g = kin.segment_globals(frames.poses, frames.roots)
    return np.einsum("fkj,kj->fk", g[:, segs[sel], 1, :], nodes[sel]).min(axis=1)


def test_the_foot_stays_on_the_ground_where_the_shin_would_kick_up(
    kick: tuple[FigureSet, ClipFrames],
) -> None:
    figs, frames = kick
    kin = figs.kin["body"]
    recorded = _foot_low(figs, frames, "right")
    start = lift_off(recorded)
    assert start is not None and KICK_FROM <= start < KICK_TO and recorded.max() > 20.0  # the shin kicks up
    held = held_feet(frames, figs.figures["body"])
    assert _foot_low(figs, held, "right").max() <= CONTACT_HEIGHT_CM  # the foot stays down
    sites = [kin.site_names.index(f"right_{s}") for s in ("foot.ball", "toes.distal")]
    at = kin.site_globals(held.poses, held.roots)[:, sites][..., :3, 3]
    assert np.abs(at[start:] - at[start]).max() < 0.5  # where it was (cm): no skating
    np.testing.assert_array_equal(held.poses[: start + 1], frames.poses[: start + 1])  # untouched before
    left = np.concatenate(
        [np.arange(s.start, s.stop) for n, s in kin.dof_slices.items() if n.startswith("left")]
    )
    np.testing.assert_array_equal(
        held.poses[:, left], frames.poses[:, left]
    )  # a foot that stays down: as it is
    assert np.all(held.poses >= kin.lower - 1e-9) and np.all(held.poses <= kin.upper + 1e-9)


def test_a_foot_never_on_the_ground_or_never_off_it_is_left_alone() -> None:
    assert lift_off(np.full(5, 10.0)) is None
    assert lift_off(np.zeros(5)) is None
    assert lift_off(np.array([0.0, 0.5, 3.0, 0.0])) == 1


def test_the_shipped_standing_fire_death_lays_its_shins_down_with_him() -> None:
    """Issue 14: stfire2dead lay face down with both shins up ~45 degrees from 1.17 to 1.5 s, the feet 11-19
    cm off the ground, his legs lifted to turn out after he was down (the knee rose 6.9 cm): now, once his
    trunk is down, no leg point rises and his feet are on the ground within 0.25 s."""
    from authoring.quality_frames import play
    from authoring.quality_rest import RISE_LIMIT_CM, _heights, down_frame, pelvis_turn, rise_after
    from server.motion.cache import load_channelset
    from ttes.paths import CHANNELSETS

    figs = FigureSet.from_dir(FIGURES, ["soldier.fig", "AK_47.fig"])
    cf = play(load_channelset(CHANNELSETS / "stfire2dead.chset.env", use_cache=False), figs)
    h = _heights(cf, figs)
    down = down_frame(h, turned=pelvis_turn(cf, figs))
    assert down is not None
    legs = {
        k: v
        for k, v in h.items()
        if k.startswith(("left_foot", "right_foot", "left_lower_leg", "right_lower_leg"))
    }
    assert rise_after(legs, down)[0] <= RISE_LIMIT_CM
    soon = down + round(0.25 * cf.channelset.fps)
    assert max(h["left_foot"][soon], h["right_foot"][soon]) <= CONTACT_HEIGHT_CM
