"""Lifeform appearance (SISO-REF-010) and its translation into TTES posture and weapon tokens.

Bit layout of the 32-bit lifeform appearance record used here:

====== ====================================================================================
bits   field
====== ====================================================================================
0      paint scheme (0 uniform, 1 camouflage)
3-4    health: 0 no injury, 1 slight, 2 moderate, 3 fatal
16-19  lifeform state: 1 upright standing, 2 upright walking, 3 upright running, 4 kneeling,
       5 prone, 6 crawling, 7 swimming, 8 parachuting, 9 jumping, 10 sitting, 11 squatting,
       12 crouching, 13 wading, 14 surrender, 15 detained (0 = null)
21     frozen
23     deactivated (state)
24-25  weapon 1: 0 none, 1 stowed, 2 deployed, 3 firing
26-27  weapon 2 (same values)
28-29  camouflage type: 0 desert, 1 winter, 2 forest, 3 other
====== ====================================================================================

All other bits are carried through untouched as ``rest`` so decode/encode round-trips every u32.

The 1994 TTES figures know four postures (standing, kneeling, prone, destroyed) plus crawling as a
locomotion (seed report section 3.1, Figure 2). :data:`TTES_POSTURE_OF_STATE` maps the fifteen DIS states
onto them; fatal health or the deactivated bit override everything with DEAD.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from protocol.dis.errors import DisError

# The TTES tokens a DIS lifeform maps onto are the entity requests' (one enum each, in protocol.entity);
# DIS 'none' (no weapon) is shown as STOWED: the rifle model stays slung.
from protocol.entity import Appearance as TtesPosture
from protocol.entity import WeaponState as TtesWeapon


class Health(IntEnum):
    NO_INJURY = 0
    SLIGHT = 1
    MODERATE = 2
    FATAL = 3


class LifeformState(IntEnum):
    NULL = 0
    UPRIGHT_STANDING = 1
    UPRIGHT_WALKING = 2
    UPRIGHT_RUNNING = 3
    KNEELING = 4
    PRONE = 5
    CRAWLING = 6
    SWIMMING = 7
    PARACHUTING = 8
    JUMPING = 9
    SITTING = 10
    SQUATTING = 11
    CROUCHING = 12
    WADING = 13
    SURRENDER = 14
    DETAINED = 15


class WeaponState(IntEnum):
    NONE = 0
    STOWED = 1
    DEPLOYED = 2
    FIRING = 3


class Camouflage(IntEnum):
    DESERT = 0
    WINTER = 1
    FOREST = 2
    OTHER = 3


# Names printed by `ttes dis dump` (index = lifeform state value).
POSTURE_NAMES: tuple[str, ...] = (
    "null",
    "standing",
    "walking",
    "running",
    "kneeling",
    "prone",
    "crawling",
    "swimming",
    "parachuting",
    "jumping",
    "sitting",
    "squatting",
    "crouching",
    "wading",
    "surrender",
    "detained",
)
WEAPON_NAMES: tuple[str, ...] = ("none", "stowed", "deployed", "firing")
HEALTH_NAMES: tuple[str, ...] = ("no_injury", "slight", "moderate", "fatal")

# DIS lifeform state -> nearest TTES posture (documented in docs/DIS.md).
TTES_POSTURE_OF_STATE: dict[LifeformState, TtesPosture] = {
    LifeformState.NULL: TtesPosture.STAND,  # unknown: the neutral posture
    LifeformState.UPRIGHT_STANDING: TtesPosture.STAND,
    LifeformState.UPRIGHT_WALKING: TtesPosture.STAND,  # locomotion comes from the velocity, not the posture
    LifeformState.UPRIGHT_RUNNING: TtesPosture.STAND,
    LifeformState.KNEELING: TtesPosture.KNEEL,
    LifeformState.PRONE: TtesPosture.PRONE,
    LifeformState.CRAWLING: TtesPosture.CRAWL,
    LifeformState.SWIMMING: TtesPosture.PRONE,  # body horizontal
    LifeformState.PARACHUTING: TtesPosture.STAND,  # hanging upright
    LifeformState.JUMPING: TtesPosture.STAND,
    LifeformState.SITTING: TtesPosture.KNEEL,  # low, torso upright
    LifeformState.SQUATTING: TtesPosture.KNEEL,
    LifeformState.CROUCHING: TtesPosture.KNEEL,
    LifeformState.WADING: TtesPosture.STAND,
    LifeformState.SURRENDER: TtesPosture.STAND,  # hands up, on its feet
    LifeformState.DETAINED: TtesPosture.KNEEL,  # restrained, made to kneel
}
TTES_WEAPON_OF_STATE: dict[WeaponState, TtesWeapon] = {
    WeaponState.NONE: TtesWeapon.STOWED,
    WeaponState.STOWED: TtesWeapon.STOWED,
    WeaponState.DEPLOYED: TtesWeapon.DEPLOYED,
    WeaponState.FIRING: TtesWeapon.FIRING,
}
_POSTURE_LUT = np.array([TTES_POSTURE_OF_STATE[LifeformState(s)] for s in range(16)], np.uint8)
_WEAPON_LUT = np.array([TTES_WEAPON_OF_STATE[WeaponState(w)] for w in range(4)], np.uint8)

# (shift, width) of every field
_FIELDS: dict[str, tuple[int, int]] = {
    "paint_scheme": (0, 1),
    "health": (3, 2),
    "state": (16, 4),
    "frozen": (21, 1),
    "deactivated": (23, 1),
    "weapon1": (24, 2),
    "weapon2": (26, 2),
    "camouflage": (28, 2),
}
_KNOWN_MASK = sum(((1 << w) - 1) << s for s, w in _FIELDS.values())
REST_MASK = 0xFFFFFFFF & ~_KNOWN_MASK


@dataclass(frozen=True, slots=True)
class LifeformAppearance:
    """One decoded lifeform appearance word."""

    health: Health = Health.NO_INJURY
    state: LifeformState = LifeformState.UPRIGHT_STANDING
    weapon1: WeaponState = WeaponState.NONE
    weapon2: WeaponState = WeaponState.NONE
    frozen: bool = False
    deactivated: bool = False
    camouflage: Camouflage = Camouflage.DESERT
    paint_scheme: int = 0
    rest: int = 0  # bits this module does not interpret, kept verbatim

    @classmethod
    def decode(cls, word: int) -> LifeformAppearance:
        if not 0 <= word <= 0xFFFFFFFF:
            raise DisError(f"appearance {word} is not a u32", 84)
        f = {name: (word >> s) & ((1 << w) - 1) for name, (s, w) in _FIELDS.items()}
        return cls(
            health=Health(f["health"]),
            state=LifeformState(f["state"]),
            weapon1=WeaponState(f["weapon1"]),
            weapon2=WeaponState(f["weapon2"]),
            frozen=bool(f["frozen"]),
            deactivated=bool(f["deactivated"]),
            camouflage=Camouflage(f["camouflage"]),
            paint_scheme=f["paint_scheme"],
            rest=word & REST_MASK,
        )

    def encode(self) -> int:
        return int(
            encode_appearance(
                health=self.health,
                state=self.state,
                weapon1=self.weapon1,
                weapon2=self.weapon2,
                frozen=self.frozen,
                deactivated=self.deactivated,
                camouflage=self.camouflage,
                paint_scheme=self.paint_scheme,
                rest=self.rest,
            )
        )

    @property
    def ttes_posture(self) -> TtesPosture:
        return TtesPosture(int(ttes_posture(self.encode())))

    @property
    def ttes_weapon(self) -> TtesWeapon:
        return TTES_WEAPON_OF_STATE[self.weapon1]


def decode_appearance(
    words: ArrayLike,
) -> dict[str, NDArray[np.uint8] | NDArray[np.bool_] | NDArray[np.uint32]]:
    """Vectorised decode: one array per field (bool for frozen/deactivated, ``rest`` as u32)."""
    w = np.asarray(words, dtype=np.uint32)
    out: dict[str, NDArray] = {}
    for name, (s, width) in _FIELDS.items():
        v = ((w >> np.uint32(s)) & np.uint32((1 << width) - 1)).astype(np.uint8)
        out[name] = v.astype(bool) if name in ("frozen", "deactivated") else v
    out["rest"] = w & np.uint32(REST_MASK)
    return out


def encode_appearance(
    *,
    health: ArrayLike = 0,
    state: ArrayLike = LifeformState.UPRIGHT_STANDING,
    weapon1: ArrayLike = 0,
    weapon2: ArrayLike = 0,
    frozen: ArrayLike = False,
    deactivated: ArrayLike = False,
    camouflage: ArrayLike = 0,
    paint_scheme: ArrayLike = 0,
    rest: ArrayLike = 0,
) -> NDArray[np.uint32]:
    """Vectorised encode (arguments broadcast). Out-of-range field values raise :class:`DisError`."""
    values = {
        "health": health,
        "state": state,
        "weapon1": weapon1,
        "weapon2": weapon2,
        "frozen": frozen,
        "deactivated": deactivated,
        "camouflage": camouflage,
        "paint_scheme": paint_scheme,
    }
    word = np.asarray(rest, dtype=np.int64) & REST_MASK
    for name, value in values.items():
        s, width = _FIELDS[name]
        v = np.asarray(value, dtype=np.int64)
        if ((v < 0) | (v >= (1 << width))).any():
            raise DisError(f"appearance {name} out of range 0..{(1 << width) - 1}", 84)
        word = word | (v << s)
    return np.asarray(word, dtype=np.uint32)


def ttes_posture(words: ArrayLike) -> NDArray[np.uint8]:
    """TTES posture codes (:class:`TtesPosture`) for appearance word(s); fatal or deactivated -> DEAD."""
    w = np.asarray(words, dtype=np.uint32)
    posture = _POSTURE_LUT[(w >> np.uint32(16)) & np.uint32(0xF)]
    dead = (((w >> np.uint32(3)) & np.uint32(3)) == Health.FATAL) | (
        ((w >> np.uint32(23)) & np.uint32(1)) == 1
    )
    return np.where(dead, np.uint8(TtesPosture.DEAD), posture)


def ttes_weapon(words: ArrayLike) -> NDArray[np.uint8]:
    """TTES weapon codes (:class:`TtesWeapon`) of weapon 1 for appearance word(s)."""
    w = np.asarray(words, dtype=np.uint32)
    return _WEAPON_LUT[(w >> np.uint32(24)) & np.uint32(3)]
