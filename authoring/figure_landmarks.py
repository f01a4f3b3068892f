"""Named landmark points on the posed MakeHuman body (figure coordinates, cm, neutral pose).

Why: joints and sites of both soldier figures sit on the same anatomical points, so the slaving
constraints of seed 002 (3.4.4) start out matched. Joint centres come from MakeHuman's joint cubes;
surface sites (heel, nose, sternum, ...) are found by casting a ray from inside the body and taking the
outermost skin vertex near it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from authoring.anthropometry import THORACIC_TOP_RATIO, VERTEBRAE, WAIST_HEIGHT_RATIO, vertebra_bounds
from authoring.figure_segmentation import FINGER_NAMES
from authoring.makehuman_mesh import MakeHumanBody

SIDE_KEYS = {"left": "l", "right": "r"}
# Jack axes: the figure's left is -X. Medial for the left side is +X, for the right side -X.
SIDE_SIGN = {"left": -1.0, "right": 1.0}


def surface_point(
    vertices: np.ndarray,
    start: np.ndarray,
    direction: np.ndarray | Sequence[float],
    radius: float = 1.5,
    reach: float = 40.0,
) -> np.ndarray:
    """Where the ray ``start + t * direction`` leaves the skin (outermost vertex within ``radius``)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    rel = vertices - start
    t = rel @ d
    off = np.linalg.norm(rel - t[:, None] * d, axis=1)
    ok = (t > 0) & (t < reach) & (off < radius)
    if not ok.any():
        raise ValueError(f"no skin found from {start} along {direction}")
    return start + t[ok].max() * d  # on the ray, so mid-plane landmarks stay on the mid-plane


def spine_curve(body: MakeHumanBody) -> np.ndarray:
    """Polyline (k, 3) through the rig's spine joints, bottom (pelvis) to top (neck base)."""
    j = body.joints
    names = ("joint-pelvis", "joint-spine-4", "joint-spine-3", "joint-spine-2", "joint-spine-1", "joint-neck")
    return np.array([j[n] for n in names])


def on_spine(curve: np.ndarray, y: float) -> np.ndarray:
    """The point of the spine polyline at height ``y`` (x forced to the mid-plane)."""
    z = float(np.interp(y, curve[:, 1], curve[:, 2]))
    return np.array([0.0, y, z])


def landmarks(body: MakeHumanBody) -> dict[str, np.ndarray]:
    """Every point the skeletons need, keyed ``"pelvis"``, ``"left_knee"``, ``"vertebra_bounds"`` ..."""
    j = body.joints
    v = body.vertices
    h = body.stature_cm
    lm: dict[str, np.ndarray] = {}
    lm["pelvis"] = j["joint-pelvis"].copy()
    curve = spine_curve(body)
    bounds = vertebra_bounds(WAIST_HEIGHT_RATIO * h, THORACIC_TOP_RATIO * h)
    lm["vertebra_bounds"] = bounds
    lm["waist"] = on_spine(curve, bounds[0])
    for i, name in enumerate(VERTEBRAE):
        lm[f"v{name}"] = on_spine(curve, bounds[i + 1])  # the joint at the top of vertebra `name`
    lm["neck"] = j["joint-neck"].copy()
    lm["head"] = j["joint-head"].copy()
    lm["head_top"] = np.array([0.0, v[:, 1].max(), j["joint-head-2"][2]])
    eyes = {s: j[f"joint-{k}-eye"] for s, k in SIDE_KEYS.items()}
    lm["sight"] = 0.5 * (eyes["left"] + eyes["right"])
    sight = lm["sight"]
    lm["nose"] = surface_point(v, sight + np.array([0.0, -3.5, 0.0]), [0.0, 0.0, -1.0])
    lm["chin"] = surface_point(v, sight + np.array([0.0, -11.5, 4.0]), [0.0, 0.0, -1.0])
    lm["sternum"] = surface_point(v, on_spine(curve, j["joint-l-clavicle"][1] - 1.0), [0.0, 0.0, -1.0])
    lm["back"] = surface_point(v, on_spine(curve, lm["neck"][1] - 3.0), [0.0, 0.0, 1.0])
    belt = on_spine(curve, bounds[0] - 4.0)
    lm["belt_front"] = surface_point(v, belt, [0.0, 0.0, -1.0], radius=2.5)
    lm["belt_back"] = surface_point(v, belt, [0.0, 0.0, 1.0], radius=2.5)
    lm["navel"] = surface_point(v, on_spine(curve, 0.6 * h), [0.0, 0.0, -1.0], radius=2.5)
    for side, k in SIDE_KEYS.items():
        sg = SIDE_SIGN[side]
        lateral = np.array([sg, 0.0, 0.0])
        lm[f"{side}_eye"] = eyes[side].copy()
        lm[f"{side}_pupil"] = surface_point(_eye_vertices(body, k), eyes[side], [0.0, 0.0, -1.0], radius=0.6)
        lm[f"{side}_ear"] = surface_point(
            v, np.array([0.0, eyes[side][1] - 2.0, lm["head"][2]]), lateral, 2.0
        )
        lm[f"{side}_hip"] = j[f"joint-{k}-upper-leg"].copy()
        lm[f"{side}_knee"] = j[f"joint-{k}-knee"].copy()
        lm[f"{side}_ankle"] = j[f"joint-{k}-ankle"].copy()
        ball = np.mean([j[f"joint-{k}-toe-{t}-1"] for t in range(1, 6)], axis=0)
        lm[f"{side}_ball"] = ball
        lm[f"{side}_kneecap"] = surface_point(v, lm[f"{side}_knee"], [0.0, 0.0, -1.0], radius=2.0)
        lm[f"{side}_trochanter"] = surface_point(v, lm[f"{side}_hip"], lateral, radius=2.5)
        lm[f"{side}_malleolus"] = surface_point(v, lm[f"{side}_ankle"], lateral, radius=1.5)
        # the foot: sole points on the ground plane
        foot = v[(np.abs(v[:, 0] - ball[0]) < 8.0) & (v[:, 1] < lm[f"{side}_ankle"][1])]
        lm[f"{side}_heel"] = np.array([lm[f"{side}_ankle"][0], 0.0, foot[:, 2].max()])
        tip = foot[np.argmin(foot[:, 2])]
        lm[f"{side}_toe_tip"] = np.array([tip[0], tip[1], tip[2]])
        lm[f"{side}_toe"] = np.array([tip[0], 0.0, tip[2]])
        lm[f"{side}_foot_ball"] = np.array([ball[0], 0.0, ball[2]])
        near_ball = foot[np.abs(foot[:, 2] - ball[2]) < 2.0]
        outer = near_ball[np.argmax(near_ball[:, 0] * sg)]
        inner = near_ball[np.argmin(near_ball[:, 0] * sg)]
        lm[f"{side}_foot_lateral"] = np.array([outer[0], 0.0, outer[2]])
        lm[f"{side}_foot_medial"] = np.array([inner[0], 0.0, inner[2]])
        # shoulder girdle and arm
        lm[f"{side}_sc"] = j[f"joint-{k}-clavicle"].copy()
        lm[f"{side}_shoulder"] = j[f"joint-{k}-shoulder"].copy()
        lm[f"{side}_acromion"] = surface_point(
            v, lm[f"{side}_shoulder"] - lateral * 1.5, [0.0, 1.0, 0.0], 2.0
        )
        lm[f"{side}_elbow"] = j[f"joint-{k}-elbow"].copy()
        lm[f"{side}_olecranon"] = surface_point(v, lm[f"{side}_elbow"], [0.0, 0.0, 1.0], radius=1.5)
        lm[f"{side}_deltoid"] = surface_point(v, lm[f"{side}_shoulder"] + [0.0, -8.0, 0.0], lateral, 2.0)
        lm[f"{side}_wrist"] = j[f"joint-{k}-hand"].copy()
        for f, name in enumerate(FINGER_NAMES, start=1):
            for p in range(1, 5):
                lm[f"{side}_{name}_{p}"] = j[f"joint-{k}-finger-{f}-{p}"].copy()
        # palm: centre of the palm surface (it faces the thigh, i.e. medially) and the grip axis
        knuckles = np.mean([lm[f"{side}_{n}_1"] for n in FINGER_NAMES[1:]], axis=0)
        mid = lm[f"{side}_wrist"] + 0.55 * (knuckles - lm[f"{side}_wrist"])
        medial = -lateral
        lm[f"{side}_palmcenter"] = surface_point(v, mid, medial, radius=1.5, reach=5.0)
        lm[f"{side}_grip"] = lm[f"{side}_palmcenter"] + 2.5 * medial
        lm[f"{side}_knuckles"] = surface_point(v, lm[f"{side}_middle_1"], lateral, radius=1.0, reach=4.0)
    return lm


def _eye_vertices(body: MakeHumanBody, key: str) -> np.ndarray:
    return body.eyes[key][0]
