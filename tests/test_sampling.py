"""Playback of one bound channelset and vectorised sampling of many soldiers (seed 002, 3.4.1-3.4.2)."""

from __future__ import annotations

import numpy as np
import pytest

from peabody import quaternion
from server.motion.binding import bind_channelset
from server.motion.channelset import FigureTrack, JointTrack, make_channelset
from server.motion.playback import frame_position, nearest_frame
from server.motion.sampling import ClipLibrary
from server.motion.synthetic import make_figure, make_soldier, synthetic_channelset, toy_rifle, toy_soldier


def ramp_clip(nframes: int = 121, fps: float = 60.0):
    """A 1-DOF clip whose angle equals its frame index: the sampled value *is* the frame shown."""
    fig = make_figure("f", "ramp.fig", [("j", 1)])
    frames = np.arange(nframes, dtype=np.float64)[:, None]
    cs = make_channelset("ramp", fps, [JointTrack("j", "ramp.fig", "j", frames)])
    return fig, cs


class RampPlay:
    """One soldier playing the ramp clip through the vectorised sampler the soldier manager uses."""

    def __init__(self, cs, forward: bool = True, duration: float = -1.0, interpolate: bool = False) -> None:
        self.lib = ClipLibrary([make_figure("f", "ramp.fig", [("j", 1)])])
        self.lib.add(cs)
        self.forward, self.duration, self.interpolate = forward, duration, interpolate
        self.start_time = 0.0
        self.done = False

    def start(self, now: float) -> None:
        self.start_time = now

    def shown(self, now: float) -> float:
        out = self.lib.sample(
            np.zeros(1, np.int64),
            np.array([self.start_time]),
            np.array([1 if self.forward else -1], np.int8),
            np.array([self.duration]),
            now,
            interpolate=self.interpolate,
        )
        self.done = bool(out.ended[0])
        return float(out.joints[0, 0])


# --- frame choice ------------------------------------------------------------------------------------------


def test_two_second_clip_at_60fps_sampled_at_20hz_plays_every_third_frame() -> None:
    _, cs = ramp_clip()
    assert cs.nframes == 121 and cs.size == 120 and cs.duration == pytest.approx(2.0)
    player = RampPlay(cs)
    player.start(10.0)
    frames = [player.shown(10.0 + k / 20.0) for k in range(41)]
    assert frames == [3.0 * k for k in range(41)]
    assert player.done
    assert player.shown(13.0) == 120.0  # held at the end


def test_backwards_play_mirrors_the_frames() -> None:
    _, cs = ramp_clip()
    player = RampPlay(cs, forward=False)
    assert [player.shown(k / 20.0) for k in range(41)] == [120.0 - 3.0 * k for k in range(41)]


def test_time_scaling_stretches_the_clip() -> None:
    _, cs = ramp_clip()
    player = RampPlay(cs, duration=4.0)
    # twice the stored time: 20 Hz now advances 1.5 frames per tick, shown as the nearest frame
    got = [player.shown(k / 20.0) for k in range(81)]
    assert got[::2] == [3.0 * k for k in range(41)]
    assert got[1] == 2.0 and got[3] == 5.0  # 1.5 -> 2, 4.5 -> 5 (round half up)
    fast = RampPlay(cs, duration=1.0)
    assert [fast.shown(k / 20.0) for k in range(21)] == [6.0 * k for k in range(21)]
    assert fast.done


def test_minus_one_means_stored_time() -> None:
    _, cs = ramp_clip()
    p = RampPlay(cs, duration=-1)
    assert p.shown(1.0) == 60.0 and not p.done
    assert p.shown(2.0) == 120.0 and p.done


def test_non_uniform_ticks_recompute_elapsed_time() -> None:
    _, cs = ramp_clip()
    player = RampPlay(cs)
    player.start(5.0)
    ticks = [0.0, 0.01, 0.3, 0.31, 0.95, 1.5, 1.999, 2.0, 2.5]
    got = [player.shown(5.0 + t) for t in ticks]
    assert got == [0.0, 1.0, 18.0, 19.0, 57.0, 90.0, 120.0, 120.0, 120.0]


def test_interpolation_lerps_between_frames() -> None:
    _, cs = ramp_clip()
    player = RampPlay(cs, interpolate=True)
    assert player.shown(0.5 / 60.0) == pytest.approx(0.5, abs=1e-5)
    assert player.shown(1.0 + 0.25 / 60.0) == pytest.approx(60.25, abs=1e-4)


def test_frame_position_reference() -> None:
    assert frame_position(121, 60.0, True, -1, 1.0) == (60.0, False)
    assert frame_position(121, 60.0, False, -1, 0.5) == (90.0, False)
    assert frame_position(121, 60.0, True, -1, 2.0) == (120.0, True)
    assert frame_position(1, 60.0, True, -1, 0.0) == (0.0, True)  # a one-frame clip is over at once


# --- figure channels ---------------------------------------------------------------------------------------


def test_figure_channel_lerps_position_and_slerps_orientation() -> None:
    fig = make_figure("g", "g.fig", [])
    t = np.tile(np.eye(4), (2, 1, 1))
    t[1, :3, 3] = (10.0, 0.0, 0.0)
    c, s = np.cos(np.pi / 2), np.sin(np.pi / 2)
    t[1, :3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]  # 90 deg about y
    cs = make_channelset("g", 1.0, [FigureTrack("g", "g.fig", "g", ["s0.proximal"] * 2, t)])
    pl = bind_channelset(cs, [fig]).sample(0.5).placements["g"]
    assert pl is not None and pl.root == "s0.proximal"
    np.testing.assert_allclose(pl.position, [5, 0, 0], atol=1e-5)
    half = np.array([np.cos(np.pi / 8), 0, np.sin(np.pi / 8), 0])
    np.testing.assert_allclose(pl.quaternion, half, atol=1e-6)


def test_root_site_change_is_never_blended() -> None:
    fig = make_figure("g", "g.fig", [("j", 1)])
    t = np.tile(np.eye(4), (2, 1, 1))
    t[1, :3, 3] = (10.0, 0.0, 0.0)
    cs = make_channelset("g", 1.0, [FigureTrack("g", "g.fig", "g", ["s0.proximal", "s1.distal"], t)])
    b = bind_channelset(cs, [fig])
    assert b.sample(0.4).placements["g"].root == "s0.proximal"  # type: ignore[union-attr]
    late = b.sample(0.6).placements["g"]
    assert late is not None and late.root == "s1.distal" and late.position[0] == 10.0


# --- the clip library --------------------------------------------------------------------------------------


def library_and_clips(nclips: int = 6):
    soldier, rifle = make_soldier(ndof=20), toy_rifle()
    lib = ClipLibrary([soldier, rifle])
    clips = []
    for i in range(nclips):
        cs = synthetic_channelset(
            f"clip{i}", [soldier, rifle], nframes=5 + 7 * i, fps=(30.0, 60.0)[i % 2], seed=i
        )
        assert lib.add(cs) == i
        clips.append(cs)
    return lib, clips, soldier, rifle


@pytest.mark.parametrize("interpolate", [True, False])
def test_vectorised_sampling_equals_the_scalar_reference(interpolate: bool) -> None:
    lib, clips, soldier, rifle = library_and_clips()
    rng = np.random.default_rng(7)
    n = 300
    clip_id = rng.integers(0, len(clips), n)
    start = rng.uniform(0.0, 2.0, n)
    direction = rng.choice([-1, 1], n).astype(np.int8)
    duration = np.where(rng.random(n) < 0.3, -1.0, rng.uniform(0.2, 3.0, n))
    now = 2.3
    out = lib.sample(clip_id, start, direction, duration, now, interpolate=interpolate)
    sl = lib.figure_slice("toy_soldier.fig")
    for i in range(n):
        bound = bind_channelset(clips[clip_id[i]], [soldier, rifle])
        cs = clips[clip_id[i]]
        pos, done = frame_position(
            cs.nframes, cs.fps, bool(direction[i] > 0), float(duration[i]), now - float(start[i])
        )
        if not interpolate:
            pos = float(nearest_frame(pos, cs.nframes))
        ref = bound.sample(pos, interpolate)  # the scalar reference: one bound channelset at one frame
        np.testing.assert_allclose(out.joints[i, sl], ref.poses["soldier"], atol=1e-6)
        assert bool(out.ended[i]) == done
        for k, name in enumerate(["soldier", "rifle"]):
            pl = ref.placements[name]
            assert pl is not None
            np.testing.assert_allclose(out.figures[i, k, :3], pl.position, atol=1e-4)
            assert abs(np.dot(out.figures[i, k, 3:], pl.quaternion)) == pytest.approx(1.0, abs=1e-6)
            assert lib.root_names[out.roots[i, k]] == pl.root


def test_sampling_reuses_output_buffers_and_flags_ended_clips() -> None:
    lib, clips, *_ = library_and_clips(2)
    n = 4
    clip_id = np.array([0, 0, 1, 1])
    start = np.zeros(n)
    direction = np.array([1, -1, 1, -1], dtype=np.int8)
    duration = np.array([-1.0, -1.0, 10.0, 10.0])
    out = lib.sample(clip_id, start, direction, duration, 0.0)
    again = lib.sample(clip_id, start, direction, duration, clips[0].duration, out=out)
    assert again is out
    assert out.ended.tolist() == [True, True, False, False]
    first, last = lib.clip_start[0], lib.clip_start[0] + clips[0].nframes - 1
    np.testing.assert_array_equal(out.joints[0], lib.joint_data[last])  # forwards: held at the last frame
    np.testing.assert_array_equal(out.joints[1], lib.joint_data[first])  # backwards: held at frame 0
    out = lib.sample(clip_id, start, direction, duration, 1e9, out=out)
    assert out.ended.all()


def test_library_fills_undriven_dofs_with_the_neutral_pose() -> None:
    soldier = toy_soldier()
    soldier.joints["neck"].dofs[1].value = 0.25
    partial = make_channelset(
        "waist_only", 10.0, [JointTrack("w", "toy_soldier.fig", "waist", np.zeros((3, 3)))]
    )
    lib = ClipLibrary([soldier])
    lib.add(partial)
    out = lib.sample(np.array([0]), np.zeros(1), np.ones(1), -np.ones(1), 0.1)
    assert out.joints.shape == (1, 7)
    assert out.joints[0, 4] == np.float32(0.25)
    assert out.roots[0, 0] == -1  # no figure channel
    np.testing.assert_array_equal(out.figures[0, 0], [0, 0, 0, 1, 0, 0, 0])


def test_library_layout_and_duplicates() -> None:
    lib, clips, soldier, rifle = library_and_clips(3)
    assert lib.ndof == soldier.dof_count + rifle.dof_count
    assert lib.clip_nframes.tolist() == [c.nframes for c in clips]
    assert lib.clip_start.tolist() == [0, clips[0].nframes, clips[0].nframes + clips[1].nframes]
    assert lib.clip_id("clip2") == 2
    with pytest.raises(ValueError):
        lib.add(clips[0])
    empty = lib.sample(np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros(0), 0.0)
    assert empty.joints.shape == (0, lib.ndof)


def test_slerp_is_unit_and_takes_the_short_way() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(50, 4))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = -a  # same rotations: the short way is no motion at all
    mid = quaternion.slerp(a, b, np.full(50, 0.5))
    np.testing.assert_allclose(np.abs(np.sum(mid * a, axis=1)), 1.0, atol=1e-9)
    m = quaternion.to_matrix(a)
    q = quaternion.from_matrix(m)
    np.testing.assert_allclose(np.abs(np.sum(q * a, axis=1)), 1.0, atol=1e-9)
