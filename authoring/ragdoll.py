"""A MuJoCo ragdoll of soldier.fig and its rifle (authoring only: the ``authoring`` extra's ``mujoco``).

The model mirrors the figure exactly, so a simulated state maps back onto the pose vector:

* one MuJoCo body per segment, nested along the figure's spanning tree (rooted at ``lower_torso``, which gets
  the free joint); each body's frame is the segment's frame, placed on its parent by ``site1 @ inv(site2)``;
* one hinge per rotational DOF, in the figure's DOF order, about the DOF axis expressed in the child segment
  (``site2``'s rotation) through ``site2``'s origin, with the DOF's limits: MuJoCo composes the hinges of a
  body left to right in local frames, exactly like Peabody's ``D = dof[0] @ dof[1] @ ...``;
* **fingers and eyes are frozen** at the start pose (bodies without joints, baked into their parent): they
  carry no weight worth simulating and their many tiny links would force a tiny time step; the recorded clip
  keeps their start angles;
* the geometry of a segment is the **convex hull of its psurf nodes** (a MuJoCo mesh geom): more faithful than
  a fitted capsule, and the lowest hull point is the lowest psurf node, so MuJoCo's ground contact keeps
  exactly the points the quality check measures out of the ground; masses from the hull volumes, scaled to
  :data:`BODY_MASS` (the figure is in centimetres, MuJoCo in metres);
* the ground is a plane on a mocap body (so it can be lowered under a posture that dips into it and rise
  while the body settles); contact is stiff (2 ms ``solref`` at a 1/1200 s step: a fall's impact stays
  within about a centimetre) with high sliding, torsional and rolling friction and MuJoCo's no-slip pass;
  the body collides with itself except for pairs that already touch in the start pose (neighbouring torso
  slices, the shoulder blob and the upper arm, ...);
* the rifle (``AK_47.fig``, one segment) is its own free body, held by weld constraints to both palms until
  :meth:`Ragdoll.release`; it collides with the body except the hands that hold it (the check measures the
  rifle against the same segment hulls). The other parts that touch it in the start pose (a forearm under
  it, the shoulder at the stock, a cheek) are explicit contact pairs, switched on (``pair_gap``) as soon as
  the rifle is clear of each, and at release for those it is still inside of, pushed out softly
  (:data:`SEPARATE_SOLREF`): no let-go rifle passes through a limb. It meets a ground of its own only once
  let go (contact bits: ground 1, rifle's ground 2, body 1|4, rifle 2|4), so a posture that dips the rifle
  into the ground does not shoot it out.

Muscles are joint springs (``jnt_stiffness`` toward ``qpos_spring``) with joint damping, both changeable
while simulating: :mod:`authoring.deaths` holds the posture, then fades the gains to a limp body.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from peabody import quaternion
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.model import Figure

CM = 0.01  # figure units (cm) -> MuJoCo (m)
DENSITY = 1000.0  # kg/m^3, of the hulls; then scaled so the body weighs BODY_MASS
BODY_MASS = 80.0  # kg: the hulls of neighbouring slices overlap, so their volumes add up to too much
RIFLE_MASS = 3.5  # kg, an AK-47 with a magazine
TIMESTEP = 1.0 / 1200.0  # s: twenty steps per 60 fps frame
FROZEN_PREFIXES = (
    "left_thumb",
    "left_index",
    "left_middle",
    "left_ring",
    "left_pinky",
    "right_thumb",
    "right_index",
    "right_middle",
    "right_ring",
    "right_pinky",
    "left_eye",
    "right_eye",
)
GROUND_FRICTION = "3.0 0.1 0.01"  # sliding, torsional, rolling
CONTACT_SOLREF = "0.002 1"
CONTACT_SOLIMP = "0.95 0.99 0.001"
LIMIT_SOLREF = "0.002 1"  # stiff joint limits (MuJoCo's are soft constraints)
CONE, IMPRATIO = "elliptic", 10.0  # elliptic friction cones, friction stiffer than the normal by this
NOSLIP_ITERATIONS = 8  # MuJoCo's no-slip pass: soft friction would let a resting part creep
PALMS = ("right_palm", "left_palm")
WELD_SOLREF = 0.002  # s: the hands' grip on the rifle, as stiff as the step allows
RIFLE_BODY_FRICTION = "0.8 0.005 0.0001"  # a let-go rifle on the body (condim 3: sliding only)
SEPARATE_SOLREF = (0.02, 1.0)  # s: a let-go rifle still inside a neighbour is pushed out this softly
INACTIVE_GAP = 1000.0  # m: a contact pair with this gap never acts (MuJoCo: active below margin - gap)
PARKED = -100.0  # m: where the rifle's ground plane waits while the rifle is held


def _hand(body: str) -> bool:
    from authoring.body_parts import HAND_PARTS, part_of

    return part_of(body) in HAND_PARTS


def frozen(joint: str) -> bool:
    """Joints baked into the model at the start pose (fingers, eyes)."""
    return joint.startswith(FROZEN_PREFIXES)


def mjcf_numbers(v: Iterable[float]) -> str:
    """Numbers as an MJCF attribute's text (the ragdoll's and the lone rifle's models)."""
    return " ".join(f"{float(x):.9g}" for x in v)


def pos_quat(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A rigid transform (cm) as MuJoCo's position (m) and (w, x, y, z) quaternion."""
    return m[:3, 3] * CM, quaternion.from_matrix(m[None, :3, :3])[0]  # both (w, x, y, z)


def from_pos_quat(p: np.ndarray, wxyz: np.ndarray) -> np.ndarray:
    """MuJoCo's position (m) and (w, x, y, z) quaternion as a transform (cm): :func:`pos_quat` undone."""
    return quaternion.to_transform(np.asarray(p)[None] / CM, np.asarray(wxyz)[None])[0]


@dataclass(frozen=True)
class JointMap:
    """Where each simulated DOF of the pose vector lives in ``qpos`` / ``qvel``."""

    dof: np.ndarray  # pose-vector indices of the simulated DOFs
    qpos: np.ndarray  # their qpos addresses
    qvel: np.ndarray  # their dof (qvel) addresses
    jnt: np.ndarray  # their MuJoCo joint ids


class Ragdoll:
    """A compiled MuJoCo model of ``soldier`` (frozen joints at ``pose``) and ``rifle`` at their start."""

    def __init__(
        self,
        soldier: Figure,
        rifle: Figure,
        pose: np.ndarray,
        root: np.ndarray,
        rifle_location: np.ndarray,
    ) -> None:
        import mujoco

        self.mujoco = mujoco
        self.kin = FigureKinematics(soldier)
        self.rkin = FigureKinematics(rifle)
        self.soldier, self.rifle = soldier, rifle
        self.pose0 = np.asarray(pose, dtype=np.float64).copy()
        root = np.asarray(root, dtype=np.float64)
        rifle_location = np.asarray(rifle_location, dtype=np.float64)
        self._root_site = self.kin.figure.root.location  # type: ignore[union-attr]
        self._rifle_site = self.rkin.figure.root.location  # type: ignore[union-attr]
        xml = self._mjcf(exclude=(), pairs=())
        model = mujoco.MjModel.from_xml_string(xml)
        data = mujoco.MjData(model)
        self._set_state(model, data, self.pose0, root, rifle_location)
        mujoco.mj_forward(model, data)
        touching = self._touching_pairs(model, data)
        # the rifle's start-pose neighbours that are not the hands holding it (a forearm, a shoulder, the
        # cheek on the stock): explicit contact pairs, each acting once the rifle is clear of it (held or
        # not: an arm pressed onto a held rifle stops at it), the rest at release (:meth:`release`)
        self.rifle_neighbours = sorted(
            b for pair in touching if "rifle" in pair for b in pair if b != "rifle" and not _hand(b)
        )
        self.xml = self._mjcf(exclude=touching, pairs=self.rifle_neighbours)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        self.map = self._joint_map()
        # the rifle's contact pairs with its neighbours act once it is clear of each (:meth:`step`)
        self._pending: list[int] = list(range(self.model.npair))
        body = np.arange(1, self.model.nbody) != self.model.body("rifle").id
        scale = BODY_MASS / self.model.body_mass[1:][body].sum()
        self.model.body_mass[1:][body] *= scale
        self.model.body_inertia[1:][body] *= scale
        self._set_state(self.model, self.data, self.pose0, root, rifle_location)
        self._weld(root, rifle_location)
        mujoco.mj_forward(self.model, self.data)

    # --- MJCF -----------------------------------------------------------------------------------------------

    def _mjcf(self, exclude: Iterable[tuple[str, str]], pairs: Iterable[str]) -> str:
        kin = self.kin
        fig = self.soldier
        assets: list[str] = []
        children: dict[str, list] = {}
        for step in kin._steps:
            children.setdefault(kin.segment_names[step.parent], []).append(step)
        q = self.pose0

        def hull(name: str, nodes: np.ndarray) -> str:
            assets.append(f'<mesh name="{name}" vertex="{mjcf_numbers((nodes * CM).ravel())}"/>')
            return name

        def geoms(seg: str) -> str:
            ps = fig.segments[seg].psurf
            if ps is None or len(ps.nodes) < 4:
                return ""
            return f'<geom name="{seg}" type="mesh" mesh="{hull(seg, ps.nodes)}" class="body"/>'

        def body(seg: str, rel: np.ndarray, joints: str, depth: int) -> str:
            pad = "  " * depth
            p, quat = pos_quat(rel)
            inner = [
                f'{pad}<body name="{seg}" pos="{mjcf_numbers(p)}" quat="{mjcf_numbers(quat)}">',
                joints,
                geoms(seg),
            ]
            for step in children.get(seg, []):
                child = kin.segment_names[step.child]
                jname = step.joint
                if frozen(jname) or len(step.dofs) == 0:
                    d = np.eye(4)
                    for i in step.dofs:
                        d = d @ kin._dof_matrix(int(i), float(q[i] * kin._sign[i]))
                    inner.append(body(child, step.pre @ d @ step.post, "", depth + 1))
                    continue
                site2 = rigid_inverse(step.post)
                hinge = []
                for k, i in enumerate(step.dofs):
                    axis = site2[:3, :3] @ kin._axes[i]
                    lo, hi = kin.lower[i], kin.upper[i]
                    rng = f' range="{lo:.9g} {hi:.9g}" limited="true"' if np.isfinite([lo, hi]).all() else ""
                    hinge.append(
                        f'<joint name="{jname}:{k}" type="hinge" pos="{mjcf_numbers(site2[:3, 3] * CM)}" '
                        f'axis="{mjcf_numbers(axis)}"{rng}/>'
                    )
                inner.append(body(child, step.pre @ step.post, "".join(hinge), depth + 1))
            inner.append(f"{pad}</body>")
            return "\n".join(x for x in inner if x)

        root_seg = kin.segment_names[kin._root_seg]
        tree = body(root_seg, np.eye(4), '<freejoint name="root"/>', 2)
        rnodes = self.rifle.segments["rifle"].psurf.nodes  # type: ignore[union-attr]
        rifle_mesh = hull("rifle", rnodes)
        ex = "\n".join(f'<exclude body1="{a}" body2="{b}"/>' for a, b in exclude)
        ex += "".join(
            f'\n<pair geom1="rifle" geom2="{b}" condim="3" friction="{RIFLE_BODY_FRICTION}" '
            f'solref="{CONTACT_SOLREF}" solimp="{CONTACT_SOLIMP}" gap="{INACTIVE_GAP}"/>'
            for b in pairs
        )
        return f"""<mujoco model="soldier_ragdoll">
  <compiler angle="radian" boundmass="0.001" boundinertia="1e-7"/>
  <option timestep="{TIMESTEP}" integrator="implicitfast" cone="{CONE}" impratio="{IMPRATIO}"
          noslip_iterations="{NOSLIP_ITERATIONS}"/>
  <size memory="64M"/>
  <default>
    <geom condim="6" friction="{GROUND_FRICTION}" solref="{CONTACT_SOLREF}" solimp="{CONTACT_SOLIMP}"/>
    <default class="body"><geom density="{DENSITY}" contype="5" conaffinity="5"/></default>
    <joint damping="0" armature="0.002" solreflimit="{LIMIT_SOLREF}"
           solimplimit="{CONTACT_SOLIMP}"/>
  </default>
  <asset>
    {"".join(assets)}
  </asset>
  <worldbody>
    <body name="ground" mocap="true">
      <geom name="ground" type="plane" size="0 0 1" contype="1" conaffinity="1"/>
    </body>
    <body name="rifle_ground" mocap="true" pos="0 0 {PARKED}">
      <geom name="rifle_ground" type="plane" size="0 0 1" contype="2" conaffinity="2"/>
    </body>
{tree}
    <body name="rifle">
      <freejoint name="rifle"/>
      <geom name="rifle" type="mesh" mesh="{rifle_mesh}" mass="{RIFLE_MASS}" contype="6" conaffinity="6"/>
    </body>
  </worldbody>
  <contact>
{ex}
  </contact>
  <equality>
    <weld name="grip:right_palm" body1="right_palm" body2="rifle"/>
    <weld name="grip:left_palm" body1="left_palm" body2="rifle"/>
  </equality>
</mujoco>
"""

    # --- state ----------------------------------------------------------------------------------------------

    def _joint_map(self) -> JointMap:
        m = self.model
        dof, qpos, qvel, jnt = [], [], [], []
        for name, sl in self.kin.dof_slices.items():
            if frozen(name):
                continue
            for k, i in enumerate(range(sl.start, sl.stop)):
                j = m.joint(f"{name}:{k}").id
                dof.append(i)
                qpos.append(m.jnt_qposadr[j])
                qvel.append(m.jnt_dofadr[j])
                jnt.append(j)
        return JointMap(*(np.array(v, dtype=np.intp) for v in (dof, qpos, qvel, jnt)))

    def _set_state(self, model, data, pose: np.ndarray, root: np.ndarray, rifle: np.ndarray) -> None:
        mj = self.mujoco
        for name, sl in self.kin.dof_slices.items():
            if frozen(name):
                continue
            for k, i in enumerate(range(sl.start, sl.stop)):
                data.qpos[model.jnt_qposadr[model.joint(f"{name}:{k}").id]] = pose[i]
        for jname, frame in (
            ("root", root @ rigid_inverse(self._root_site)),
            ("rifle", rifle @ rigid_inverse(self._rifle_site)),
        ):
            adr = model.jnt_qposadr[model.joint(jname).id]
            p, quat = pos_quat(to_mj_world(frame))
            data.qpos[adr : adr + 3] = p
            data.qpos[adr + 3 : adr + 7] = quat
        data.qvel[:] = 0.0
        mj.mj_forward(model, data)

    def _touching_pairs(self, model, data) -> list[tuple[str, str]]:
        """Body pairs whose geoms touch or overlap in the start pose (never the ground)."""
        mj = self.mujoco
        pairs: set[tuple[str, str]] = set()
        # a generous margin so near misses that the first fall would jam are excluded too
        model.geom_margin[:] = 0.005
        mj.mj_forward(model, data)
        for c in data.contact[: data.ncon]:
            b1, b2 = model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]
            if {model.body(b1).name, model.body(b2).name} & {"world", "ground", "rifle_ground"}:
                continue
            a, b = sorted((model.body(b1).name, model.body(b2).name))
            pairs.add((a, b))
        model.geom_margin[:] = 0.0
        for palm in PALMS:  # the hands and forearms that hold the rifle never push it away
            pairs.add(tuple(sorted((palm, "rifle"))))  # type: ignore[arg-type]
        return sorted(pairs)

    def _weld(self, root: np.ndarray, rifle: np.ndarray) -> None:
        """Weld each palm to the rifle where it holds it in the start pose."""
        m, d = self.model, self.data
        for palm in PALMS:
            eq = m.equality(f"grip:{palm}")
            gp = self.body_global(palm)
            gr = self.body_global("rifle")
            rel = rigid_inverse(gp) @ gr  # the rifle in the palm's frame
            p, quat = pos_quat(rel)
            eq.data[:3] = 0.0  # anchor on body2 (rifle) at its origin
            eq.data[3:6] = p
            eq.data[6:10] = quat
            eq.data[10] = 1.0
            d.eq_active[eq.id] = 1
        eq_solref = np.array([WELD_SOLREF, 1.0])
        m.eq_solref[:] = eq_solref

    def release(self, push_out: bool = True) -> None:
        """The hands let go of the rifle; the start-pose neighbours it is still inside of push it out, gently
        (:data:`SEPARATE_SOLREF`: at full stiffness they would fling it), or (not ``push_out``) each waits
        until the rifle is clear of it, as while held: pushed out at the let-go, the standing deaths' rifle
        flung the left forearm it lay in and the right hand jumped 12-17 cm in one frame."""
        for palm in PALMS:
            self.data.eq_active[self.model.equality(f"grip:{palm}").id] = 0
        if not push_out:
            return
        for p in self._pending:  # still inside a neighbour: pushed out of it gently
            self.model.pair_solref[p] = SEPARATE_SOLREF
            self.model.pair_gap[p] = 0.0
        self._pending = []

    def _arm_rifle_pairs(self) -> None:
        m, d = self.model, self.data
        still = []
        for p in self._pending:
            if self.mujoco.mj_geomDistance(m, d, m.pair_geom1[p], m.pair_geom2[p], 0.01, None) > 0.0:
                m.pair_gap[p] = 0.0
            else:
                still.append(p)
        self._pending = still

    def rifle_lowest(self) -> float:
        """Height (cm) of the rifle's lowest psurf node."""
        g = self.rifle_location() @ rigid_inverse(self._rifle_site)
        nodes = self.rifle.segments["rifle"].psurf.nodes  # type: ignore[union-attr]
        return float((nodes @ g[1, :3] + g[1, 3]).min())

    def lowest(self) -> float:
        """Height (cm) of the body's lowest psurf node."""
        from authoring.postures import lowest_point

        return float(lowest_point(self.kin, self.pose(), self.root_location()))

    def set_ground(self, height: float) -> None:
        """Put the body's ground plane at ``height`` cm (a posture that dips into the ground starts on a
        ground that far down, which rises to 0 while the body settles: no pop out of it)."""
        self.data.mocap_pos[self.model.body("ground").mocapid[0], 2] = height * CM

    def set_rifle_ground(self, height: float | None) -> None:
        """The rifle's own ground plane at ``height`` cm, or (None) parked out of reach: the rifle meets no
        ground while the hands hold it (the posture places it, a posture may dip it into the ground), and
        a rifle let go inside the ground is raised out of it by this plane rising to 0."""
        z = PARKED if height is None else height * CM
        self.data.mocap_pos[self.model.body("rifle_ground").mocapid[0], 2] = z

    # --- reading back ---------------------------------------------------------------------------------------

    def body_global(self, name: str) -> np.ndarray:
        """A body's frame in figure world coordinates (cm, +Y up)."""
        b = self.data.body(name)
        return from_mj_world(from_pos_quat(b.xpos, b.xquat))

    def pose(self) -> np.ndarray:
        """The current pose vector (frozen DOFs keep their start values), within the joint limits (the
        limit constraints allow a hair beyond)."""
        q = self.pose0.copy()
        q[self.map.dof] = self.data.qpos[self.map.qpos]
        return self.kin.clamp(q)

    def root_location(self) -> np.ndarray:
        return self.body_global(self.kin.segment_names[self.kin._root_seg]) @ self._root_site

    def rifle_location(self) -> np.ndarray:
        return self.body_global("rifle") @ self._rifle_site

    def step(self, n: int = 1) -> None:
        if not self._pending:
            self.mujoco.mj_step(self.model, self.data, nstep=n)
            return
        for _ in range(n):
            self._arm_rifle_pairs()
            self.mujoco.mj_step(self.model, self.data)


# Figures are +Y up, MuJoCo's gravity is -Z: the MuJoCo world is the figure world turned +90 deg about X
# (figure y -> MuJoCo z, figure z -> MuJoCo -y).
_Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


def to_mj_world(m: np.ndarray) -> np.ndarray:
    """A figure-world transform in the MuJoCo world (z up)."""
    return _Y_UP_TO_Z_UP @ m


def from_mj_world(m: np.ndarray) -> np.ndarray:
    """A MuJoCo-world transform in the figure world (y up): :func:`to_mj_world` undone."""
    return _Y_UP_TO_Z_UP.T @ m
