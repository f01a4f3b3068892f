"""A let-go rifle recorded again on its own, falling from the hands to the ground (issue 14, ``ststow2dead``).

The ragdoll's fall (:mod:`authoring.deaths`) is chaotic: a death's spec is tuned until its recorded fall
passes the quality check, and any change to the rifle's toss (which the body meets as it leaves the hands
and on the ground) re-rolls the whole fall. ststow2dead's rifle, flung to his left away from a fall straight
ahead, came to rest by his boots as the fall turned him onto his right side; tossed any other way, or let
go later, his thigh skidded 3.6-5.8 cm as he landed or he lay on the rifle. So the body keeps its tuned
fall and the rifle alone is simulated again from the moment the hands let go, where and as fast as it was
then, with a toss of its own: a MuJoCo model of the rifle and the ground only, with the ragdoll's contact
and time step. It does not meet the body; the quality check's ``rifle_in_body_cm`` proves its path clear.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from authoring import ragdoll
from authoring.death_specs import REST_SECONDS, REST_SPEED, TOSS_SECONDS
from peabody.fk import rigid_inverse
from peabody.model import Figure


@dataclass(frozen=True)
class LetGo:
    """The rifle at the moment the hands let go: its location (figure world), its MuJoCo free-joint
    velocity ``(6,)`` and the substeps left in the frame being recorded."""

    location: np.ndarray
    velocity: np.ndarray
    substeps: int


def let_go(doll: ragdoll.Ragdoll, substeps: int) -> LetGo:
    """The ragdoll's rifle as the hands let go of it, ``substeps`` before the frame is recorded."""
    adr = doll.model.jnt_dofadr[doll.model.joint("rifle").id]
    return LetGo(doll.rifle_location(), doll.data.qvel[adr : adr + 6].copy(), substeps)


def mesh_asset(name: str, nodes: np.ndarray) -> str:
    """A MuJoCo mesh asset of a segment's psurf ``nodes`` (cm)."""
    return f'<mesh name="{name}" vertex="{ragdoll.mjcf_numbers((np.asarray(nodes) * ragdoll.CM).ravel())}"/>'


def mjcf(rifle: Figure, assets: str = "", bodies: str = "", contact: str = "", parts: str = "") -> str:
    """The rifle and the ground, with (:mod:`authoring.rifle_settle`) more ``assets``, ``bodies`` in the
    world, ``contact`` pairs and massless geoms ``parts`` on the rifle."""
    nodes = rifle.segments["rifle"].psurf.nodes  # type: ignore[union-attr]
    return f"""<mujoco model="rifle_drop">
  <compiler angle="radian"/>
  <option timestep="{ragdoll.TIMESTEP}" integrator="implicitfast" cone="{ragdoll.CONE}"
          impratio="{ragdoll.IMPRATIO}" noslip_iterations="{ragdoll.NOSLIP_ITERATIONS}"/>
  <default>
    <geom condim="6" friction="{ragdoll.GROUND_FRICTION}" solref="{ragdoll.CONTACT_SOLREF}"
          solimp="{ragdoll.CONTACT_SOLIMP}"/>
  </default>
  <asset>{mesh_asset("rifle", nodes)}{assets}</asset>
  <worldbody>
    <geom name="ground" type="plane" size="0 0 1"/>
    <body name="rifle">
      <freejoint name="rifle"/>
      <geom name="rifle" type="mesh" mesh="rifle" mass="{ragdoll.RIFLE_MASS}"/>{parts}
    </body>{bodies}
  </worldbody>{contact}
</mujoco>
"""


def dropped(rifle: Figure, start: LetGo, toss: np.ndarray, frames: int, fps: float) -> np.ndarray:
    """``(m, 4, 4)`` the rifle's locations (figure world) per frame from the one after the hands let go
    (``start``), flung with ``toss`` (N, figure world) for :data:`TOSS_SECONDS`: at least ``frames``, and
    on until it has lain still for :data:`REST_SECONDS`."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf(rifle))
    data = mujoco.MjData(model)
    site = rifle.root.location  # type: ignore[union-attr]
    p, quat = ragdoll.pos_quat(ragdoll.to_mj_world(start.location @ rigid_inverse(site)))
    data.qpos[:3], data.qpos[3:7] = p, quat
    data.qvel[:] = start.velocity
    push = np.array([toss[0], -toss[2], toss[1]])  # figure (x, y, z) -> MuJoCo (x, -z, y)
    gun = model.body("rifle").id
    steps = round(1.0 / (fps * model.opt.timestep))
    out: list[np.ndarray] = []
    still, t0 = 0, data.time
    todo = start.substeps
    while len(out) < frames or still * steps * model.opt.timestep < REST_SECONDS:
        before = data.xipos[gun].copy()
        for _ in range(todo):
            data.xfrc_applied[gun, :3] = push if data.time - t0 < TOSS_SECONDS else 0.0
            mujoco.mj_step(model, data)
        todo = steps
        out.append(ragdoll.from_mj_world(ragdoll.from_pos_quat(data.xpos[gun], data.xquat[gun])) @ site)
        speed = np.linalg.norm(data.xipos[gun] - before) * fps
        still = still + 1 if speed < REST_SPEED else 0
    return np.array(out)
