"""No body part jumps for one frame in the world (``pop_m_s``): constructed clips, and the shipped clips the
check judges (issue 14, session 19's audit: the let-go hand of the standing deaths jumps 13-17 cm in one
60 Hz frame, the prone deaths' forearm twitches 3 cm; no joint angle flicks past 15 degrees there)."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from authoring.quality import THRESHOLDS, FigureSet, check_clip, ground_shift, summarise
from authoring.quality_frames import play
from authoring.quality_pops import POP_LIMIT_M_S, pop_excess, pops
from peabody.loader import read_figure
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset
from tests.known_faults import known_faults

ROOT = Path(__file__).resolve().parents[1]
N = 61  # frames: 1 s at 60 fps


@cache
def _figures() -> FigureSet:
    return FigureSet(
        {n: read_figure(ROOT / "figures" / n) for n in ("soldier.fig", "DI.fig", "AK_47.fig", "M16.fig")}
    )


def _clip(name: str, swing: np.ndarray, lift: np.ndarray) -> Channelset:
    """DI standing (``N`` frames), his right shoulder turned ``swing[k]`` rad and the whole body raised
    ``lift[k]`` cm at frame ``k``; the rifle lies still on the ground beside him."""
    figset = _figures()
    kin = figset.kin["DI.fig"]
    di, ak = figset.figures["DI.fig"], figset.figures["AK_47.fig"]
    shoulder = kin.dof_slices["right_shoulder"].start
    rifle = np.eye(4)
    rifle[:3, 3] = (60.0, 2.0, 0.0)
    rec = Recording([di, ak])
    for k in range(N):
        q = kin.neutral_pose()
        q[shoulder] += swing[k]
        up = np.eye(4)
        up[1, 3] = lift[k]
        rec.append("DI", q, "lower_torso.proximal", up @ di.location)
        rec.append("AK_47", np.zeros(0), "rifle.proximal", rifle)
    return recording_to_channelset(name, rec, 0, N - 1, 60.0)


def test_a_smooth_fast_swing_passes() -> None:
    """The arm swung through 2 rad in 0.3 s (eased in and out: the hand at ~7 m/s at its fastest) speeds up
    and slows down over several frames."""
    t = np.arange(N) / 60.0
    swing = 2.0 * (1.0 - np.cos(np.pi * np.clip((t - 0.2) / 0.3, 0.0, 1.0))) / 2.0
    row = check_clip(_clip("stand.chset", swing, np.zeros(N)), _figures())
    assert 0.0 < row["pop_m_s"] < 0.5 * POP_LIMIT_M_S, row["pop_m_s"]
    assert "pop_m_s" not in row["failures"]


def test_a_one_frame_jump_of_15_cm_fails() -> None:
    lift = np.where(np.arange(N) >= 30, 15.0, 0.0)  # up 15 cm between frames 29 and 30, and stays
    row = check_clip(_clip("stand.chset", np.zeros(N), lift), _figures())
    assert row["pop_m_s"] == pytest.approx(9.0, abs=0.01) and row["pop_where"].endswith("[30]")
    assert "pop_m_s" in row["failures"]
    table = summarise([row], [])["thresholds"]
    assert table["pop_m_s"]["limit"] == POP_LIMIT_M_S == THRESHOLDS["pop_m_s"]
    assert not table["pop_m_s"]["pass"] and table["pop_m_s"]["where"].startswith("stand.chset (")


def test_a_twitch_of_one_frame_fails() -> None:
    """The prone deaths' forearm: 3 cm off its path for one frame and back, out of stillness."""
    lift = np.where(np.arange(N) == 20, 3.0, 0.0)
    row = check_clip(_clip("stand.chset", np.zeros(N), lift), _figures())
    assert row["pop_m_s"] == pytest.approx(1.8, abs=0.01) and row["pop_where"].endswith("[20]")
    assert "pop_m_s" in row["failures"]


def test_a_swing_at_its_fastest_or_a_landing_is_not_a_twitch() -> None:
    """Speeds of one node along x (m/s per interval): a bell over a few frames scores its curvature, two fast
    intervals the same way are no twitch, a foot stopping on the ground scores half its last speed."""
    bell = np.array([0.7, 3.9, 6.9, 7.5, 5.9, 3.2, 0.5])
    assert pop_excess(np.stack([bell, 0 * bell, 0 * bell], axis=-1)[:, None]).max() < POP_LIMIT_M_S
    flat = np.array([0.0, 0.0, 2.0, 2.0, 0.0, 0.0])
    assert pop_excess(np.stack([flat, 0 * flat, 0 * flat], axis=-1)[:, None]).max() == 0.0
    landing = np.array([1.4, 1.5, 1.7, 0.3, 0.3])
    assert pop_excess(np.stack([landing, 0 * landing, 0 * landing], axis=-1)[:, None]).max() < POP_LIMIT_M_S


# Clips the check fails (session 19): each names what a person sees; strict: a mended clip leaves it.
_LETGO = "at the let-go (0.38 s) the right hand flies off the grip {} cm in one frame"
_ARM = "turning on the crawl, the right upper arm jumps {} cm in one frame ({} s) and stops"
KNOWN_POPS: dict[str, str] = {
    "stfire2dead": "landing on his face (1.08 s) the left hand slaps down onto the ground (1.87 m/s)",
    "stfire2dead_low": "landing on his face (1.12 s) the right forearm slaps down onto the ground (1.79 m/s)",
    "stfire2dead_m16_low": "at the let-go (0.38 s) the right hand leaves the M16 in one frame (2.27 m/s)",
    "kstow2dead": "at the let-go (0.20 s) the right hand flies off the grip 12.2 cm in one frame",
    "kstow2dead_low": "at the let-go (0.20 s) the right hand flies off the grip 13.6 cm in one frame",
    "kstow2dead_m16_low": "falling from the knee, the right foot kicks 9.3 cm in one frame (0.48 s)",
    "kfire2dead": "landing on his side (1.28 s) his left upper arm and chest drop 7.4-7.9 cm in one frame",
    "kfire2dead_low": "at the let-go (0.23 s) the right hand flies off the grip 6.4 cm in one frame",
    "kfire2dead_m16_low": "landing on his side (1.28 s) the left forearm drops 9.4 cm in one frame",
    "crawlarc_l135_m16_low": "turning on the crawl, the belly pops 1.72 m/s in one frame (2.53 s)",
    "crawlarc_r180_far": _ARM.format(4.1, 3.20),
}
CLIPS = sorted(p.name.split(".")[0] for p in (ROOT / "channelsets").glob("*.chset.env"))


def shipped_pops(clip: str) -> dict[str, Any]:
    """``pop_m_s`` of a shipped channelset, from its body mesh nodes in the world (an in-place clip that
    records a ``ground_speed`` travels at it, as the check has it)."""
    figures = _figures()
    cs = load_channelset(ROOT / "channelsets" / f"{clip}.chset.env")
    frames = play(cs, figures)
    body = max(frames.poses, key=lambda k: figures.kin[k].ndof)
    nodes, segs = figures.nodes(body)
    segg = figures.kin[body].segment_globals(frames.poses[body], frames.locations[body])
    pts = np.einsum("fkij,kj->fki", segg[:, segs, :3, :], nodes) + ground_shift(cs, True)[:, None, :]
    return pops(pts, figures.node_parts(body), cs.fps)


@pytest.mark.parametrize("clip", known_faults(CLIPS, KNOWN_POPS))
def test_the_shipped_clips_do_not_pop(clip: str) -> None:
    row = shipped_pops(clip)
    assert row["pop_m_s"] <= POP_LIMIT_M_S, row
