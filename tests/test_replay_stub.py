"""The stub fed by DIS (DisSoldiers) without a window: DIS soldiers placed in the stub on the terrain, looked
after by force and camouflage, hidden when they time out and back in their slot when they return (offline
posing)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from test_replay_translator import FRAME, make_log, pdu

from client_stub.dis import Replayer
from client_stub.dis.soldiers import LOOK_BASE, look_colour, look_of, replay_app
from client_stub.link.buffer import UpdateBatch
from client_stub.stub.render import FORCE_UNIFORMS
from client_stub.stub.simsoldier import Force
from client_stub.stub.terrain import DEFAULT_TERRAIN, Terrain, load_terrain
from protocol.dis.appearance import LifeformState
from protocol.entity import Appearance, WeaponState
from protocol.update_table import UpdateTable


@functools.cache
def village() -> Terrain:
    return load_terrain(DEFAULT_TERRAIN)


def test_dis_soldiers_in_the_stub(tmp_path: pytest.TempPathFactory) -> None:
    entries = [(0.0, pdu(1, (10.0, 20.0), speed=1.5, heading=90.0, state=LifeformState.UPRIGHT_WALKING)),
               (0.0, pdu(2, (-30.0, 5.0), force=2, paint=1, state=LifeformState.KNEELING)),
               (1.0, pdu(2, (-30.0, 5.0), force=2, paint=1, state=LifeformState.KNEELING)),
               (30.0, pdu(1, (40.0, 20.0), state=LifeformState.PRONE))]  # fmt: skip
    replayer = Replayer(make_log(entries), origin=FRAME, timeout=12.0)
    app = replay_app(village(), replayer, artic_dir=tmp_path)
    dis = app.source
    app.frame(0.0)
    s = app.soldiers
    assert s.count == 2 and s.alive[:2].all()
    for _ in range(20):  # 2 s at 10 frames a second
        app.frame(0.1)
    # soldier 0 walked east for 2 s at 1.5 m/s (dead reckoning between PDUs), feet on the ground
    assert s.position[0, :2] == pytest.approx([13.0, 20.0], abs=0.05)
    ground = village().height(s.position[0:1, :2], s.position[0:1, 2] + 2.0)[0]  # the ray from above
    assert s.position[0, 2] == pytest.approx(float(ground), abs=1e-6) and s.position[0, 2] < 1.5  # no roof
    assert s.heading[0] == pytest.approx(90.0, abs=0.01) and s.speed[0] == pytest.approx(1.5, abs=1e-3)
    assert (s.appearance[0], s.appearance[1]) == (Appearance.UPRIGHT, Appearance.KNEEL)
    assert s.weapon[1] == WeaponState.DEPLOYED
    # forces and looks: friendly uniform vs opposing forest camouflage; the rifle from the entity type
    assert (s.force[0], s.force[1]) == (Force.FRIENDLY, Force.OPPOSING)
    assert app.look[0] != app.look[1] and app.look[1] >= LOOK_BASE
    assert FORCE_UNIFORMS[int(app.look[1])] == look_colour(int(app.look[1]) - LOOK_BASE)
    assert [app.kinds[int(app.slot_kind[i])].weapon for i in (0, 1)] == ["M16.fig", "AK_47.fig"]
    # both time out (last PDUs at 0 s and 1 s), soldier 0 comes back at 30 s in his old slot, prone
    for _ in range(140):
        app.frame(0.1)
    assert not s.alive[:2].any()
    assert not app.kinds[int(app.slot_kind[0])].crowd.active[0]
    for _ in range(150):
        app.frame(0.1)
    assert s.count == 2 and s.alive[0] and not s.alive[1]
    assert s.appearance[0] == Appearance.PRONE and s.position[0, :2] == pytest.approx([40.0, 20.0], abs=0.05)
    # the squad camera frames the live soldiers; keys that would drive a soldier are refused
    assert "DIS PDUs drive" in (app.handle_key("3") or "")
    dis.squad_view = True
    pose = app.camera_pose()
    to_soldier = s.position[0] - pose[:3, 3]
    assert np.dot(to_soldier / np.linalg.norm(to_soldier), -pose[:3, 2]) > 0.95  # looking at him
    app.handle_key("b")
    assert not dis.squad_view


def test_looks_tell_forces_and_camouflage_apart() -> None:
    force = np.array([1, 1, 2, 2, 3, 1])
    paint = np.array([0, 1, 0, 1, 0, 1])
    camo = np.array([0, 2, 0, 2, 0, 1])
    looks = look_of(force, paint, camo).tolist()
    assert len(set(looks)) == 6
    colours = [look_colour(k) for k in looks]
    friendly, opposing = np.array(colours[:2]), np.array(colours[2:4])
    assert (opposing[:, 0] > opposing[:, 1]).all()  # opposing: reddish
    assert (friendly[:, 1] >= friendly[:, 0]).all()  # friendly: greenish


class FakeLink:
    """A server link that records what the stub sends and hands back joint updates we make up."""

    def __init__(self, table: UpdateTable) -> None:
        self.tables = {table.table_id: table}
        self.ready_soldiers = {0: 1, 1: 1}  # two soldiers from the start-up script
        self.max_soldiers = 64
        self.sent: list[tuple] = []
        self.pending: list[UpdateBatch] = []

    def create(self, index: int, figure: str, weapon: str) -> int:
        self.sent.append(("create", index, figure, weapon))
        return len(self.sent)

    def remove(self, index: int) -> None:
        self.sent.append(("remove", index))

    def subscribe(self, indices: list[int]) -> None:
        self.sent.append(("subscribe", *(int(i) for i in indices)))

    def send_requests(self, rows: np.ndarray) -> None:
        self.sent.append(("requests", rows["index"].tolist(), rows["appearance"].tolist()))

    def react(self, indices: np.ndarray, kind: int) -> None:
        self.sent.append(("react", int(kind), *(int(i) for i in indices)))

    def swap(self) -> list[UpdateBatch]:
        out, self.pending = self.pending, []
        return out


def test_server_soldiers_pose_the_stub_through_the_wire_table(tmp_path: pytest.TempPathFactory) -> None:
    prone = LifeformState.PRONE
    entries = [(0.0, pdu(1, (5.0, 5.0), force=2)), (0.5, pdu(1, (5.0, 5.0), force=2, state=prone))]
    replayer = Replayer(make_log(entries), origin=FRAME)
    app = replay_app(village(), replayer, artic_dir=tmp_path)
    kind = app.kinds[app.kind("DI.fig", "AK_47.fig")]
    wire = dataclasses.replace(kind.table, table_id=7)  # a server whose table matches the stub's figure
    link = FakeLink(wire)
    app = replay_app(village(), replayer, link=link, artic_dir=tmp_path)
    app.frame(0.0)
    assert link.sent[:3] == [("create", 2, "DI.fig", "AK_47.fig"), ("subscribe", 2), ("requests", [2], [2])]
    assert app.server_of[0] == 2 and app.slot_of_server[2] == 0  # bound: the server poses him
    k = app.kinds[int(app.slot_kind[0])]
    q = np.full((1, wire.ndofs), 0.25)
    link.pending = [UpdateBatch(7, np.array([2]), q, np.zeros((1, wire.nfigures, 3)),
                                np.tile([1.0, 0.0, 0.0, 0.0], (1, wire.nfigures, 1)))]  # fmt: skip
    app.frame(0.6)
    assert link.sent[-1] == ("requests", [2], [Appearance.PRONE])
    assert k.crowd.dofs[0] == pytest.approx(np.full(k.crowd.dofs.shape[1], 0.25))
    app.source.finish(app)
    assert link.sent[-1] == ("remove", 2) and not app.soldiers.alive[0]
