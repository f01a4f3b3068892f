"""Body dimensions for the soldier figures (seed 002, 3.4.3: a 95th-percentile ANSUR 88 male).

Why a module: the generator scales the MakeHuman mesh to one stature and places the spine joints,
which the mesh rig does not have (MakeHuman's spine has five bones; Jack's has seventeen vertebrae).
Ratios are fractions of stature, the way anthropometric tables give landmark heights.
"""

from __future__ import annotations

import numpy as np

# ANSUR 88 (Gordon et al. 1989) men's stature, 95th percentile: 1865 mm.
STATURE_95TH_MALE_CM = 186.5

# Landmark heights as fractions of stature (standing, neutral): the lumbosacral junction (the waist
# joint, L5/S1) and the cervicothoracic top of the thoracic spine (where vt1 sits, just under the
# sternoclavicular joints so the clavicles attach to upper_torso).
WAIST_HEIGHT_RATIO = 0.580
THORACIC_TOP_RATIO = 0.803

# Adult spine: the lumbar column is about 39% of the L5/S1..T1 length; lumbar vertebrae are roughly
# equal, thoracic ones grow taller going down (T1 ~ 0.8, T12 ~ 1.2 of the thoracic mean).
LUMBAR_FRACTION = 0.39
LUMBAR = ("l5", "l4", "l3", "l2", "l1")
THORACIC = tuple(f"t{i}" for i in range(12, 0, -1))  # t12 (lowest) .. t1 (highest)
VERTEBRAE = LUMBAR + THORACIC


def vertebra_bounds(waist_y: float, top_y: float) -> np.ndarray:
    """Heights of the 18 vertebral boundaries from the waist joint (L5/S1) up to vt1, bottom to top.

    ``bounds[i]`` is the bottom of ``VERTEBRAE[i]`` and ``bounds[i + 1]`` its top.
    """
    span = top_y - waist_y
    lumbar = np.full(len(LUMBAR), LUMBAR_FRACTION * span / len(LUMBAR))
    weights = np.linspace(1.2, 0.8, len(THORACIC))  # t12 .. t1
    thoracic = (1.0 - LUMBAR_FRACTION) * span * weights / weights.sum()
    return waist_y + np.concatenate([[0.0], np.cumsum(np.concatenate([lumbar, thoracic]))])
