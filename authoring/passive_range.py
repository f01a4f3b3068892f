"""A dead body's legs go as far as a joint goes passively, a little past a live soldier's limits (issue 14).

The figures' joint limits (soldier.fig, DI.fig) are a live man's **active** range: the ankle pointed 50 deg,
the hip turned out 45 deg. Face down within them a dead soldier lies on his toes, heels 15-21 cm up (the
product owner's limit is 15 cm). A limp body's joints are moved by gravity and the ground, and a joint moved
so goes further than its muscles take it: a death's ragdoll and everything done to its frames after the
physics use the figure with its legs widened to :data:`PASSIVE_DEG` (:func:`passive_figure`), so gravity
lays the feet down while the body settles (issue 14, heels14d). Only widened, never narrowed; live soldiers,
IK and every other clip keep the figure's own limits; the check holds a clip that ends in DEAD to these.

Published passive ranges of motion (healthy adults, goniometer), not exceeded here:

* ankle plantarflexion: 55.8 deg (males) and 67.1 deg (females) in the CDC's joint range-of-motion study
  (Soucie et al. 2011, "Range of motion measurements: reference values and a database for comparison
  studies", Haemophilia 17:500-507; measured passively by physical therapists); "50-65" in clinical
  passive-ROM tables; the figures' 50 is the textbook active value. Here **60 deg**.
* hip external rotation: 0-60 deg in the clinical tables (e.g. the US VA rating schedule, 38 CFR 4.71a
  plate II: "external rotation = 0 to 60 degrees"; passive-ROM tables "40-60"); the figures' 45 is the
  textbook active value. Here **60 deg**.
"""

from __future__ import annotations

import copy
from collections.abc import Iterator, Mapping

import numpy as np

from peabody.fk import FigureKinematics
from peabody.model import Figure

# per leg joint (both sides), per DOF index: the passive lower limit in degrees. The ankle's first DOF points
# the foot (negative), the hip's third turns the leg (negative: the toes out)
PASSIVE_DEG: dict[str, dict[int, float]] = {
    "ankle": {0: -60.0},  # plantarflexion (Soucie 2011: 55.8 males, 67.1 females)
    "hip": {2: -60.0},  # external rotation (38 CFR 4.71a plate II: 0-60)
}
SIDES = ("left", "right")


def _widened(dof_slices: Mapping[str, object]) -> Iterator[tuple[str, int, float]]:
    """(joint name, DOF index in the joint, passive lower limit in radians) of :data:`PASSIVE_DEG` for each
    leg joint ``dof_slices`` has (a figure without them: none)."""
    for joint, dofs in PASSIVE_DEG.items():
        for side in SIDES:
            if f"{side}_{joint}" in dof_slices:
                for i, lo in dofs.items():
                    yield f"{side}_{joint}", i, float(np.radians(lo))


def passive_figure(figure: Figure) -> Figure:
    """A copy of ``figure`` whose legs may go to :data:`PASSIVE_DEG` (wider only; a figure without those
    joints is copied unchanged): a dead body's."""
    out = copy.deepcopy(figure)
    for name, i, lo in _widened(out.joints):
        dof = out.joints[name].dofs[i]
        dof.lower = min(dof.lower, lo)
    return out


def passive_limits(kin: FigureKinematics) -> tuple[np.ndarray, np.ndarray]:
    """The joint limits (radians, per DOF) of :func:`passive_figure` of ``kin``'s figure."""
    lower = kin.lower.copy()
    for name, i, lo in _widened(kin.dof_slices):
        k = kin.dof_slices[name].start + i
        lower[k] = min(lower[k], lo)
    return lower, kin.upper.copy()


def past_live_limits(kin: FigureKinematics, poses: np.ndarray, slack: float = 1e-4) -> bool:
    """Whether ``poses`` ``(n, ndof)`` of ``kin``'s (live) figure take a leg past its own limits into the
    passive range anywhere (``slack`` radians: the files' float32 rounding of a joint at its limit)."""
    dofs = [kin.dof_slices[name].start + i for name, i, _ in _widened(kin.dof_slices)]
    return bool((poses[:, dofs] < kin.lower[dofs] - slack).any())
