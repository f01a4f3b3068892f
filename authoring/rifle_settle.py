"""A let-go rifle left leaning on the settling body falls again once its support goes (issue 14).

The ragdoll's fall leaves the prone deaths' rifle (prstow2dead, prfire2dead) leaning on his arms, stood on
its magazine or muzzle. The settle after the physics (:mod:`authoring.dead_prone`, then
:mod:`authoring.prone_roll`) lowers his chest and lays his arms anew, kinematically, and left the rifle where
it was: standing in the air, butt 19-36 cm up, for as long as he lies DEAD (review s16). So the rifle alone
is simulated again from the frame it last moved, at rest there: a MuJoCo model of the rifle, the ground and
the body's segment hulls as mocap bodies replaying the recorded frames (each substep between two frames
interpolated), with the ragdoll's contact and time step (:mod:`authoring.rifle_drop`). As the arms go it
tips and falls onto the ground or his body, and comes to rest there; the body moves as recorded, the rifle
does not push it. A hull the rifle already lies in at the start (a hand it was never meant to meet) is left
out of its contacts, so it does not shoot out of it.

The body meets the rifle's pieces (:func:`rifle_parts`), not its convex hull (8070 cm3; the pieces' 3070):
prstow2dead's rifle lay flat on the ground by 0.8 s when his settled left palm came down 2.5 cm clear of its
nodes but 1.5 cm into its hull, between magazine and barrel, and wedged it against the ground; it rocked
there butt-up (overhang 44 cm) to the end. The ground meets the hull, which touches it where the nodes do.
"""

from __future__ import annotations

import numpy as np

from authoring import ragdoll
from authoring.death_specs import REST_SECONDS, REST_SPEED, TOSS_SECONDS
from authoring.rifle_drop import mesh_asset, mjcf
from authoring.transitions import ClipFrames
from peabody import quaternion
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.model import Figure

INSIDE_M = 0.01  # m: a body hull the rifle is this deep in at the start meets it not at all
# m/s: the recorded rifle slower than this from some frame on has been laid where it leans (prstow2dead's,
# leaning on arms the settle had moved 3.5-4 cm away, shook at 0.1 m/s in place: REST_SPEED is 0.03)
SETTLED_SPEED = 0.15
# the segments a rifle falling from the hands that let it go meets not at all (DeathSpec.rifle_refall): the
# arms, flailing as he falls, juggled ststow2dead's over his head and let it fall 0.6 s later
ARMS = ("arm", "palm", "thumb", "index", "middle", "ring", "pinky")
MORE_S = 10.0  # s: the most the rifle falls on past the clip's end (one that never rests: the check sees it)


def resting_from(rifles: np.ndarray, fps: float) -> int:
    """The first frame from which the recorded rifle (its locations, cm) moves no faster than
    :data:`SETTLED_SPEED`: the ragdoll's fall has laid it where it leans."""
    speed = np.linalg.norm(np.diff(rifles[:, :3, 3], axis=0), axis=1) * ragdoll.CM * fps
    fast = np.flatnonzero(speed >= SETTLED_SPEED)
    return int(fast[-1]) + 1 if len(fast) else 0


def rifle_parts(rifle: Figure) -> list[np.ndarray]:
    """The rifle's mesh nodes (cm, its own frame) split into its pieces, its mesh's connected faces (stock,
    grip, receiver, barrel, each bend of the magazine): each convex, where the whole rifle is not."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    psurf = rifle.segments["rifle"].psurf
    assert psurf is not None
    edges = np.array([(a, b) for face in psurf.faces for a, b in zip(face, np.roll(face, 1), strict=True)])
    n = len(psurf.nodes)
    graph = coo_array((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    return [psurf.nodes[label == k] for k in range(count) if (label == k).sum() >= 4]


def _parts_xml(rifle: Figure) -> tuple[str, str, list[str]]:
    """The rifle's pieces (:func:`rifle_parts`) as massless geoms meeting nothing but their contact pairs:
    their mesh assets, the geoms and the geoms' names."""
    parts = rifle_parts(rifle)
    names = [f"rifle_part{k}" for k in range(len(parts))]
    assets = "".join(mesh_asset(name, nodes) for name, nodes in zip(names, parts, strict=True))
    geoms = "".join(
        f'\n      <geom name="{name}" type="mesh" mesh="{name}" mass="0" contype="0" conaffinity="0"/>'
        for name in names
    )
    return assets, geoms, names


def _body_xml(
    soldier: Figure, segments: list[str], paired: list[str], parts: list[str]
) -> tuple[str, str, str]:
    """The body's hulls as mocap bodies (assets, bodies) and the contact pairs of the rifle's ``parts``
    with ``paired``."""
    assets, bodies = [], []
    for seg in segments:
        assets.append(mesh_asset(seg, soldier.segments[seg].psurf.nodes))  # type: ignore[union-attr]
        bodies.append(
            f'\n    <body name="{seg}" mocap="true"><geom name="{seg}" type="mesh" mesh="{seg}" '
            f'contype="0" conaffinity="0"/></body>'
        )
    pairs = "".join(
        f'\n    <pair geom1="{part}" geom2="{seg}" condim="3" friction="{ragdoll.RIFLE_BODY_FRICTION}" '
        f'solref="{ragdoll.CONTACT_SOLREF}" solimp="{ragdoll.CONTACT_SOLIMP}"/>'
        for seg in paired
        for part in parts
    )
    return "".join(assets), "".join(bodies), f"\n  <contact>{pairs}\n  </contact>" if paired else ""


def _mocap(globals_: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment globals ``(nseg, 4, 4)`` (figure world) as MuJoCo mocap positions and quaternions."""
    pq = [ragdoll.pos_quat(ragdoll.to_mj_world(g)) for g in globals_]
    return np.array([p for p, _ in pq]), np.array([q for _, q in pq])


def _between(
    a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray], u: float
) -> tuple[np.ndarray, np.ndarray]:
    """Mocap poses ``u`` of the way from ``a`` to ``b`` (positions linear, quaternions slerped)."""
    return (1.0 - u) * a[0] + u * b[0], quaternion.slerp(a[1], b[1], u)


def _velocity(rifles: np.ndarray, site: np.ndarray, frame: int, fps: float) -> np.ndarray:
    """The recorded rifle's (locations of its root ``site``) MuJoCo free-joint velocity ``(6,)`` (linear
    m/s, world; angular rad/s, its body's frame) over the frame before ``frame``."""
    from scipy.spatial.transform import Rotation

    if frame < 1:
        return np.zeros(6)
    a, b = (ragdoll.to_mj_world(rifles[i] @ rigid_inverse(site)) for i in (frame - 1, frame))
    turn = Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).as_rotvec() * fps
    return np.r_[(b[:3, 3] - a[:3, 3]) * ragdoll.CM * fps, turn]


def settled(
    frames: ClipFrames,
    soldier: Figure,
    rifle: Figure,
    start: int | None = None,
    unmet: tuple[str, ...] = (),
    toss: np.ndarray | None = None,
) -> ClipFrames:
    """``frames`` with the rifle, from ``start`` (None: :func:`resting_from`), falling again among
    the replayed body, as fast as it moved then, until it rests (at least to the clip's end; the body's
    last frame held after it if the rifle takes longer). It meets no segment whose name contains one of
    ``unmet`` (the arms that have just let it go), and is flung by ``toss`` (N, figure world) for
    :data:`TOSS_SECONDS` from ``start``."""
    import mujoco

    start = resting_from(frames.rifles, frames.fps) if start is None else start
    kin = FigureKinematics(soldier)
    segments = [
        s for s in kin.segment_names if (ps := soldier.segments[s].psurf) is not None and len(ps.nodes) >= 4
    ]
    index = [kin.segment_names.index(s) for s in segments]
    seg_globals = kin.segment_globals(frames.poses[start:], frames.roots[start:])[:, index]
    poses = [_mocap(g) for g in seg_globals]

    part_assets, part_geoms, parts = _parts_xml(rifle)

    def build(paired: list[str]):
        assets, bodies, contact = _body_xml(soldier, segments, paired, parts)
        model = mujoco.MjModel.from_xml_string(mjcf(rifle, part_assets + assets, bodies, contact, part_geoms))
        data = mujoco.MjData(model)
        site = rifle.root.location  # type: ignore[union-attr]
        p, quat = ragdoll.pos_quat(ragdoll.to_mj_world(frames.rifles[start] @ rigid_inverse(site)))
        data.qpos[:3], data.qpos[3:7] = p, quat
        data.qvel[:] = _velocity(frames.rifles, site, start, frames.fps)
        data.mocap_pos[:], data.mocap_quat[:] = poses[0]
        mujoco.mj_forward(model, data)
        return model, data

    model, data = build(segments)
    inside = {
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, int(c.geom2))
        for c in data.contact[: data.ncon]
        if c.dist < -INSIDE_M and mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, int(c.geom1)) in parts
    }
    model, data = build([s for s in segments if s not in inside and not any(u in s for u in unmet)])
    gun = model.body("rifle").id
    site = rifle.root.location  # type: ignore[union-attr]
    steps = round(1.0 / (frames.fps * model.opt.timestep))
    push = np.zeros(3) if toss is None else np.array([toss[0], -toss[2], toss[1]])  # figure -> MuJoCo
    out: list[np.ndarray] = []
    still, frame, t0 = 0, 0, data.time
    last = len(poses) - 1 + round(MORE_S * frames.fps)
    while frame < len(poses) - 1 or (still * steps * model.opt.timestep < REST_SECONDS and frame < last):
        before = data.xipos[gun].copy()
        a, b = poses[min(frame, len(poses) - 1)], poses[min(frame + 1, len(poses) - 1)]
        for k in range(steps):
            data.mocap_pos[:], data.mocap_quat[:] = _between(a, b, (k + 1) / steps)
            data.xfrc_applied[gun, :3] = push if data.time - t0 < TOSS_SECONDS else 0.0
            mujoco.mj_step(model, data)
        frame += 1
        out.append(ragdoll.from_mj_world(ragdoll.from_pos_quat(data.xpos[gun], data.xquat[gun])) @ site)
        speed = np.linalg.norm(data.xipos[gun] - before) * frames.fps
        still = still + 1 if speed < REST_SPEED else 0
    n = start + 1 + len(out)
    more = n - len(frames.poses)
    return ClipFrames(
        np.concatenate([frames.poses, np.repeat(frames.poses[-1:], more, axis=0)]),
        np.concatenate([frames.roots, np.repeat(frames.roots[-1:], more, axis=0)]),
        np.concatenate([frames.rifles[: start + 1], np.array(out)]),
        frames.fps,
    )
