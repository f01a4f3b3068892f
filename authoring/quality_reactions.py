"""A reaction a trainee can see (``ttes author check``'s reaction amplitude, issue 14).

Issue 14 asks for "a firing recoil (a small shoulder kick, standing, kneeling and prone) and a flinch (a hit
or near-detonation reaction in each posture)". Session 19's audit found them passing every limit while barely
showing: the standing recoil kicked the shoulders 1.7 cm and nodded the head 2.6 cm over 0.3 s, the soldier's
prone recoil moved the shoulders 0.4 cm and the rifle's muzzle 2.9 cm, and the prone and crawl flinches moved
the head alone (the shoulders 0.0 cm). Nothing in the check looked at how much a reaction moves.

A reaction clip (its name has ``_recoil`` or ``_flinch``: :func:`reaction_kind`) begins and ends in its
posture, so its visible amplitude is the peak displacement from its first frame of

* ``reaction_shoulders_cm``: the shoulders (the clavicles' acromion sites, the larger of the two): a rifle's
  recoil kicks the firing shoulder back a few cm in some 50 ms; a flinch hunches them;
* ``reaction_head_cm``: the head (the nose): it rides the stock back with the kick, it ducks in a flinch;
* ``reaction_muzzle_cm``: the rifle's muzzle (kicked back and climbing about the butt in a recoil; a flinch
  may leave the rifle where it lies, so it is recorded, not judged, there);

each judged against :data:`REACTION_LIMITS` (a range per kind, like the gaits': too small is not seen, too
large is no longer a kick or a duck). ``reaction_peak_s`` (information) is when the shoulders are furthest
out: a kick peaks within a tenth of a second, a slow nod later.
"""

from __future__ import annotations

from typing import Any

import numpy as np

KINDS = ("recoil", "flinch")
SHOULDER_SITES = ("left_clavicle.acromion", "right_clavicle.acromion")
HEAD_SITE = "bottom_head.nose"
# cm, (low, high) per kind: a 7.62 / 5.56 recoil kicks the shoulder back 2-5 cm and the muzzle climbs a
# few degrees (5 degrees is 8 cm at an AK's muzzle); a flinch ducks the head a hand's breadth and hunches
# the shoulders. Session 19's clips: recoil shoulders 0.4-1.7, flinch shoulders 0.0 prone and crawling.
REACTION_LIMITS: dict[str, dict[str, tuple[float, float]]] = {
    "recoil": {
        "reaction_shoulders_cm": (2.5, 8.0),
        "reaction_head_cm": (2.0, 10.0),
        "reaction_muzzle_cm": (5.0, 25.0),
    },
    "flinch": {"reaction_shoulders_cm": (2.5, 20.0), "reaction_head_cm": (8.0, 30.0)},
}


def reaction_kind(name: str) -> str | None:
    """``"recoil"`` or ``"flinch"`` for a reaction clip's name (``stfire_recoil_m16_low``), else None."""
    return next((k for k in KINDS if f"_{k}" in name), None)


def _peak(points: np.ndarray) -> tuple[float, int]:
    """The largest distance (cm) of ``points`` ``(n, 3)`` from its first and the frame it is reached."""
    d = np.linalg.norm(points - points[0], axis=-1)
    at = int(np.argmax(d))
    return float(d[at]), at


def reaction_amplitude(
    name: str, sites: np.ndarray, site_names: list[str], muzzle: np.ndarray | None, fps: float
) -> dict[str, Any]:
    """The reaction metrics of clip ``name`` (none for a clip that is not a reaction) from its body sites
    ``sites`` ``(n, k, 3)`` named ``site_names`` and the rifle's muzzle ``(n, 3)`` (cm, world)."""
    kind = reaction_kind(name)
    if kind is None:
        return {}
    shoulders = [_peak(sites[:, site_names.index(s)]) for s in SHOULDER_SITES if s in site_names]
    shoulder, at = max(shoulders, default=(0.0, 0))
    head = _peak(sites[:, site_names.index(HEAD_SITE)])[0] if HEAD_SITE in site_names else 0.0
    return {
        "reaction": kind,
        "reaction_shoulders_cm": round(shoulder, 3),
        "reaction_head_cm": round(head, 3),
        "reaction_muzzle_cm": None if muzzle is None else round(_peak(muzzle)[0], 3),
        "reaction_peak_s": round(at / fps, 4),
    }
