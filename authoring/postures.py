"""The eight key postures of seed 002 (Figures 4 and 7) on ``soldier.fig`` holding an ``AK_47.fig`` rifle.

A posture is written the way an animator sets one up in Jack: a pelvis placement, a few joint angles that
give the style (lean, twist, head, fingers), where the feet, knees and elbows touch the ground, and where the
rifle is. :func:`solve_posture` then lets the IK solver (:mod:`authoring.ik`) do the rest, all goals in
one prioritised solve: palm centres on the rifle's ``grip`` / ``handguard`` (highest priority: the hands never
leave the gun), feet flat / knees down on the ground, the right eye on the line of sight when aiming, the
palms turned to hold the gun, elbows towards a natural place. The result is a
:class:`~authoring.motion.KeyPosture` for the figures ``soldier`` and ``AK_47``.

The clip frame (every channelset's local frame): origin on the ground between the feet of the standing
soldier, +Y up, the soldier's heading along -Z. "Stowed" means the rifle at the ready (low ready: butt in the
shoulder, muzzle lowered); "fire" means shouldered and aimed exactly along -Z, so TTES can orient the soldier
by his heading when he fires (seed 002, section 2). Standing and kneeling soldiers stand bladed (turned about
45 degrees to the right, left foot forward), as riflemen do; both standing postures share the feet, both
kneeling postures the legs, so firing <-> stowed moves only the arms, head and rifle.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from authoring import ik
from authoring.motion import KeyPosture
from peabody import values as V
from peabody.fk import FigureKinematics
from peabody.model import Figure

SOLDIER = "soldier"
RIFLE = "AK_47"
DEG = np.pi / 180.0

POSTURES: tuple[str, ...] = (
    "STAND_STOWED",
    "STAND_FIRE",
    "KNEEL_STOWED",
    "KNEEL_FIRE",
    "PRONE_STOWED",
    "PRONE_FIRE",
    "CRAWL",
    "DEAD",
)

SPINE: tuple[str, ...] = ("vl5", "vl4", "vl3", "vl2", "vl1", *(f"vt{i}" for i in range(12, 0, -1)))
SIDES: tuple[str, str] = ("left", "right")


def arm(side: str) -> tuple[str, ...]:
    return (f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist")


def leg(side: str) -> tuple[str, ...]:
    return (f"{side}_hip", f"{side}_knee", f"{side}_ankle")


# --- rigid placements ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Placement:
    """A rigid frame in the clip frame: position (cm) and Jack ``xyz`` angles (degrees, ``Rx Ry Rz``)."""

    position: tuple[float, float, float]
    angles: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        m = V.xyz_matrix(*(a * DEG for a in self.angles))
        m[:3, 3] = self.position
        return m


def _frame(normal: Sequence[float], fingers: Sequence[float], side: str) -> np.ndarray:
    """A palm orientation from the palm normal and the finger direction (rifle frame).

    In the zero pose both palms face the thighs (left palm normal +x, right -x), fingers point down (-y).
    """
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    f = np.asarray(fingers, float)
    f = f - n * (f @ n)
    f /= np.linalg.norm(f)
    c0 = n if side == "left" else -n
    c1 = -f
    return np.column_stack([c0, c1, np.cross(c0, c1)])


# How the palms sit on the rifle, in the rifle's frame: the right palm against the right side of the pistol
# grip, fingers wrapped forwards and down; the left palm under the handguard, palm up, fingers across it.
PALM_ON_RIFLE: dict[str, tuple[str, np.ndarray]] = {
    "right": ("rifle.grip", _frame((-1.0, 0.0, 0.0), (0.0, -0.7, -0.7), "right")),
    "left": ("rifle.handguard", _frame((0.0, 1.0, 0.2), (0.6, 0.1, -0.8), "left")),
}

# The shoulder pocket where the butt goes, in the right clavicle's frame (front of the chest, under the
# collar bone, medial of the shoulder joint); and how far the right eye sits above the line of sight.
SHOULDER_POCKET = np.array([11.7, -5.0, -9.6])
EYE_ABOVE_SIGHT = 1.2
EYE_BEHIND_SIGHT = (
    42.0  # cm behind the rear sight along the barrel (cheek on the stock, 11 cm ahead of the butt)
)


# --- leg contacts -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FootFlat:
    """A foot flat on the ground: heel at ``(x, 0, z)``, toes turned ``yaw`` degrees (positive = left)."""

    side: str
    heel: tuple[float, float]
    yaw: float = 0.0


@dataclass(frozen=True)
class KneeDown:
    """A kneeling leg: the kneecap (``lower_leg.knee``) at ``(x, height, z)`` and the ball of the foot on the
    ground at ``(x, ball_height, z)`` (the toes bent up by the style angles, or the instep down)."""

    side: str
    knee: tuple[float, float]
    ball: tuple[float, float]
    knee_height: float = 1.0
    ball_height: float = 1.0


@dataclass(frozen=True)
class ElbowDown:
    """A forearm on the ground: the elbow joint centre (``upper_arm.distal``) at ``(x, height, z)``."""

    side: str
    elbow: tuple[float, float]
    height: float = 4.0


Contact = FootFlat | KneeDown | ElbowDown


@dataclass(frozen=True)
class PostureSpec:
    """An animator's setting of one key posture (see the module docstring).

    ``joints``: style angles in degrees (DOF order of soldier.fig; missing joints are 0); ``spine``: total
    (lateral bend, flexion, twist) in degrees spread over the 17 vertebral joints in proportion to their
    ranges; ``aim``: the right eye goes onto the line of sight; ``elbow_hints``: where the elbows should go
    (clip frame, a weak goal that picks the arm's swivel); ``ground``: lower the figure and rifle so that the
    lowest point of the body touches the ground (lying postures); ``head_offset``: degrees added to the solved
    neck/head joints (a head lifted off the stock of a body solved as if aiming, so both keep the same arms);
    ``pocket``: cm added to :data:`SHOULDER_POCKET` (right clavicle frame) where the butt goes — prone, the
    raised right arm's deltoid swings over the standing pocket, so the butt sits a little higher and inwards.
    """

    name: str
    root: Placement
    rifle: Placement
    joints: Mapping[str, Sequence[float]] = field(default_factory=dict)
    spine: tuple[float, float, float] = (0.0, 0.0, 0.0)
    contacts: tuple[Contact, ...] = ()
    aim: bool = False
    elbow_hints: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)
    ground: bool = False
    shouldered: bool = False
    look: bool = False
    head_offset: Mapping[str, Sequence[float]] = field(default_factory=dict)
    pocket: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _hand(side: str, trigger: bool = False) -> dict[str, tuple[float, ...]]:
    """Fingers closed around a handle (the right index finger along the trigger guard)."""
    out: dict[str, tuple[float, ...]] = {}
    for f in ("index", "middle", "ring", "pinky"):
        mcp, pip, dip = (20.0, 25.0, 10.0) if trigger and f == "index" else (65.0, 75.0, 35.0)
        out[f"{side}_{f}_mcp"] = (mcp,) if f == "middle" else (mcp, 0.0)
        out[f"{side}_{f}_pip"] = (pip,)
        out[f"{side}_{f}_dip"] = (dip,)
    out[f"{side}_thumb_cmc"] = (20.0, 30.0)
    out[f"{side}_thumb_mcp"] = (25.0,)
    out[f"{side}_thumb_ip"] = (20.0,)
    return out


GRIP_HANDS: dict[str, tuple[float, ...]] = {**_hand("right", trigger=True), **_hand("left")}


# --- building poses -----------------------------------------------------------------------------------------


def spine_angles(kin: FigureKinematics, lateral: float, flexion: float, twist: float) -> np.ndarray:
    """``(17, 3)`` radians: a total spine bend spread over the vertebrae in proportion to their ranges."""
    idx = np.array([np.arange(kin.dof_slices[j].start, kin.dof_slices[j].stop) for j in SPINE])
    span = np.where(
        np.array([lateral, flexion, twist]) >= 0, kin.upper[idx], -kin.lower[idx]
    )  # (17, 3) room in the direction of the bend
    share = span / span.sum(axis=0)
    return share * np.array([lateral, flexion, twist]) * DEG


def style_pose(kin: FigureKinematics, spec: PostureSpec) -> np.ndarray:
    """The pose vector of the style angles alone (before IK)."""
    q = np.zeros(kin.ndof)
    for name, deg in {**GRIP_HANDS, **spec.joints}.items():
        sl = kin.dof_slices[name]
        q[sl] = np.asarray(deg, float) * DEG
    sp = spine_angles(kin, *spec.spine)
    for k, j in enumerate(SPINE):
        q[kin.dof_slices[j]] = sp[k]
    return kin.clamp(q)


def shoulder_pocket(
    kin: FigureKinematics, pose: np.ndarray, root: np.ndarray, offset: Sequence[float] = (0.0, 0.0, 0.0)
) -> np.ndarray:
    """Where the butt goes (clip frame) for a pose; ``offset``: a posture's :attr:`PostureSpec.pocket`."""
    g = kin.segment_globals(pose, root)[..., kin.segment_names.index("right_clavicle"), :, :]
    return g[..., :3, :3] @ (SHOULDER_POCKET + np.asarray(offset, float)) + g[..., :3, 3]


def palm_targets(rifle_kin: FigureKinematics, rifle: np.ndarray, side: str) -> np.ndarray:
    """``(..., 4, 4)``: where ``{side}_palm.palmcenter`` goes for rifle placements ``rifle``."""
    site, rot = PALM_ON_RIFLE[side]
    g = rifle @ rifle_kin.site_globals(np.zeros(0))[rifle_kin.site_names.index(site)]
    out = np.array(g, dtype=np.float64)
    out[..., :3, :3] = g[..., :3, :3] @ rot
    return out


def hand_goals(rifle_kin: FigureKinematics, rifle: np.ndarray, weight: object = 1.0) -> list[ik.Goal]:
    """Palm centres on the rifle (highest priority) and palms turned to grip it (low priority)."""
    goals: list[ik.Goal] = []
    for side in ("right", "left"):
        t = palm_targets(rifle_kin, rifle, side)
        chain = arm(side)
        goals.append(ik.Goal(f"{side}_palm.palmcenter", t[..., :3, 3], None, weight, 3, chain))
        goals.append(
            ik.Goal(
                f"{side}_palm.palmcenter", None, t[..., :3, :3], weight, 1, arm(side), orientation_weight=8.0
            )
        )
    return goals


def contact_goals(contacts: Sequence[Contact]) -> list[ik.Goal]:
    goals: list[ik.Goal] = []
    for c in contacts:
        if isinstance(c, FootFlat):
            x, z = c.heel
            goals.append(
                ik.Goal(f"{c.side}_foot.heel", (x, 0.0, z), V.rot_y(c.yaw * DEG), 1.0, 2, leg(c.side))
            )
        elif isinstance(c, ElbowDown):
            x, z = c.elbow
            chain = (f"{c.side}_clavicle", f"{c.side}_shoulder")
            goals.append(ik.Goal(f"{c.side}_upper_arm.distal", (x, c.height, z), None, 1.0, 2, chain))
        else:
            goals.append(
                ik.Goal(
                    f"{c.side}_lower_leg.knee",
                    (c.knee[0], c.knee_height, c.knee[1]),
                    None,
                    1.0,
                    2,
                    leg(c.side),
                )
            )
            ball = (c.ball[0], c.ball_height, c.ball[1])
            goals.append(ik.Goal(f"{c.side}_foot.ball", ball, None, 1.0, 2, leg(c.side)))
    return goals


def _aim_goal(kin: FigureKinematics, rifle_kin: FigureKinematics, rifle: np.ndarray) -> ik.Goal:
    sight = rifle @ rifle_kin.site_globals(np.zeros(0))[rifle_kin.site_names.index("rifle.sight")]
    eye = sight[:3, :3] @ np.array([0.0, EYE_ABOVE_SIGHT, EYE_BEHIND_SIGHT]) + sight[:3, 3]
    return ik.Goal("bottom_head.right_eye", eye, None, 1.0, 2, ("neck", "head"))


def solve_posture(
    spec: PostureSpec, kin: FigureKinematics, rifle_kin: FigureKinematics
) -> tuple[KeyPosture, ik.SolveReport]:
    """The key posture for ``spec``: style angles, then one prioritised IK solve for all goals."""
    root = spec.root.matrix()
    rifle = spec.rifle.matrix()
    q0 = style_pose(kin, spec)
    butt = rifle_kin.site_globals(np.zeros(0))[rifle_kin.site_names.index("rifle.butt"), :, 3]
    q = q0
    for _ in range(4 if spec.shouldered else 1):
        if spec.shouldered:  # slide the rifle so the butt meets the pocket of the current pose
            rifle[:3, 3] += shoulder_pocket(kin, q, root, spec.pocket) - (rifle @ butt)[:3]
        goals = hand_goals(rifle_kin, rifle) + contact_goals(spec.contacts)
        if spec.aim:
            goals.append(_aim_goal(kin, rifle_kin, rifle))
        if spec.look:
            goals.append(ik.Goal("bottom_head.sight", None, np.eye(3), 1.0, 1, ("neck", "head")))
        for side, p in spec.elbow_hints.items():
            goals.append(ik.Goal(f"{side}_upper_arm.distal", p, None, 0.3, 0, arm(side)[:1]))
        q, report = ik.solve(kin, q0, goals, root, iterations=200, rest_pose=q0, rest_gain=0.05)
    if spec.head_offset:
        q = q.copy()
        for name, deg in spec.head_offset.items():
            q[kin.dof_slices[name]] += np.asarray(deg, float) * DEG
        q = kin.clamp(q)
    if spec.ground:
        drop = lowest_point(kin, q, root)
        root = root.copy()
        rifle = rifle.copy()
        root[1, 3] -= drop
        rifle[1, 3] -= drop
    key = KeyPosture(spec.name, {SOLDIER: q, RIFLE: np.zeros(0)}, {SOLDIER: root, RIFLE: rifle})
    return key, report


# --- ground contact -----------------------------------------------------------------------------------------


def segment_heights(kin: FigureKinematics, pose: np.ndarray, root: np.ndarray) -> dict[str, np.ndarray]:
    """Lowest psurf point of every segment with geometry, per pose (``(...)`` arrays, cm)."""
    g = kin.segment_globals(pose, root)
    out: dict[str, np.ndarray] = {}
    for i, name in enumerate(kin.segment_names):
        ps = kin.figure.segments[name].psurf
        if ps is None or not len(ps.nodes):
            continue
        y = np.einsum("...j,nj->...n", g[..., i, 1, :3], ps.nodes) + g[..., i, 1, 3, None]
        out[name] = y.min(axis=-1)
    return out


def lowest_point(kin: FigureKinematics, pose: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Height of the body's lowest psurf point (0 = touching the ground)."""
    h = segment_heights(kin, pose, root)
    return np.min(np.stack(list(h.values())), axis=0)


# --- the eight postures -------------------------------------------------------------------------------------

# Both standing postures: bladed 40 degrees to the right, left foot forward, knees soft.
_STAND_ROOT = Placement((0.0, 100.0, 0.0), (0.0, -45.0, 0.0))
_STAND_FEET = (FootFlat("left", (-15.0, -12.0), -10.0), FootFlat("right", (2.0, 14.0), -25.0))
_STAND_LEGS = {
    "left_hip": (0.0, 10.0, 0.0),
    "left_knee": (15.0,),
    "right_hip": (0.0, -5.0, 0.0),
    "right_knee": (10.0,),
}
_STAND_ARMS = {
    "right_shoulder": (60.0, 30.0, 30.0),
    "right_elbow": (100.0, 0.0),
    "left_shoulder": (0.0, 60.0, 30.0),
    "left_elbow": (40.0, -60.0),
}

_AIMED = Placement((0.0, 0.0, 0.0))  # the rifle's orientation when firing (position: shouldered)
_LOW_READY = Placement((0.0, 0.0, 0.0), (-35.0, 10.0, 0.0))  # muzzle lowered and turned in
# kneeling, the left thigh rises across where a low-ready muzzle turned in points: muzzle straight ahead and
# a little higher, so the rifle is carried clear of the thigh
_KNEEL_READY = Placement((0.0, 0.0, 0.0), (-30.0, 0.0, 0.0))

_STANDING = {
    **_STAND_LEGS,
    **_STAND_ARMS,
    "waist": (0.0, 6.0, 0.0),
    "right_clavicle": (25.0, 5.0),
    "left_clavicle": (0.0, 25.0),
}

# Both kneeling postures: right knee and toes down, left foot forward, seated high over the right heel. The
# pelvis is low enough that the right kneecap rests on the ground (the leg cannot reach it from higher).
_KNEEL_ROOT = Placement((2.0, 53.8, 2.0), (0.0, -30.0, 0.0))
_KNEEL_LEGS = (
    FootFlat("left", (12.0, -36.0), -35.0),
    KneeDown("right", (16.0, 14.0), (20.0, 64.0), knee_height=-0.5, ball_height=5.5),
)
_KNEELING = {
    **_STAND_ARMS,
    "left_hip": (0.0, 80.0, 0.0),
    "left_knee": (90.0,),
    "right_hip": (0.0, 5.0, 0.0),
    "right_knee": (100.0,),
    "right_toes": (60.0,),
    "right_ankle": (0.0, 0.0),
    "right_clavicle": (25.0, 5.0),
    "left_clavicle": (0.0, 25.0),
}

# Prone: face down, the body turned 55 degrees off the line of fire (left shoulder forward, legs apart, toes
# turned out), belly and thighs on the ground, the chest raised on both elbows: the forearms lie on the ground
# (the left under the handguard, the right out to the side), as a rifleman lies in the prone position. The
# chest is as high as the spine allows, so the shouldered rifle's magazine clears the ground; the rifle is
# canted (magazine out to the right) a little when firing, more when stowed (cheek off the stock, head up).
_PRONE_ROOT = Placement((0.0, 12.0, 0.0), (-90.0, -0.3, -55.0))
_PRONE = {
    "left_hip": (20.0, 0.0, -25.0),
    "right_hip": (20.0, 0.0, -25.0),
    "left_ankle": (-40.0, 0.0),
    "right_ankle": (-40.0, 0.0),
    "neck": (0.0, -40.0, 0.0),
    "head": (0.0, -15.0, 0.0),
    "right_clavicle": (10.0, -25.0),
    "left_clavicle": (10.0, -25.0),
    "right_shoulder": (30.0, 150.0, 0.0),
    "left_shoulder": (20.0, 160.0, 0.0),
    "right_elbow": (90.0, 0.0),
    "left_elbow": (60.0, 0.0),
}
_PRONE_SPINE = (-15.0, -55.1, -9.0)  # chest raised to the limit of the spine, bent a little towards the rifle
_PRONE_ELBOWS = (ElbowDown("left", (41.2, -60.8), 1.0), ElbowDown("right", (56.0, -19.0), 0.0))
_PRONE_POCKET = (1.1, 5.3, -2.5)
_PRONE_CANT = -15.3

SPECS: dict[str, PostureSpec] = {
    "STAND_STOWED": PostureSpec(
        "STAND_STOWED",
        root=_STAND_ROOT,
        rifle=_LOW_READY,
        joints={**_STANDING, "neck": (0.0, 5.0, 30.0)},
        spine=(-3.0, 12.0, -5.0),
        contacts=_STAND_FEET,
        look=True,
        shouldered=True,
    ),
    "STAND_FIRE": PostureSpec(
        "STAND_FIRE",
        root=_STAND_ROOT,
        rifle=_AIMED,
        joints={**_STANDING, "neck": (0.0, 25.0, 10.0), "head": (-8.0, 5.0, 5.0)},
        spine=(-3.0, 16.0, -5.0),
        contacts=_STAND_FEET,
        aim=True,
        shouldered=True,
    ),
    "KNEEL_STOWED": PostureSpec(
        "KNEEL_STOWED",
        root=_KNEEL_ROOT,
        rifle=_KNEEL_READY,
        joints={**_KNEELING, "neck": (0.0, 5.0, 25.0)},
        spine=(-3.0, 10.0, -5.0),
        contacts=_KNEEL_LEGS,
        look=True,
        shouldered=True,
    ),
    "KNEEL_FIRE": PostureSpec(
        "KNEEL_FIRE",
        root=_KNEEL_ROOT,
        rifle=_AIMED,
        joints={**_KNEELING, "neck": (0.0, 25.0, 10.0), "head": (-8.0, 5.0, 5.0)},
        spine=(-3.0, 20.0, -15.0),
        contacts=_KNEEL_LEGS,
        aim=True,
        shouldered=True,
    ),
    "PRONE_STOWED": PostureSpec(
        "PRONE_STOWED",
        root=_PRONE_ROOT,
        rifle=Placement((0.0, 0.0, 0.0), (0.0, 0.0, _PRONE_CANT)),
        joints={**_PRONE, "neck": (-10.0, -35.0, 10.0)},
        spine=_PRONE_SPINE,
        contacts=_PRONE_ELBOWS,
        pocket=_PRONE_POCKET,
        aim=True,  # the arms as when firing; then the head lifts off the stock
        head_offset={"neck": (10.0, -30.0, 0.0), "head": (0.0, -10.0, 0.0)},
        shouldered=True,
        ground=True,
    ),
    "PRONE_FIRE": PostureSpec(
        "PRONE_FIRE",
        root=_PRONE_ROOT,
        rifle=Placement((0.0, 0.0, 0.0), (0.0, 0.0, _PRONE_CANT)),  # aimed along -Z, canted
        joints={**_PRONE, "neck": (-10.0, -35.0, 10.0)},
        spine=_PRONE_SPINE,
        contacts=_PRONE_ELBOWS,
        pocket=_PRONE_POCKET,
        aim=True,
        shouldered=True,
        ground=True,
    ),
    "CRAWL": PostureSpec(
        "CRAWL",
        root=Placement((0.0, 38.0, 0.0), (-107.0, 0.0, 0.0)),
        # cradled across the hands in front of the forearms, on its side: muzzle to the left, magazine forward
        rifle=Placement((15.0, 12.8, -80.2), (0.0, 76.0, -90.0)),
        joints={
            "left_hip": (10.0, 90.0, 0.0),
            "right_hip": (10.0, 90.0, 0.0),
            "left_knee": (90.0,),
            "right_knee": (90.0,),
            "left_ankle": (-40.0, 0.0),
            "right_ankle": (-40.0, 0.0),
            "neck": (0.0, -40.0, 0.0),
            "head": (0.0, -15.0, 0.0),
            "right_shoulder": (135.0, 62.0, -77.0),
            "left_shoulder": (43.0, 142.0, -35.0),
            "right_elbow": (112.0, -9.0),
            "left_elbow": (57.0, -62.0),
            "right_wrist": (16.0, -26.0),
            "left_wrist": (-21.0, -9.0),
        },
        spine=(0.0, -10.0, 0.0),
        contacts=(
            KneeDown("left", (-16.0, 32.0), (-16.0, 82.0), knee_height=3.0, ball_height=7.0),
            KneeDown("right", (16.0, 32.0), (16.0, 82.0), knee_height=3.0, ball_height=7.0),
            ElbowDown("left", (-20.0, -55.0), 1.5),
            ElbowDown("right", (20.0, -55.0), 3.0),
        ),
        look=True,
        ground=True,
    ),
    "DEAD": PostureSpec(
        "DEAD",
        root=Placement((0.0, 11.0, 0.0), (-90.0, 0.0, 8.0)),
        rifle=Placement((20.0, 3.0, -70.0), (0.0, 30.0, -90.0)),
        elbow_hints={"right": (34.0, 6.0, -50.0), "left": (-22.0, 6.0, -62.0)},
        joints={
            "left_hip": (30.0, 0.0, -20.0),
            "right_hip": (10.0, 0.0, -20.0),
            "left_knee": (45.0,),
            "right_knee": (5.0,),
            "left_ankle": (-45.0, 0.0),
            "right_ankle": (-45.0, 0.0),
            "neck": (0.0, -10.0, 60.0),
            "head": (10.0, 0.0, 10.0),
            "right_shoulder": (40.0, 140.0, 0.0),
            "left_shoulder": (18.0, 170.0, 68.0),
            "right_elbow": (60.0, 0.0),
            "left_elbow": (25.0, -70.0),
            "left_wrist": (-50.0, -34.0),
        },
        spine=(-5.0, 0.0, 5.0),
        ground=True,
    ),
}


# In-between keys of the transitions (not graph postures): kneeling on both knees, and slumping forward on
# them (the first half of falling dead).
_BOTH_KNEES = (
    KneeDown("left", (-14.0, 8.0), (-16.0, 58.0), knee_height=2.0, ball_height=5.0),
    KneeDown("right", (14.0, 8.0), (16.0, 58.0), knee_height=2.0, ball_height=5.0),
)
_ON_KNEES = {
    **_STAND_ARMS,
    "left_hip": (0.0, 10.0, 0.0),
    "right_hip": (0.0, 10.0, 0.0),
    "left_knee": (100.0,),
    "right_knee": (100.0,),
    "left_toes": (60.0,),
    "right_toes": (60.0,),
    "right_clavicle": (25.0, 5.0),
    "left_clavicle": (0.0, 25.0),
}
IN_BETWEEN: dict[str, PostureSpec] = {
    "KNEEL_BOTH": PostureSpec(
        "KNEEL_BOTH",
        root=Placement((0.0, 54.0, 0.0), (0.0, -20.0, 0.0)),
        rifle=_LOW_READY,
        joints={**_ON_KNEES, "neck": (0.0, 5.0, 15.0)},
        spine=(-3.0, 15.0, -5.0),
        contacts=_BOTH_KNEES,
        look=True,
        shouldered=True,
    ),
    # the upper body and rifle carry of walking and running (the legs are the gait's)
    "WALK_READY": PostureSpec(
        "WALK_READY",
        root=Placement((0.0, 96.0, 0.0), (0.0, 0.0, 0.0)),
        rifle=_LOW_READY,
        joints={**_STANDING, "neck": (0.0, 5.0, 20.0)},
        spine=(-2.0, 8.0, -25.0),
        contacts=(FootFlat("left", (-11.0, 0.0), 0.0), FootFlat("right", (11.0, 0.0), 0.0)),
        look=True,
        shouldered=True,
    ),
    "RUN_READY": PostureSpec(
        "RUN_READY",
        root=Placement((0.0, 92.0, 0.0), (-10.0, 0.0, 0.0)),
        # muzzle across the body, not so low that the right thigh swings into the rifle
        rifle=Placement((0.0, 0.0, 0.0), (-35.0, 20.0, 0.0)),
        joints={**_STANDING, "neck": (0.0, -5.0, 20.0)},
        spine=(-2.0, 8.0, -25.0),
        contacts=(FootFlat("left", (-11.0, 0.0), 0.0), FootFlat("right", (11.0, 0.0), 0.0)),
        look=True,
        shouldered=True,
    ),
    "SLUMP": PostureSpec(
        "SLUMP",
        root=Placement((0.0, 54.0, -4.0), (-15.0, -10.0, 0.0)),
        rifle=Placement((12.0, 62.0, -30.0), (-45.0, 20.0, 0.0)),
        joints={
            **_ON_KNEES,
            "left_hip": (5.0, 30.0, 0.0),
            "right_hip": (0.0, 25.0, 0.0),
            "neck": (10.0, 40.0, 20.0),
            "head": (0.0, 20.0, 0.0),
        },
        spine=(-8.0, 40.0, -10.0),
        contacts=_BOTH_KNEES,
        shouldered=False,
    ),
}


def specs() -> dict[str, PostureSpec]:
    """Every posture spec: the graph's eight and the transitions' in-between keys."""
    return {**SPECS, **IN_BETWEEN}


def build_postures(
    soldier: Figure, rifle: Figure, names: Sequence[str] | None = None
) -> dict[str, KeyPosture]:
    """Solve every posture and in-between key (or only ``names``) for these figures."""
    kin = FigureKinematics(soldier)
    rkin = FigureKinematics(rifle)
    table = specs()
    out: dict[str, KeyPosture] = {}
    for name in names or list(table):
        out[name], _ = solve_posture(table[name], kin, rkin)
    return out
