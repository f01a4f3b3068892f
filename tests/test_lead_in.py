"""Starts that begin at once (issue 16): the first update after a request already differs from the old pose.

Several shipped clips open with frames that show nothing new on the wire (kneel -> stand 5 frames, getting
up from DEAD up to 10, most transitions 1-3 eased in: 17-280 ms). A request answered between ticks
(``SoldierManager.answer``, published as ``ttes server`` publishes it) then sent the old pose and the first
visible change waited for a later tick. A clip a request starts now begins at its first moving frame.
No timing here: explicit times, the pose board's codes.
"""

from __future__ import annotations

import functools
import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from client_stub.loadtest.mix import MOVING, SPECS, Activity
from peabody.model import Figure
from protocol.entity import make_entity_requests
from protocol.update_table import DEFAULT_DOF_BITS
from server.motion.channelset import JointTrack, make_channelset
from server.motion.sampling import ClipLibrary
from server.motion.synthetic import make_soldier
from server.pose_board import PoseBoard
from server.soldier.lead_in import lead_in_fractions
from server.startup import ServerWorld

REPO = Path(__file__).resolve().parent.parent
HZ = 30.0
STEP = 2 * math.pi / (1 << DEFAULT_DOF_BITS)  # one code of a rotational DOF on the wire
SETTLE = 180  # ticks (6 s): every transition of the mix has ended
LATE = 0.95  # the request's phase in its tick period: 1.7 ms before the tick the answer anticipates


@functools.cache
def shipped_world() -> ServerWorld:
    world = ServerWorld(REPO)
    world.run_startup("jack-ttes-soldier_low.jcl")
    return world


def requests(idx: list[int], acts: list[Activity], heading: float = 0.0) -> np.ndarray:
    s = [SPECS[a] for a in acts]
    h = math.radians(heading)
    vel = [(x.speed * math.sin(h), x.speed * math.cos(h), 0.0) for x in s]
    return make_entity_requests(
        np.array(idx), [x.appearance for x in s], [x.weapon for x in s], vel, heading, (0.0, 0.0, 0.0)
    )


class Rig:
    """Fresh soldiers on the shipped world, published to a pose board the way the server publishes."""

    def __init__(self, n: int) -> None:
        self.world = shipped_world()
        self.m = self.world.manager
        assert self.m is not None
        table = self.world.sets[0].table
        self.board = PoseBoard(table.ndofs, table.nfigures)
        self.idx = [self.m.create_soldier(figure="DI.fig", weapon="AK_47.fig", now=0.0) for _ in range(n)]
        for i in self.idx:
            self.board.add(i, self.world.table_of(i))
        self.k = 0

    def close(self) -> None:
        for i in self.idx:
            self.m.remove_soldier(i)

    def ticks(self, n: int) -> None:
        for _ in range(n):
            self.board.publish(self.m.tick(self.k / HZ), self.world)
            self.k += 1

    def request_and_answer(self, rows: np.ndarray, phase: float = LATE) -> np.ndarray:
        """Requests ``phase`` of a period before the next tick, then the server's answer: which soldiers'
        codes changed on the wire (bool per row)."""
        t = (self.k - 1 + phase) / HZ
        self.m.apply_requests(rows, t)
        self.board.publish(self.m.answer(t, self.k / HZ), self.world, between=True)
        return self.board.version[rows["index"].astype(np.int64)] == self.board.serial


@pytest.fixture
def rig_of():
    made: list[Rig] = []

    def make(n: int) -> Rig:
        made.append(Rig(n))
        return made[-1]

    yield make
    for r in made:
        r.close()


def test_every_request_of_the_load_mix_is_visible_in_its_answer(rig_of) -> None:
    """Each resting activity of ``ttes loadtest``'s mix -> each other activity, asked 1.7 ms before a tick."""
    pairs = [(a, b) for a, b in itertools.product(Activity, Activity) if a != b and not MOVING[a]]
    rig = rig_of(len(pairs))
    rig.m.apply_requests(requests(rig.idx, [a for a, _ in pairs]), 0.0)
    rig.ticks(SETTLE)
    assert all(rig.m.soldier_info(i)["mode"] == "IDLE" for i in rig.idx)
    seen = rig.request_and_answer(requests(rig.idx, [b for _, b in pairs]))
    late = [f"{a.name}->{b.name}" for (a, b), ok in zip(pairs, seen, strict=True) if not ok]
    assert late == []


def test_the_skipped_lead_in_is_no_jump(rig_of) -> None:
    """Kneel -> stand starts at its first moving frame: the answer is a step or two of the wire from the
    kneeling pose, not a pop, and the transition ends as much earlier as it skipped."""
    rig = rig_of(1)
    i = rig.idx[0]
    rig.m.apply_requests(requests([i], [Activity.KNEEL]), 0.0)
    rig.ticks(SETTLE)
    kneeling = rig.board.dofs[i].copy()
    t = (rig.k - 1 + LATE) / HZ
    assert rig.request_and_answer(requests([i], [Activity.STAND])).tolist() == [True]
    info = rig.m.soldier_info(i)
    assert info["clip"].endswith("ststow2kstow_low") and info["mode"] == "TRANSITION"
    skipped = t - info["clip_start"]
    assert 0.0 < skipped < 0.1  # its 5 still frames at 60 fps (83 ms), not more
    assert info["clip_start"] + info["clip_duration"] == pytest.approx(t - skipped + info["clip_duration"])
    d = np.abs((rig.board.dofs[i] - kneeling + np.pi) % (2 * np.pi) - np.pi)
    assert STEP <= d.max() < 4 * STEP


def test_lead_in_fractions_count_the_still_frames_each_way() -> None:
    """Frames within a wire step of the first (in the direction played) are the lead-in; a clip that never
    moves by a step has none to skip."""
    fig: Figure = make_soldier(ndof=4)
    lib = ClipLibrary([fig])
    joint = next(iter(fig.joints))
    width = fig.joints[joint].ndofs
    ramp = np.concatenate([np.zeros(3), np.linspace(0.1, 0.5, 5), np.full(3, 0.5)])
    tiny = np.full(11, 0.3 * STEP)
    tiny[0] = 0.0
    for name, first in (("ramp", ramp), ("still", np.zeros(11)), ("tiny", tiny)):
        data = np.zeros((11, width))
        data[:, 0] = first
        lib.add(make_channelset(name, 10.0, [JointTrack(joint, "toy_soldier.fig", joint, data)]))
    lead = lead_in_fractions(lib, np.full(lib.ndof, STEP), 0.1, 1e-3)
    assert lead.shape == (3, 2)
    # ramp: frames 0-2 equal, frame 3 moves 0.1 rad: 3 of 10 intervals; backwards frames 10-7 equal, 6 moves
    np.testing.assert_allclose(lead[0], [0.3, 0.4])
    np.testing.assert_array_equal(lead[1:], 0.0)


def test_every_request_of_the_load_mix_moves_the_joints_when_answered_at_its_own_time(rig_of) -> None:
    """Asked at the very time its answer samples (a request that lands while the tick samples is answered
    in that tick's first frames, at the tick's time; a late tick samples at the request's): each resting
    activity of the mix -> each other activity already moves a joint by a wire step, as an image generator
    draws it, not only the root offset. Walk and run starts (their first frame still) showed nothing new
    then and waited for the next tick."""
    pairs = [(a, b) for a, b in itertools.product(Activity, Activity) if a != b and not MOVING[a]]
    rig = rig_of(len(pairs))
    rig.m.apply_requests(requests(rig.idx, [a for a, _ in pairs]), 0.0)
    rig.ticks(SETTLE)
    rows = np.array(rig.idx)
    before = rig.board.codes[rows].copy()
    rig.request_and_answer(requests(rig.idx, [b for _, b in pairs]), phase=1.0)
    ndofs = rig.board.ndofs
    moved = (rig.board.codes[rows, :ndofs] != before[:, :ndofs]).any(axis=1)
    late = [f"{a.name}->{b.name}" for (a, b), ok in zip(pairs, moved, strict=True) if not ok]
    assert late == []
