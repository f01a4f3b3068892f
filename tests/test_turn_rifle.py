"""A deployed soldier turning in place keeps his rifle at the ready (issue 16's video, 9.3-10.8 s).

The video seemed to show an M16 soldier holding the rifle vertical at the shoulder after his 90° turn, as
if stowed. Measured here on what the server sends (manager core, ``now`` passed in), the turn clips of both
weapon sets carry the rifle exactly as STAND_STOWED does (the graph's "standing deployed": the low ready,
the barrel about 30° down and ahead): rigid with the pelvis, palms on its grip and handguard. The video's
soldier faced the camera then, and a low ready seen head-on is foreshortened into a short vertical rifle
(a soldier who never turned looks the same from the front)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from peabody.fk import FigureKinematics
from peabody.quaternion import to_transform
from server.soldier.library import MotionLibrary
from tests.test_gait_selection import shipped_library
from tests.test_root_motion import drive
from tests.test_turn_start import families

CARRY_DEG = 0.5  # the rifle's turn from its STAND_STOWED carry relative to the pelvis
CARRY_CM = 0.5
PALM_CM = 1.0  # palm centre to the rifle's grip (right) / handguard (left), as `ttes author check`
LOW_READY_PITCH = (-45.0, -20.0)  # degrees of the butt-to-muzzle line above the horizontal (stowed: ~+70)
AHEAD_DEG = 30.0  # the muzzle's compass degrees from the soldier's heading, at rest


@pytest.fixture(scope="module")
def lib() -> MotionLibrary:
    return shipped_library()


def transforms(placements: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` of ``(n, 7)`` placements (position cm, quaternion w, x, y, z)."""
    return np.stack([to_transform(p[:3], p[3:7]) for p in np.asarray(placements, np.float64)])


def rifle_sites(lib: MotionLibrary, played: dict[str, np.ndarray], weapon: str) -> dict[str, np.ndarray]:
    """Per tick, in the soldier frame (X right, +Y up, -Z ahead): the rifle's butt, muzzle, grip and
    handguard, the palm centres, and the rifle's rotation and position relative to the pelvis (``carry``,
    ``offset``)."""
    fset = lib.sets[lib.set_index("DI.fig", weapon)]
    kin, rkin = (FigureKinematics(p) for p in fset.prototypes[:2])
    root, rifle = transforms(played["placements"][:, 0]), transforms(played["placements"][:, 1])
    joints = np.asarray(played["joints"], np.float64)
    body = kin.site_globals(joints[:, fset.figure_slice("DI.fig")], root)
    gun = rkin.site_globals(joints[:, fset.figure_slice(weapon)], rifle)
    names = ("butt", "muzzle", "grip", "handguard")
    out = {s: gun[:, rkin.site_names.index(f"rifle.{s}"), :3, 3] for s in names}
    for side in ("left", "right"):
        out[side] = body[:, kin.site_names.index(f"{side}_palm.palmcenter"), :3, 3]
    out["carry"] = np.einsum("nji,njk->nik", root[:, :3, :3], rifle[:, :3, :3])
    out["offset"] = np.einsum("nji,nj->ni", root[:, :3, :3], rifle[:, :3, 3] - root[:, :3, 3])
    return out


def barrel(sites: dict[str, np.ndarray], k: int) -> tuple[float, float]:
    """(pitch above the horizontal, compass degrees right of ahead) of the butt-to-muzzle line at tick k."""
    x, y, z = sites["muzzle"][k] - sites["butt"][k]
    return math.degrees(math.atan2(y, math.hypot(x, z))), math.degrees(math.atan2(x, -z))


@pytest.mark.parametrize("weapon", ["M16.fig", "AK_47.fig"])
@pytest.mark.parametrize("turn", [90.0, -90.0, 180.0])
def test_a_deployed_soldier_turning_in_place_keeps_the_rifle_at_the_ready(
    lib: MotionLibrary, weapon: str, turn: float
) -> None:
    """Was never wrong: measured 0.00° / 0.00 cm from the carry, palms 0.01 cm, barrel -33° (M16) and
    -30.7° (AK) all through turn_r90 and turn_r180."""
    played = drive(lib, [(0.0, 0.0, 0.0), (0.5, 0.0, 0.0, turn)], heading=0.0, until=4.5, weapon=weapon)
    seq = families(played, 0.5)
    assert any(f.startswith("turn_") and f.endswith(f"{abs(turn):g}") for f in seq), seq
    sites = rifle_sites(lib, played, weapon)
    rest = sites["carry"][0]  # resting in STAND_STOWED before the turn
    cos = (np.einsum("nij,ij->n", sites["carry"], rest) - 1.0) / 2.0
    assert np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max() <= CARRY_DEG
    assert np.linalg.norm(sites["offset"] - sites["offset"][0], axis=1).max() <= CARRY_CM
    assert np.linalg.norm(sites["right"] - sites["grip"], axis=1).max() <= PALM_CM
    assert np.linalg.norm(sites["left"] - sites["handguard"], axis=1).max() <= PALM_CM
    pitch = [barrel(sites, k)[0] for k in range(len(sites["butt"]))]
    assert LOW_READY_PITCH[0] <= min(pitch) and max(pitch) <= LOW_READY_PITCH[1], (min(pitch), max(pitch))
    before, after = barrel(sites, 0), barrel(sites, -1)  # at rest, the figure faces the heading again
    assert abs(before[1]) <= AHEAD_DEG and abs(after[1] - before[1]) <= 2.0, (before, after)
