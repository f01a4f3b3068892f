"""Soldier and DI figures as Peabody objects: skeleton + the skin cut into per-segment psurfs.

Why separate from the layouts: :mod:`figure_skeleton` says where segments, sites and joints are;
this module decides which skin goes to which segment (part -> segment rules, torso bands), how many
polygons each part gets, and turns everything into :mod:`peabody.model` objects with each psurf
in its segment's frame.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from authoring.anthropometry import VERTEBRAE
from authoring.figure_landmarks import landmarks
from authoring.figure_segmentation import (
    FINGER_NAMES,
    SegmentMesh,
    face_parts,
    segment_meshes,
)
from authoring.figure_skeleton import SIDES, Skeleton, di_skeleton, soldier_skeleton
from authoring.makehuman_mesh import MakeHumanBody
from peabody.model import Dof, Figure, Joint, Psurf, Segment, Site

# Surface colours (diffuse RGB): a soldier in olive-drab fatigues and black boots.
MATERIALS: dict[str, tuple[float, float, float]] = {
    "uniform": (0.33, 0.36, 0.22),
    "skin": (0.80, 0.62, 0.50),
    "boots": (0.08, 0.08, 0.07),
    "eye": (0.92, 0.92, 0.90),
}

# Triangle budgets per decimation group; with the caps closing the cuts the totals come to the seed's
# polygon counts (seed 002, 3.4.3: soldier.fig 2410, DI.fig 478).
SOLDIER_BUDGET: dict[str, int] = {
    "torso": 820,
    "neck": 44,
    "bottom_head": 195,
    "eyeball": 12,
    "upper_arm": 80,
    "lower_arm": 64,
    "hand": 205,
    "upper_leg": 100,
    "lower_leg": 86,
    "foot": 90,
}
DI_BUDGET: dict[str, int] = {
    "torso": 134,
    "neck": 16,
    "bottom_head": 56,
    "upper_arm": 22,
    "lower_arm": 19,
    "hand": 21,
    "upper_leg": 27,
    "lower_leg": 22,
    "foot": 20,
}


def material_of(segment: str) -> str:
    if segment.endswith("eyeball"):
        return "eye"
    hand = segment.endswith("palm") or segment.rstrip("123").endswith(tuple(f"_{f}" for f in FINGER_NAMES))
    if hand or segment in ("neck", "bottom_head"):
        return "skin"
    if segment.endswith(("foot", "toes")):
        return "boots"
    return "uniform"


# ------------------------------------------------------------------------------------------ face rules


def _torso_bands(centroids: np.ndarray, bounds: ArrayLike, names: Sequence[str]) -> np.ndarray:
    """``names[i]`` for faces whose centroid height lies in band i (``len(names) == len(bounds) + 1``)."""
    return np.asarray(names, dtype=object)[np.searchsorted(np.asarray(bounds), centroids[:, 1], side="right")]


def _clavicle_carve(centroids: np.ndarray, lm: dict[str, np.ndarray]) -> np.ndarray:
    """Side ('left'/'right'/'') of torso faces on top of the shoulder girdle: the clavicle's skin.

    MakeHuman's clavicle bones dominate almost no vertices; Jack's clavicle segment is the shoulder top.
    """
    top = min(lm["left_sc"][1], lm["right_sc"][1]) - 3.0
    x = centroids[:, 0]
    inner = 0.45 * abs(lm["right_shoulder"][0] - lm["left_shoulder"][0]) / 2.0
    out = np.full(len(centroids), "", dtype=object)
    sel = centroids[:, 1] > top
    out[sel & (x < -inner)] = "left"
    out[sel & (x > inner)] = "right"
    return out


def soldier_face_segments(body: MakeHumanBody, parts: np.ndarray, lm: dict[str, np.ndarray]) -> np.ndarray:
    centroids = body.vertices[body.quads].mean(axis=1)
    seg = parts.astype(object).copy()
    seg[parts == "head"] = "bottom_head"
    torso = parts == "torso"
    bounds = lm["vertebra_bounds"]
    seg[torso] = _torso_bands(centroids[torso], bounds, ["lower_torso", *VERTEBRAE, "upper_torso"])
    carve = _clavicle_carve(centroids, lm)
    for s in SIDES:
        seg[torso & (carve == s)] = f"{s}_clavicle"
    return seg


def di_face_segments(body: MakeHumanBody, parts: np.ndarray, lm: dict[str, np.ndarray]) -> np.ndarray:
    centroids = body.vertices[body.quads].mean(axis=1)
    seg = parts.astype(object).copy()
    seg[parts == "head"] = "bottom_head"
    torso = (parts == "torso") | np.char.endswith(parts.astype(str), "_clavicle")
    cuts = [lm["waist"][1], lm["vt12"][1]]
    seg[torso] = _torso_bands(centroids[torso], cuts, ["lower_torso", "middle_torso", "upper_torso"])
    for s in SIDES:
        hand = np.zeros(len(parts), dtype=bool)
        for name in FINGER_NAMES:
            hand |= np.char.startswith(parts.astype(str), f"{s}_{name}")
        seg[hand] = f"{s}_palm"
    return seg


def soldier_groups(budget: dict[str, int]) -> list[tuple[list[str], int]]:
    groups: list[tuple[list[str], int]] = [
        (["lower_torso", *VERTEBRAE, "upper_torso", "left_clavicle", "right_clavicle"], budget["torso"]),
        (["neck"], budget["neck"]),
        (["bottom_head"], budget["bottom_head"]),
    ]
    for s in SIDES:
        fingers = [f"{s}_{n}{p}" for n in FINGER_NAMES for p in (1, 2, 3)]
        groups += [
            ([f"{s}_eyeball"], budget["eyeball"]),
            ([f"{s}_upper_arm"], budget["upper_arm"]),
            ([f"{s}_lower_arm"], budget["lower_arm"]),
            ([f"{s}_palm", *fingers], budget["hand"]),
            ([f"{s}_upper_leg"], budget["upper_leg"]),
            ([f"{s}_lower_leg"], budget["lower_leg"]),
            ([f"{s}_foot", f"{s}_toes"], budget["foot"]),
        ]
    return groups


def di_groups(budget: dict[str, int]) -> list[tuple[list[str], int]]:
    groups: list[tuple[list[str], int]] = [
        (["lower_torso", "middle_torso", "upper_torso"], budget["torso"]),
        (["neck"], budget["neck"]),
        (["bottom_head"], budget["bottom_head"]),
    ]
    for s in SIDES:
        groups += [
            ([f"{s}_upper_arm"], budget["upper_arm"]),
            ([f"{s}_lower_arm"], budget["lower_arm"]),
            ([f"{s}_palm"], budget["hand"]),
            ([f"{s}_upper_leg"], budget["upper_leg"]),
            ([f"{s}_lower_leg"], budget["lower_leg"]),
            ([f"{s}_foot", f"{s}_toes"], budget["foot"]),
        ]
    return groups


# ------------------------------------------------------------------------------------------ objects


def translation(p: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = p
    return t


def psurf_from_mesh(mesh: SegmentMesh, origin: np.ndarray, material: str, filename: str) -> Psurf:
    """Psurf in the segment frame (origin at the proximal joint); one attribute for the whole segment."""
    nodes = np.round(mesh.vertices - origin, 4) + 0.0  # + 0.0: no "-0.0" in the files
    return Psurf(
        nodes=nodes,
        faces=[np.asarray(f, dtype=np.int64) for f in mesh.faces] + list(mesh.caps),
        face_attributes=np.zeros(mesh.polygon_count, dtype=np.int64),
        attributes=[{"name": material, "diffuse": MATERIALS[material], "ambient": MATERIALS[material]}],
        filename=filename,
    )


def figure_from_skeleton(
    sk: Skeleton, meshes: dict[str, SegmentMesh], psurf_dir: str, root_location: np.ndarray
) -> Figure:
    """Peabody objects for a skeleton; ``psurf_dir`` is the psurf folder relative to the .fig file."""
    fig = Figure(sk.name)
    for name, origin in sk.origins.items():
        seg = fig.add_segment(Segment(name))
        for site_name, p in sk.sites[name].items():
            seg.add_site(Site(site_name, translation(np.round(p - origin, 4) + 0.0)))
        if name in sk.virtual:
            continue
        if name not in meshes:
            raise ValueError(f"segment {name!r} has no geometry")
        filename = f"{psurf_dir}/{name}.pss"
        seg.psurf = psurf_from_mesh(meshes[name], origin, material_of(name), filename)
        seg.psurf_file = filename
    for j in sk.joints:
        dofs = [Dof(d.kind, np.array(d.axis), d.lower, d.upper) for d in j.dofs]  # type: ignore[arg-type]
        site1 = fig.segments[j.parent].sites[j.parent_site]
        site2 = fig.segments[j.child].sites["proximal"]
        fig.add_joint(Joint(j.name, site1, site2, dofs))
    fig.root = fig.segments["lower_torso"].sites["proximal"]
    fig.location = translation(np.round(root_location, 4) + 0.0)
    return fig


def body_figures(body: MakeHumanBody) -> dict[str, Figure]:
    """``{"soldier": ..., "DI": ...}`` built on one posed body, so their landmarks coincide."""
    lm = landmarks(body)
    parts = face_parts(body, body.bone_parents)
    eyes = {f"{s}_eyeball": body.eyes[s[0]] for s in SIDES}
    soldier_meshes = segment_meshes(
        body,
        soldier_face_segments(body, parts, lm),
        soldier_groups(SOLDIER_BUDGET),
        extra=eyes,
        uncapped=VERTEBRAE,
    )
    di_meshes = segment_meshes(body, di_face_segments(body, parts, lm), di_groups(DI_BUDGET))
    return {
        "soldier": figure_from_skeleton(soldier_skeleton(lm), soldier_meshes, "soldier", lm["pelvis"]),
        "DI": figure_from_skeleton(di_skeleton(lm), di_meshes, "DI", lm["pelvis"]),
    }
