"""Which entities are soldiers, and which rifle model each carries.

A TTES soldier is a DIS *lifeform* (kind 3) in the *land* domain (1). SISO-REF-010 has two schemes for
human lifeforms, told apart by the category byte:

* **old scheme** (category 1..9, e.g. 1 = dismounted infantry, used by 1990s simulators): the
  *subcategory* is the weapon, numbered per country list (US 1..134, CIS 201..248, ...);
* **new scheme** (category 10..159 = the organisation: 10 conventional armed forces, 11 army, 12 naval
  infantry, ..., 130 civilian): the *subcategory* is the equipment class (5 = assault rifles) and the
  *specific* byte the weapon within it.

Only the AK-47 and M16 rifle models exist (seed report section 3.1); everything else gets the default.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

LIFEFORM_KIND = 3
LAND_DOMAIN = 1

RIFLE_FIGURES: tuple[str, ...] = ("M16.fig", "AK_47.fig")  # index = rifle code
RIFLE_M16, RIFLE_AK = 0, 1
DEFAULT_RIFLE = RIFLE_M16

# Old scheme: subcategory = weapon (SISO-REF-010 US / CIS "weapons for lifeforms" lists).
OLD_SCHEME_AK: dict[int, str] = {
    205: "Assault rifle AK and AKM, 7.62 mm",
    206: "Assault rifle AK-74 and AKS-74, 5.45 mm",
    209: "AKSU-74 5.45 mm",
    216: "Light RPK 7.62 mm",
    217: "Light RPK-74 5.45 mm",
}
OLD_SCHEME_M16: dict[int, str] = {
    18: "Commando assault rifle, Model 733 5.56 mm, Colt",
    27: "AR-15 (M16) 5.56 mm",
    32: "M16A2 assault rifle 5.56 mm, Colt",
    39: "Assault carbine M16K",
    41: "M4 (Model 720) 5.56 mm, Colt",
    55: "Light M16A2 5.56 mm, Colt",
    92: "Dragon and M16",
    93: "Firing port weapon M231 5.56 mm",
}
# New scheme: subcategory 5 (assault rifles), specific = rifle.
NEW_SCHEME_ASSAULT_RIFLES = 5
NEW_SCHEME_AK: dict[int, str] = {
    10: "5.45 mm AK-74",
    11: "5.45 mm AKS-74",
    12: "5.45 mm AK-74M",
    13: "5.45 mm Kbk wz. 1988 Tantal",
    30: "5.56 mm AK-101",
    110: "7.62 mm AK-103",
    111: "7.62 mm AK-104",
    112: "7.62 mm AK-47",
    113: "7.62 mm AKM",
    114: "7.62 mm AKS-47",
    119: "7.62 mm Type 56",
}
NEW_SCHEME_M16: dict[int, str] = {
    31: "5.56 mm Diemaco C7",
    32: "5.56 mm Colt Canada C8 carbine",
    40: "5.56 mm M16A1",
    41: "5.56 mm M16A2/A3/A4",
    42: "5.56 mm Colt M4",
    43: "5.56 mm Colt M4 SOPMOD",
    63: "5.56 mm Bushmaster XM15",
    64: "5.56 mm HK416",
}
NEW_SCHEME_FIRST_CATEGORY = 10


def _lut(keys: dict[int, str]) -> NDArray[np.bool_]:
    lut = np.zeros(256, bool)
    lut[list(keys)] = True
    return lut


_OLD_AK, _OLD_M16 = _lut(OLD_SCHEME_AK), _lut(OLD_SCHEME_M16)
_NEW_AK, _NEW_M16 = _lut(NEW_SCHEME_AK), _lut(NEW_SCHEME_M16)


def is_lifeform(kind: ArrayLike, domain: ArrayLike) -> NDArray[np.bool_]:
    """Kind 3 (lifeform) in domain 1 (land): the entities TTES animates."""
    return (np.asarray(kind) == LIFEFORM_KIND) & (np.asarray(domain) == LAND_DOMAIN)


def rifle_code(category: ArrayLike, subcategory: ArrayLike, specific: ArrayLike) -> NDArray[np.uint8]:
    """Rifle model code per entity (index into :data:`RIFLE_FIGURES`), vectorised."""
    cat = np.asarray(category, dtype=np.int64) & 0xFF
    sub = np.asarray(subcategory, dtype=np.int64) & 0xFF
    spec = np.asarray(specific, dtype=np.int64) & 0xFF
    old = cat < NEW_SCHEME_FIRST_CATEGORY
    new = ~old & (sub == NEW_SCHEME_ASSAULT_RIFLES)
    ak = (old & _OLD_AK[sub]) | (new & _NEW_AK[spec])
    m16 = (old & _OLD_M16[sub]) | (new & _NEW_M16[spec])
    out = np.full(np.broadcast(cat, sub, spec).shape, DEFAULT_RIFLE, np.uint8)
    out[np.broadcast_to(m16, out.shape)] = RIFLE_M16
    out[np.broadcast_to(ak, out.shape)] = RIFLE_AK
    return out


def rifle_figure(entity_type: tuple[int, ...]) -> str:
    """The rifle figure file for one entity type tuple (kind, domain, country, category, subcategory, ...)."""
    return RIFLE_FIGURES[int(rifle_code(entity_type[3], entity_type[4], entity_type[5]))]
