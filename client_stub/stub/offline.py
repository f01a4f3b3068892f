"""Offline posing: rough soldier postures when no Jack/TTES server is connected.

Not the seed's motion (that is the server's channelset playback): a stand-in so the stub shows something
sensible on its own, in tests and in ``ttes stub --headless`` without ``--host``/``--spawn-server``. Each
DIS posture (standing, kneeling, prone, dead; weapon deployed or firing) is a handful of named joint angles
of DI.fig (figures/README.md: positive = flexion/abduction on both sides) and a root placement; walking,
running and crawling swing hips and knees with the distance travelled. The rifle goes into the right palm,
barrel forward. Poses ease towards their target (no posture graph), all soldiers of a kind at once.
"""

from __future__ import annotations

import numpy as np

from client_stub.stub.scene_graph import Crowd, FigureGraph
from peabody.values import rot_x
from protocol import coords
from protocol.entity import Appearance, WeaponState

STAND, STAND_FIRE, KNEEL, KNEEL_FIRE, PRONE, PRONE_FIRE, DEAD = range(7)
EASE_SECONDS = 0.35
RUN_SPEED = 3.0  # m/s: above it the offline gait is a run (the seed's walk/run threshold)

# posture -> {joint: DOF values}; 3-DOF joints are (abduction or lateral bend, flexion, twist)
_PORT_ARMS = {
    "right_shoulder": (0.1, 0.45, 0.0),
    "right_elbow": (1.45, 0.0),
    "left_shoulder": (-0.15, 0.75, 0.0),
    "left_elbow": (1.3, 0.0),
}
_AIM = {
    "right_shoulder": (0.45, 1.05, 0.0),
    "right_elbow": (1.75, 0.0),
    "left_shoulder": (-0.05, 1.35, 0.0),
    "left_elbow": (0.45, 0.0),
}
_KNEE_DOWN = {
    "left_hip": (0.1, 1.45, 0.0),
    "left_knee": (1.55,),
    "right_hip": (0.05, 0.05, 0.0),
    "right_knee": (1.85,),
    "right_ankle": (-0.6, 0.0),
}
_LYING = {"left_ankle": (-0.8, 0.0), "right_ankle": (-0.8, 0.0)}
_POSTURES: dict[int, dict[str, tuple[float, ...]]] = {
    STAND: _PORT_ARMS,
    STAND_FIRE: {**_AIM, "neck": (0.0, 0.15, 0.0), "head": (0.2, 0.1, 0.0)},
    KNEEL: {**_KNEE_DOWN, **_PORT_ARMS},
    KNEEL_FIRE: {**_KNEE_DOWN, **_AIM},
    PRONE: {**_LYING, "neck": (0.0, -0.55, 0.0), "head": (0.0, -0.35, 0.0),
            "right_shoulder": (0.35, 2.5, 0.0), "right_elbow": (1.3, 0.0),
            "left_shoulder": (0.2, 2.7, 0.0), "left_elbow": (1.0, 0.0),
            "left_hip": (0.25, 0.0, 0.0), "right_hip": (0.25, 0.0, 0.0)},
    PRONE_FIRE: {**_LYING, "neck": (0.0, -0.7, 0.0), "head": (0.0, -0.4, 0.0),
                 "right_shoulder": (0.5, 2.2, 0.0), "right_elbow": (1.8, 0.0),
                 "left_shoulder": (0.1, 2.6, 0.0), "left_elbow": (0.6, 0.0),
                 "left_hip": (0.3, 0.0, 0.0), "right_hip": (0.3, 0.0, 0.0)},
    DEAD: {"left_shoulder": (0.9, 0.2, 0.0), "right_shoulder": (1.1, 0.1, 0.0), "left_elbow": (0.4, 0.0),
           "right_elbow": (0.2, 0.0), "left_hip": (0.2, 0.1, 0.0), "right_hip": (0.15, 0.3, 0.0),
           "right_knee": (0.5,), "head": (0.3, 0.0, 0.0)},
}  # fmt: skip


# body pitch per posture: prone lies face down along the heading, dead on his back
_PITCH = {
    STAND: 0.0,
    STAND_FIRE: 0.0,
    KNEEL: 0.0,
    KNEEL_FIRE: 0.0,
    PRONE: -90.0,
    PRONE_FIRE: -90.0,
    DEAD: 90.0,
}


_ON_ITS_SIDE = np.array([[0.0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]])  # 90 deg about Y


def posture_of(appearance: np.ndarray, weapon: np.ndarray) -> np.ndarray:
    """DIS posture + weapon state -> offline posture id."""
    app = np.asarray(appearance)
    fire = np.asarray(weapon) == WeaponState.FIRING
    out = np.where(fire, STAND_FIRE, STAND)
    out = np.where(app == Appearance.KNEEL, np.where(fire, KNEEL_FIRE, KNEEL), out)
    out = np.where(
        (app == Appearance.PRONE) | (app == Appearance.CRAWL), np.where(fire, PRONE_FIRE, PRONE), out
    )
    return np.where(app == Appearance.DEAD, DEAD, out)


class OfflinePoser:
    """Poses the soldiers of one crowd (figure + weapon) without a server."""

    def __init__(self, crowd: Crowd) -> None:
        self.crowd = crowd
        lay = crowd.layout
        self.body: FigureGraph = lay.figures[0]
        self.weapon: FigureGraph | None = lay.figures[1] if len(lay.figures) > 1 else None
        ndof = lay.ndof
        self.table = np.zeros((len(_POSTURES), ndof))
        for pid, joints in _POSTURES.items():
            for name, values in joints.items():
                sl = self.body.dof_slices.get(name)
                if sl is not None:
                    n = min(len(values), sl.stop - sl.start)
                    self.table[pid, sl.start : sl.start + n] = values[:n]
        self._gait_cols = {name: self.body.dof_slices.get(name) for name in
                           ("left_hip", "right_hip", "left_knee", "right_knee", "waist", "left_shoulder",
                            "right_shoulder")}  # fmt: skip
        self.pitch = np.stack([rot_x(np.radians(_PITCH[p])) for p in range(len(_POSTURES))])
        self.lift = self._lifts()
        self._q = np.zeros((crowd.capacity, ndof))
        self._root = np.broadcast_to(self.body.location, (crowd.capacity, 4, 4)).copy()
        self._seen = np.zeros(crowd.capacity, bool)

    def _lifts(self) -> np.ndarray:
        """Per posture: the root height that puts the lowest site of the body on the ground."""
        probe = Crowd(self.crowd.layout, len(_POSTURES))
        rows = np.arange(len(_POSTURES))
        probe.active[:] = True
        probe.set_dofs(rows, self.table)
        place = np.broadcast_to(np.eye(4), (len(rows), len(self.crowd.layout.figures), 4, 4)).copy()
        place[:, 0] = self.pitch
        probe.set_placements(rows, place)
        world = probe.world(rows)
        lowest = np.full(len(rows), np.inf)
        for name in self.body.sites:
            lowest = np.minimum(lowest, probe.site_world(world, 0, name)[:, 2, 3])
        return -lowest + 0.02

    def _grow(self, capacity: int) -> None:
        if capacity <= len(self._q):
            return
        extra = capacity - len(self._q)
        self._q = np.concatenate([self._q, np.zeros((extra, self._q.shape[1]))])
        self._root = np.concatenate([self._root, np.broadcast_to(self.body.location, (extra, 4, 4))])
        self._seen = np.concatenate([self._seen, np.zeros(extra, bool)])

    def pose(
        self,
        rows: np.ndarray,
        appearance: np.ndarray,
        weapon: np.ndarray,
        speed: np.ndarray,
        distance: np.ndarray,
        dt: float,
    ) -> None:
        """Write DOFs and figure placements of ``rows`` into the crowd (entity matrices set already)."""
        rows = np.asarray(rows, np.int64)
        if not len(rows):
            return
        self._grow(self.crowd.capacity)
        pid = posture_of(appearance, weapon)
        target = self.table[pid].copy()
        self._gait(target, pid, np.asarray(speed, np.float64), np.asarray(distance, np.float64))
        root = self.pitch[pid].copy()
        root[:, 2, 3] = self.lift[pid]
        fresh = ~self._seen[rows]
        a = np.where(fresh, 1.0, min(1.0, dt / EASE_SECONDS))[:, None]
        q = self._q[rows] + (target - self._q[rows]) * a
        self._q[rows] = q
        self._root[rows] = self._ease_root(self._root[rows], root, a[:, 0])
        self._seen[rows] = True
        crowd = self.crowd
        nfig = len(crowd.layout.figures)
        place = np.broadcast_to(np.eye(4), (len(rows), nfig, 4, 4)).copy()
        place[:, 0] = self._root[rows]
        crowd.set_dofs(rows, q)
        crowd.set_placements(rows, place)
        if (
            self.weapon is not None
            and "right_palm.palmcenter" in self.body.sites
            and "root.grip" in self.weapon.sites
        ):
            world = crowd.world(rows)
            palm = crowd.site_world(world, 0, "right_palm.palmcenter")
            ent = crowd.entity[rows]
            local = np.einsum("nji,nj->ni", ent[:, :3, :3], palm[:, :3, 3] - ent[:, :3, 3])
            rifle = np.broadcast_to(np.eye(4), (len(rows), 4, 4)).copy()
            rifle[pid == DEAD] = _ON_ITS_SIDE
            grip = self.weapon.sites["root.grip"][1]
            rifle[:, :3, 3] = local - np.einsum("nij,j->ni", rifle[:, :3, :3], grip[:3, 3])
            place[:, 1] = rifle
            crowd.set_placements(rows, place)

    def _gait(self, q: np.ndarray, pid: np.ndarray, speed: np.ndarray, distance: np.ndarray) -> None:
        """Swing hips and knees with the distance travelled (walk, run, crawl)."""
        moving = (np.abs(speed) > 1e-3) & (pid != DEAD) & (pid != KNEEL) & (pid != KNEEL_FIRE)
        if not moving.any():
            return
        run = np.abs(speed) > RUN_SPEED
        prone = (pid == PRONE) | (pid == PRONE_FIRE)
        stride = np.where(run, 2.6, np.where(prone, 0.8, 1.4))
        phase = 2 * np.pi * distance / stride
        s = np.sin(phase) * moving
        amp = np.where(run, 0.6, np.where(prone, 0.5, 0.35))
        cols = self._gait_cols
        for side, sign in (("left", 1.0), ("right", -1.0)):
            hip, knee = cols[f"{side}_hip"], cols[f"{side}_knee"]
            if hip is None or knee is None:
                continue
            swing = sign * s * amp
            if hip.stop - hip.start >= 2:
                q[:, hip.start + 1] += np.where(prone, np.abs(swing), swing)
                q[:, hip.start] += np.where(prone, 0.3 * np.abs(swing), 0.0)
            q[:, knee.start] += np.where(prone, 0.6 + np.abs(swing), 1.4 * np.maximum(0.0, swing)) * moving
        waist = cols["waist"]
        if waist is not None and waist.stop - waist.start >= 2:
            q[:, waist.start + 1] += np.where(run & moving, 0.2, 0.0)

    @staticmethod
    def _ease_root(current: np.ndarray, target: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Move root placements towards their targets: nlerp of the rotation, lerp of the position."""
        q0 = coords.matrix_to_quat(current[:, :3, :3])
        q1 = coords.matrix_to_quat(target[:, :3, :3])
        flip = (q0 * q1).sum(axis=1) < 0
        q1[flip] = -q1[flip]
        q = q0 + (q1 - q0) * a[:, None]
        out = coords.pose7_to_transform(
            current[:, :3, 3] + (target[:, :3, 3] - current[:, :3, 3]) * a[:, None], q
        )
        return out
