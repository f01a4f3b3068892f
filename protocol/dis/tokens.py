"""DIS -> TTES: the posture and command tokens the seed's Figure 2 lists for each soldier.

"The TTES filters and translates the DIS stream into a set of posture and command tokens that are passed
to Jack" (seed report section 2). Per Entity State PDU of a lifeform: posture (STAND / KNEEL / PRONE /
CRAWL / DEAD), weapon (STOWED / DEPLOYED / FIRING), position and velocity in the local Performer frame
(+X east, +Y north, +Z up, metres), compass heading, and which rifle model to attach. All vectorised.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from protocol.dis.appearance import ttes_posture, ttes_weapon
from protocol.dis.batch import ENTITY_ID_DTYPE, EntityStateBatch
from protocol.dis.entity_type import rifle_code
from protocol.dis.geo import LocalFrame, heading_deg

TOKEN_DTYPE = np.dtype(
    [
        ("t", "f8"),
        ("entity", ENTITY_ID_DTYPE),
        ("force", "u1"),
        ("posture", "u1"),  # TtesPosture
        ("weapon", "u1"),  # TtesWeapon
        ("rifle", "u1"),  # index into entity_type.RIFLE_FIGURES
        ("position", "f8", (3,)),  # local east, north, up (m)
        ("velocity", "f8", (3,)),  # local east, north, up (m/s)
        ("speed", "f8"),  # horizontal speed (m/s)
        ("heading", "f8"),  # degrees clockwise from north
    ]
)


def translate(
    batch: EntityStateBatch, times: NDArray[np.float64], frame: LocalFrame | None = None
) -> tuple[NDArray[np.void], LocalFrame | None]:
    """Tokens (:data:`TOKEN_DTYPE`) for every record of ``batch``; ``frame`` defaults to the first entity.

    Returns the tokens and the frame used (None only for an empty batch without a frame).
    """
    r = batch.records
    out = np.zeros(len(batch), TOKEN_DTYPE)
    if len(batch) == 0:
        return out, frame
    if frame is None:
        frame = LocalFrame.at_ecef(r["location"][0])
    et = r["entity_type"]
    out["t"] = times
    out["entity"] = r["entity_id"]
    out["force"] = r["force_id"]
    out["posture"] = ttes_posture(r["appearance"])
    out["weapon"] = ttes_weapon(r["appearance"])
    out["rifle"] = rifle_code(et["category"], et["subcategory"], et["specific"])
    out["position"] = frame.to_local(r["location"])
    vel = frame.vector_to_local(r["velocity"].astype(np.float64))
    out["velocity"] = vel
    out["speed"] = np.hypot(vel[:, 0], vel[:, 1])
    out["heading"] = heading_deg(r["location"], r["orientation"])
    return out, frame
