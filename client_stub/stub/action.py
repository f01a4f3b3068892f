"""Following the action: which soldiers ACTION CAM frames, the soldier a touring ACTION CAM follows, and
the name and posture labels above the soldiers.

ACTION CAM frames the drawn figures (their joints' boxes as :meth:`StubApp.draw` last saw them), not the
entities: a server may place a figure away from its entity (the root offset of a step, a late update). A
label says what the stub asked of the soldier (posture, gait and speed, weapon), the way the keys set it.
"""

from __future__ import annotations

import functools

import numpy as np

from client_stub.stub.camera import ACTION_RADIUS_M, ACTION_TURN_SECONDS, SOLDIER_HEIGHT_M
from client_stub.stub.overlay import Label
from client_stub.stub.simsoldier import SimSoldiers
from protocol.entity import Appearance, WeaponState


def action_points(s: SimSoldiers, figure_box: np.ndarray, current: int) -> np.ndarray:
    """Corners of the figures ACTION CAM frames, ``(2n, 3)``: the ``current`` soldier and the live ones
    within :data:`ACTION_RADIUS_M` of him (all live ones without a live current soldier). ``figure_box``
    ``(slots, 2, 3)`` holds each slot's lowest and highest joint (NaN: not drawn yet, so his entity, a
    soldier's height tall)."""
    live = np.flatnonzero(s.alive[: s.count])
    if not len(live):
        return np.array([[0.0, 0.0, 0.0], [0.0, 0.0, SOLDIER_HEIGHT_M]])
    box = figure_box[live] if len(figure_box) >= s.count else np.full((len(live), 2, 3), np.nan)
    unknown = np.isnan(box[:, 0, 0])
    box[unknown, 0] = s.position[live[unknown]]
    box[unknown, 1] = s.position[live[unknown]] + np.array([0.0, 0.0, SOLDIER_HEIGHT_M])
    cur = np.flatnonzero(live == current)
    if len(cur):
        middle = box.mean(axis=1)[:, :2]
        box = box[np.linalg.norm(middle - middle[cur[0]], axis=1) <= ACTION_RADIUS_M]
    return box.reshape(-1, 3)


def follow_action(s: SimSoldiers, current: int, now: float, turned: float) -> tuple[int, float] | None:
    """A touring ACTION CAM's next soldier and the time it turned to him, or None to stay: it stays on the
    current soldier while he lives, and turns to a soldier of the next force every
    :data:`ACTION_TURN_SECONDS` (a replay shows both sides)."""
    live = np.flatnonzero(s.alive[: s.count])
    if not len(live):
        return None
    turn = int(now // ACTION_TURN_SECONDS) != int(turned // ACTION_TURN_SECONDS)
    if current in live and not turn:
        return None
    forces = np.unique(s.force[live])
    here = int(s.force[current]) if current < s.count else int(forces[0])
    want = forces[(int(np.searchsorted(forces, here)) + (1 if turn else 0)) % len(forces)]
    return int(live[s.force[live] == want][0]), now


def soldier_labels(s: SimSoldiers, rows: np.ndarray, world: np.ndarray, current: int) -> list[Label]:
    """Name and posture above each soldier's head (the highest of his joints, ``world`` the node matrices
    ``(n, nodes, 4, 4)`` of soldiers ``rows``)."""
    if not len(rows):
        return []
    p = world[:, :, :3, 3]
    anchors = np.column_stack([p[..., 0].mean(1), p[..., 1].mean(1), p[..., 2].max(1) + 0.25]).tolist()
    texts = posture_texts(s, rows)
    return [
        Label(f"soldier {row}", text, tuple(anchor), row == current)
        for row, text, anchor in zip(rows.tolist(), texts, anchors, strict=True)
    ]


def posture_texts(soldiers: SimSoldiers, slots: np.ndarray) -> list[str]:
    """What the labels of ``slots`` say the soldiers are doing (see :func:`posture_text`)."""
    s = soldiers
    speed = np.round(s.speed[slots] * s.moving(slots), 1)
    return [
        posture_text(a, w, v)
        for a, w, v in zip(
            s.appearance[slots].tolist(), s.weapon[slots].tolist(), speed.tolist(), strict=True
        )
    ]


@functools.lru_cache(maxsize=512)
def posture_text(code: int, weapon: int, speed: float) -> str:
    """``kneel, firing`` / ``stand, walk 1.3 m/s, deployed`` / ``prone, crawl 0.5 m/s``."""
    text = Appearance(code).name.lower() if code in Appearance._value2member_map_ else f"posture {code}"
    if abs(speed) > 0.05:
        gait = "crawl" if code != Appearance.UPRIGHT else "run" if abs(speed) > 2.5 else "walk"
        text = f"{text} {speed:.1f} m/s" if gait == text else f"{text}, {gait} {speed:.1f} m/s"
    if weapon in (WeaponState.DEPLOYED, WeaponState.FIRING):
        text += f", {WeaponState(weapon).name.lower()}"
    return text
