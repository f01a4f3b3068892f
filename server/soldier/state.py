"""Per-soldier mode enums and the request → posture mapping (seed 002, 3.1–3.3, Figures 2, 3 and 12).

A soldier state (the seed's ``SoldierState``) is always in one :class:`Mode`:

* ``IDLE`` — resting in a static posture node of the posture graph (``node`` column);
* ``TRANSITION`` — playing the quickest path (in time) to a goal posture, arc after arc;
* ``LOCO`` — walking / running / walking backwards (Figure 5, :class:`LocoState`), from the base posture
  STAND_STOWED ("standing deployed");
* ``CRAWL`` — crawling (start, cycle, end = start played backwards), from the base posture CRAWL.

The DIS appearance and weapon state of a request pick the *goal posture* (:func:`goal_posture`). The 1994
weapon values were "deployed" and "firing"; the graph calls the not-firing postures ``*_STOWED`` (the report's
"standing deployed" base posture is the graph's STAND_STOWED), so STOWED and DEPLOYED both rest in the
``*_STOWED`` nodes and FIRING in the ``*_FIRE`` nodes.
"""

from __future__ import annotations

from enum import IntEnum

from protocol.entity import Appearance, WeaponState

STAND_STOWED = "STAND_STOWED"
CRAWL_NODE = "CRAWL"
PRONE_NODES = ("PRONE_STOWED", "PRONE_FIRE")  # lying prone: a turn goes up to CRAWL and back (turning.py)
DEAD = "DEAD"


class Mode(IntEnum):
    IDLE = 0
    TRANSITION = 1
    LOCO = 2
    CRAWL = 3


class LocoState(IntEnum):
    """The nodes of Figure 5 (each a clip that plays once; cycles repeat by re-entering their state)."""

    NONE = 0  # back at the base posture: the soldier leaves LOCO/CRAWL mode
    WALK_START = 1
    WALK_CYCLE = 2
    WALK_END = 3
    BWALK_START = 4
    BWALK_CYCLE = 5
    BWALK_END = 6
    RUN_START = 7
    RUN_CYCLE = 8
    RUN_END = 9
    WALK2RUN = 10
    RUN2WALK = 11
    CRAWL_START = 12
    CRAWL_CYCLE = 13
    CRAWL_END = 14
    SIDESTEP_L = 15  # velocity to the left of the heading: a side-step per clip (no start or end step)
    SIDESTEP_R = 16


class Foot(IntEnum):
    LEFT = 0
    RIGHT = 1


class Movement(IntEnum):
    """How a soldier of a given appearance moves when its velocity is non-zero."""

    NONE = 0  # kneeling and dead soldiers ignore velocity
    WALK = 1  # standing: walk / run from STAND_STOWED
    CRAWL = 2  # prone: crawl from CRAWL


# (appearance, firing) -> posture node name
_GOALS: dict[tuple[int, bool], str] = {
    (Appearance.UPRIGHT, False): "STAND_STOWED",
    (Appearance.UPRIGHT, True): "STAND_FIRE",
    (Appearance.KNEEL, False): "KNEEL_STOWED",
    (Appearance.KNEEL, True): "KNEEL_FIRE",
    (Appearance.PRONE, False): "PRONE_STOWED",
    (Appearance.PRONE, True): "PRONE_FIRE",
    (Appearance.CRAWL, False): "CRAWL",
    (Appearance.CRAWL, True): "CRAWL",
    (Appearance.DEAD, False): "DEAD",
    (Appearance.DEAD, True): "DEAD",
}

MOVEMENT: dict[int, Movement] = {
    Appearance.DEAD: Movement.NONE,
    Appearance.UPRIGHT: Movement.WALK,
    Appearance.KNEEL: Movement.NONE,
    Appearance.PRONE: Movement.CRAWL,
    Appearance.CRAWL: Movement.CRAWL,
}

BASE_POSTURE: dict[Movement, str] = {Movement.WALK: STAND_STOWED, Movement.CRAWL: CRAWL_NODE}


def goal_posture(appearance: int, weapon: int) -> str:
    """The static posture node a request asks for when the soldier is not moving."""
    return _GOALS[(int(appearance), int(weapon) == WeaponState.FIRING)]


def movement(appearance: int) -> Movement:
    return MOVEMENT.get(int(appearance), Movement.NONE)


def request_for(posture: str) -> tuple[int, int]:
    """The (appearance, weapon state) of a request that rests in ``posture`` (``DEAD@kstow`` → DEAD): the
    inverse of :func:`goal_posture`, for ``posture_change`` over JCL; KeyError if no request rests there."""
    name = posture.partition("@")[0]
    for (appearance, firing), goal in _GOALS.items():
        if goal == name:
            return int(appearance), int(WeaponState.FIRING if firing else WeaponState.DEPLOYED)
    raise KeyError(f"no request rests in posture {posture!r} (known: {sorted(set(_GOALS.values()))})")
