"""Segment/site/joint layouts of ``soldier.fig`` (the polybody) and ``DI.fig`` (seed 002, 3.4.3).

Conventions (neutral pose = all DOFs zero = standing, arms at the sides, facing -Z):

* every segment frame and every site frame is parallel to the figure frame in the neutral pose; a
  segment's origin is its proximal joint, so its ``proximal`` site is the identity;
* DOF axes are written in those frames, mirrored for the left side so that a positive angle means the
  same anatomical motion on both sides (flexion, abduction, internal rotation, pronation);
* angles in radians (limits given here in degrees), translations in centimetres.

Counts (checked by the tests): soldier.fig 69 segments, 68 joints, 134 DOFs, 180 sites;
DI.fig 24 segments, 23 joints, 50 DOFs, 147 sites. How the DI's torso reaches those counts:
``waist`` (shared with the soldier, so angles copy from the waist down), then the seed's "two
rotational joints and one translational joint" replacing the 17-joint spine (``belly`` R3,
``spine_compression`` T1, ``upper_spine`` R3: the 7-DOF torso), with the virtual segments ``lumbar``
and ``thoracic`` between them, and a virtual ``eyes`` segment (2-DOF gaze, no eyeballs) ending the
"top of spine - eyes" chain.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from authoring.anthropometry import VERTEBRAE
from authoring.figure_segmentation import FINGER_NAMES

SIDES = ("left", "right")


@dataclass(frozen=True)
class DofSpec:
    kind: str  # "R" or "T"
    axis: tuple[float, float, float]
    lower: float  # radians (R) or cm (T)
    upper: float


@dataclass(frozen=True)
class JointSpec:
    name: str
    parent: str  # segment
    parent_site: str  # site on the parent segment (site1)
    child: str  # segment; site2 is the child's "proximal"
    dofs: tuple[DofSpec, ...]


@dataclass
class Skeleton:
    """A figure layout in figure coordinates (neutral pose), before it becomes a Peabody Figure."""

    name: str
    origins: dict[str, np.ndarray] = field(default_factory=dict)  # segment -> frame origin
    sites: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # segment -> site -> point
    joints: list[JointSpec] = field(default_factory=list)
    virtual: set[str] = field(default_factory=set)  # segments without a psurf

    def segment(self, name: str, origin: np.ndarray, distal: np.ndarray, *, virtual: bool = False) -> None:
        self.origins[name] = np.asarray(origin, dtype=np.float64).copy()
        self.sites[name] = {"proximal": self.origins[name].copy(), "distal": np.asarray(distal, float).copy()}
        if virtual:
            self.virtual.add(name)

    def site(self, segment: str, name: str, point: np.ndarray) -> None:
        if name in self.sites[segment]:
            raise ValueError(f"duplicate site {segment}.{name}")
        self.sites[segment][name] = np.asarray(point, dtype=np.float64).copy()

    def joint(self, name: str, parent: str, parent_site: str, child: str, *dofs: DofSpec) -> None:
        if parent_site not in self.sites[parent]:
            raise ValueError(f"joint {name}: no site {parent}.{parent_site}")
        self.joints.append(JointSpec(name, parent, parent_site, child, tuple(dofs)))

    @property
    def site_count(self) -> int:
        return sum(len(s) for s in self.sites.values())

    @property
    def dof_count(self) -> int:
        return sum(len(j.dofs) for j in self.joints)


# ------------------------------------------------------------------------------------------ DOF helpers


def R(axis: np.ndarray | tuple[float, float, float], lower_deg: float, upper_deg: float) -> DofSpec:
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    if not lower_deg <= 0.0 <= upper_deg:
        raise ValueError("the neutral pose (0) must lie within the limits")
    return DofSpec(
        "R",
        (float(a[0]), float(a[1]), float(a[2])),
        float(np.radians(lower_deg)),
        float(np.radians(upper_deg)),
    )


def T(axis: tuple[float, float, float], lower_cm: float, upper_cm: float) -> DofSpec:
    return DofSpec("T", axis, float(lower_cm), float(upper_cm))


def mirror(side: str, axis: tuple[float, float, float]) -> tuple[float, float, float]:
    """Axes are given for the right side (+X); the left side's rotation axes mirror as (x, -y, -z)."""
    return axis if side == "right" else (axis[0], -axis[1], -axis[2])


X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
NX, NZ = (-1.0, 0.0, 0.0), (0.0, 0.0, -1.0)


def spine3(lat: float, flex: tuple[float, float], twist: float) -> tuple[DofSpec, DofSpec, DofSpec]:
    """Midline 3-DOF joint ``R(z) * R(-x) * R(y)``: lateral bend (+ = left), flexion (+ = forward), twist."""
    return R(Z, -lat, lat), R(NX, -flex[0], flex[1]), R(Y, -twist, twist)


# ------------------------------------------------------------------------------------------ limbs


def long_axis(side: str, top: np.ndarray, bottom: np.ndarray) -> np.ndarray:
    """A limb's long axis for its twist DOF (pointing up the limb on the right, mirrored on the left)."""
    a = _unit(np.asarray(top, dtype=np.float64) - bottom)
    return a if side == "right" else -a


def _legs(sk: Skeleton, lm: dict[str, np.ndarray]) -> None:
    """Hips, knees, ankles and toes: identical on both figures (seed: angles copy from the waist down)."""
    for s in SIDES:
        m = partial(mirror, s)
        sk.segment(f"{s}_upper_leg", lm[f"{s}_hip"], lm[f"{s}_knee"])
        sk.segment(f"{s}_lower_leg", lm[f"{s}_knee"], lm[f"{s}_ankle"])
        sk.segment(f"{s}_foot", lm[f"{s}_ankle"], lm[f"{s}_ball"])
        sk.segment(f"{s}_toes", lm[f"{s}_ball"], lm[f"{s}_toe_tip"])
        sk.site("lower_torso", f"{s}_hip", lm[f"{s}_hip"])
        sk.site(f"{s}_lower_leg", "knee", lm[f"{s}_kneecap"])
        for site in ("heel", "toe", "ball", "lateral", "medial"):
            key = {"ball": "foot_ball", "lateral": "foot_lateral", "medial": "foot_medial"}.get(site, site)
            sk.site(f"{s}_foot", site, lm[f"{s}_{key}"])
        # hip: abduction (+), flexion (+), internal rotation (+)
        sk.joint(
            f"{s}_hip",
            "lower_torso",
            f"{s}_hip",
            f"{s}_upper_leg",
            R(m(Z), -30, 45),
            R(X, -30, 125),
            R(long_axis(s, lm[f"{s}_hip"], lm[f"{s}_knee"]), -45, 40),
        )
        sk.joint(f"{s}_knee", f"{s}_upper_leg", "distal", f"{s}_lower_leg", R(NX, 0, 150))  # flexion only
        # ankle: dorsiflexion (+) / plantarflexion (-), inversion (+) / eversion (-)
        sk.joint(f"{s}_ankle", f"{s}_lower_leg", "distal", f"{s}_foot", R(X, -50, 25), R(m(NZ), -20, 30))
        sk.joint(f"{s}_toes", f"{s}_foot", "distal", f"{s}_toes", R(X, -40, 70))  # extension (+)


def _arm(sk: Skeleton, lm: dict[str, np.ndarray], s: str, *, virtual_clavicle: bool) -> None:
    m = partial(mirror, s)
    sk.segment(f"{s}_clavicle", lm[f"{s}_sc"], lm[f"{s}_shoulder"], virtual=virtual_clavicle)
    sk.segment(f"{s}_upper_arm", lm[f"{s}_shoulder"], lm[f"{s}_elbow"])
    sk.segment(f"{s}_lower_arm", lm[f"{s}_elbow"], lm[f"{s}_wrist"])
    sk.segment(f"{s}_palm", lm[f"{s}_wrist"], lm[f"{s}_middle_1"])
    sk.site("upper_torso", f"{s}_clavicle", lm[f"{s}_sc"])
    sk.site(f"{s}_clavicle", "acromion", lm[f"{s}_acromion"])
    sk.site(f"{s}_palm", "palmcenter", lm[f"{s}_palmcenter"])
    sk.site(f"{s}_palm", "grip", lm[f"{s}_grip"])
    # clavicle: elevation (+), protraction (+)
    sk.joint(
        f"{s}_clavicle", "upper_torso", f"{s}_clavicle", f"{s}_clavicle", R(m(Z), -10, 40), R(m(Y), -25, 25)
    )
    # shoulder: abduction (+), flexion (+), internal rotation (+)
    sk.joint(
        f"{s}_shoulder",
        f"{s}_clavicle",
        "distal",
        f"{s}_upper_arm",
        R(m(Z), -15, 180),
        R(X, -60, 180),
        R(long_axis(s, lm[f"{s}_shoulder"], lm[f"{s}_elbow"]), -90, 90),
    )
    # elbow: flexion only (no hyper-extension), forearm pronation (+) / supination (-)
    forearm = long_axis(s, lm[f"{s}_elbow"], lm[f"{s}_wrist"])
    sk.joint(f"{s}_elbow", f"{s}_upper_arm", "distal", f"{s}_lower_arm", R(X, 0, 150), R(forearm, -90, 90))
    # wrist: flexion toward the palm (+), radial deviation toward the thumb (+)
    sk.joint(f"{s}_wrist", f"{s}_lower_arm", "distal", f"{s}_palm", R(m(NZ), -70, 80), R(X, -35, 20))


def _finger_axes(lm: dict[str, np.ndarray], s: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(flexion axis, abduction axis) of one digit from its geometry: flexion curls toward the palm."""
    sg = -1.0 if s == "left" else 1.0
    palm_dir = np.array([-sg, 0.0, 0.0])  # the palm faces the thigh
    thumbward = np.array([0.0, 0.0, -1.0])  # thumbs point forward
    d = lm[f"{s}_{name}_4"] - lm[f"{s}_{name}_1"]
    d = d / np.linalg.norm(d)
    if name == "thumb":  # the thumb flexes across the palm, toward the little finger
        across = lm[f"{s}_pinky_1"] - lm[f"{s}_index_1"]
        curl = across - (across @ d) * d
        out = palm_dir - (palm_dir @ d) * d
        return _unit(np.cross(d, curl)), _unit(np.cross(d, out))
    curl = palm_dir - (palm_dir @ d) * d
    toward = thumbward - (thumbward @ d) * d
    return _unit(np.cross(d, curl)), _unit(np.cross(d, toward))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


# MCP abduction: the middle finger is the reference axis of the hand's ab/adduction, so it has flexion only.
_MCP_ABDUCTION = {"index": (-20, 20), "ring": (-20, 20), "pinky": (-30, 15)}


def _fingers(sk: Skeleton, lm: dict[str, np.ndarray], s: str) -> None:
    for name in FINGER_NAMES:
        if name != "middle":
            sk.site(f"{s}_palm", name, lm[f"{s}_{name}_1"])
        flex, abd = _finger_axes(lm, s, name)
        for p in (1, 2, 3):
            seg = f"{s}_{name}{p}"
            sk.segment(seg, lm[f"{s}_{name}_{p}"], lm[f"{s}_{name}_{p + 1}"])
            parent, parent_site = (
                (f"{s}_palm", "distal" if name == "middle" else name)
                if p == 1
                else (f"{s}_{name}{p - 1}", "distal")
            )
            if name == "thumb":
                joint = ("cmc", "mcp", "ip")[p - 1]
                dofs = ((R(flex, -20, 45), R(abd, -10, 60)), (R(flex, 0, 60),), (R(flex, -10, 80),))[p - 1]
            else:
                joint = ("mcp", "pip", "dip")[p - 1]
                dofs = ((R(flex, -20, 90),), (R(flex, 0, 110),), (R(flex, 0, 80),))[p - 1]
                if p == 1 and name in _MCP_ABDUCTION:
                    dofs = (*dofs, R(abd, *_MCP_ABDUCTION[name]))
            sk.joint(f"{s}_{name}_{joint}", parent, parent_site, seg, *dofs)


def _head(sk: Skeleton, lm: dict[str, np.ndarray], upper: str) -> None:
    sk.segment("neck", lm["neck"], lm["head"])
    sk.segment("bottom_head", lm["head"], lm["head_top"])
    sk.site("bottom_head", "sight", lm["sight"])
    for name in ("nose", "chin", "left_ear", "right_ear"):
        sk.site("bottom_head", name, lm[name])
    sk.joint("neck", upper, "distal", "neck", *spine3(40, (50, 50), 70))
    sk.joint("head", "neck", "distal", "bottom_head", *spine3(10, (20, 20), 10))  # atlanto-occipital


def _torso_landmark_sites(sk: Skeleton, lm: dict[str, np.ndarray], lower: str, upper: str) -> None:
    sk.site(lower, "front", lm["belt_front"])
    sk.site(lower, "back", lm["belt_back"])
    sk.site(upper, "sternum", lm["sternum"])
    sk.site(upper, "back", lm["back"])


# ------------------------------------------------------------------------------------------ figures

# per-level spine limits (degrees): lateral, (extension, flexion), twist
_LUMBAR_LEVEL = (6.0, (4.0, 12.0), 3.0)
_THORACIC_LEVEL = (4.0, (3.0, 5.0), 5.0)


def soldier_skeleton(lm: dict[str, np.ndarray]) -> Skeleton:
    """The polybody: 17-joint spine, fingers, eyeballs (69 segments, 68 joints, 134 DOFs, 180 sites)."""
    sk = Skeleton("soldier")
    sk.segment("lower_torso", lm["pelvis"], lm["waist"])
    points = [lm["waist"]] + [lm[f"v{v}"] for v in VERTEBRAE]
    for i, name in enumerate(VERTEBRAE):
        sk.segment(name, points[i], points[i + 1])
    sk.segment("upper_torso", lm["vt1"], lm["neck"])
    sk.site("t12", "DI_middletarget", lm["vt12"])
    sk.joint("waist", "lower_torso", "distal", VERTEBRAE[0], *spine3(20, (20, 45), 20))
    chain = (*VERTEBRAE, "upper_torso")
    for i, name in enumerate(VERTEBRAE):
        level = _LUMBAR_LEVEL if name.startswith("l") else _THORACIC_LEVEL
        sk.joint(f"v{name}", name, "distal", chain[i + 1], *spine3(level[0], level[1], level[2]))
    _torso_landmark_sites(sk, lm, "lower_torso", "upper_torso")
    _head(sk, lm, "upper_torso")
    for s in SIDES:
        sk.segment(f"{s}_eyeball", lm[f"{s}_eye"], lm[f"{s}_pupil"])
        sk.site("bottom_head", f"{s}_eye", lm[f"{s}_eye"])
        sk.joint(f"{s}_eye", "bottom_head", f"{s}_eye", f"{s}_eyeball", R(Y, -35, 35), R(X, -30, 25))
    for s in SIDES:
        _arm(sk, lm, s, virtual_clavicle=False)
        _fingers(sk, lm, s)
    _legs(sk, lm)
    return sk


def di_skeleton(lm: dict[str, np.ndarray]) -> Skeleton:
    """The low-resolution DI: no spine, fingers, eyeballs or clavicle psurfs (24/23/50, 147 sites)."""
    sk = Skeleton("DI")
    belly_at = lm["vl3"]  # belly joint mid-lumbar
    middle_top = lm["vt12"]  # matches the soldier's t12.DI_middletarget
    sk.segment("lower_torso", lm["pelvis"], lm["waist"])
    sk.segment("lumbar", lm["waist"], belly_at, virtual=True)
    sk.segment("middle_torso", belly_at, middle_top)
    sk.site("middle_torso", "upper_torso", middle_top)
    sk.site("middle_torso", "navel", lm["navel"])
    sk.segment("thoracic", middle_top, middle_top, virtual=True)
    sk.segment("upper_torso", middle_top, lm["neck"])
    sk.joint("waist", "lower_torso", "distal", "lumbar", *spine3(20, (20, 45), 20))
    sk.joint("belly", "lumbar", "distal", "middle_torso", *spine3(25, (15, 50), 15))
    sk.joint("spine_compression", "middle_torso", "upper_torso", "thoracic", T(Y, -3.0, 1.0))
    sk.joint("upper_spine", "thoracic", "distal", "upper_torso", *spine3(40, (30, 50), 55))
    # the soldier's vertebral joint centres, as sites on the DI torso (targets for blending the spine)
    for name in VERTEBRAE:
        seg = "middle_torso" if lm[f"v{name}"][1] <= middle_top[1] + 1e-9 else "upper_torso"
        if name in ("l5", "l4"):
            seg = "lumbar"
        sk.site(seg, f"v{name}", lm[f"v{name}"])
    _torso_landmark_sites(sk, lm, "lower_torso", "upper_torso")
    _head(sk, lm, "upper_torso")
    sk.segment("eyes", lm["sight"], lm["sight"] + np.array([0.0, 0.0, -1.0]), virtual=True)
    sk.site("bottom_head", "eyes", lm["sight"])
    sk.joint("eyes", "bottom_head", "eyes", "eyes", R(Y, -35, 35), R(X, -30, 25))
    for s in SIDES:
        _arm(sk, lm, s, virtual_clavicle=True)
        # the soldier's finger joints and tips, as sites on the one-piece hand
        for name in FINGER_NAMES:
            for p in (1, 2, 3, 4):
                if (name, p) != ("middle", 1):
                    sk.site(f"{s}_palm", f"{name}{p}" if p > 1 else name, lm[f"{s}_{name}_{p}"])
        sk.site(f"{s}_palm", "knuckles", lm[f"{s}_knuckles"])
        sk.site(f"{s}_upper_arm", "deltoid", lm[f"{s}_deltoid"])
        sk.site(f"{s}_lower_arm", "olecranon", lm[f"{s}_olecranon"])
    _legs(sk, lm)
    for s in SIDES:
        sk.site(f"{s}_upper_leg", "trochanter", lm[f"{s}_trochanter"])
        sk.site(f"{s}_lower_leg", "malleolus", lm[f"{s}_malleolus"])
    return sk
