"""BVH out and back in (issue 20) through the kept ``bvhio`` library: a soldier's motion for DCC tools.

BVH has no rest rotation, so a BVH joint is the frame *after* a joint's DOFs (the glTF export's joint node):
the root is the root segment (``ROOT <segment>``, position and rotation channels), every other joint is named
as the update table names it and its local transform is ``post(parent) · pre · D(q)`` — constant offset, the
rotation channels carry ``R(post · pre) · R(D(q))`` and a joint with T DOFs gets position channels too. Each
joint's Euler order is the one whose middle angle stays farthest from ±90° over the clip (the root segment of
an upright soldier is pitched 90° in ZXY; Euler angles at that lock do not read back). Axes
are glTF's (+Y up, facing +Z), centimetres. Reading back inverts that: ``D(q) = inv(post · pre) · local`` and
the joint's DOF angles come out of ``D`` by its axes (``authoring.ik.decompose_rotation`` for three).
Only the soldier: BVH holds one skeleton, so the weapon's placement is not written.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from pyglm import glm

with warnings.catch_warnings():  # bvhio imports PyGLM the old way ("import glm": PendingDeprecationWarning)
    warnings.simplefilter("ignore", PendingDeprecationWarning)
    import bvhio

from authoring.gltf_export import PERFORMER_TO_GLTF, Rig, local_transforms
from authoring.ik import decompose_rotation, rotation_log, signed_angle
from peabody import quaternion
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.rotations import axis_angle
from protocol import coords
from protocol.figure import WireFigure, dof_starts
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset

_POSITIONS = ["Xposition", "Yposition", "Zposition"]
_ORDERS = ("ZXY", "XYZ", "YZX", "ZYX", "XZY", "YXZ")  # ZXY first: the usual BVH order, kept on ties


def _gltf_frame() -> np.ndarray:
    x, y, z, w = PERFORMER_TO_GLTF
    c = np.eye(4)
    c[:3, :3] = quaternion.to_matrix(np.array([w, x, y, z]))
    return c


def _pose(m: np.ndarray) -> bvhio.Pose:
    w, x, y, z = quaternion.from_matrix(m[:3, :3])
    t = m[:3, 3] * coords.CM_PER_M
    return bvhio.Pose(glm.vec3(*map(float, t)), glm.quat(float(w), float(x), float(y), float(z)))


def _matrix(pose: bvhio.Pose) -> np.ndarray:
    q = pose.Rotation
    m = np.eye(4)
    m[:3, :3] = quaternion.to_matrix(np.array([q.w, q.x, q.y, q.z], np.float64))
    m[:3, 3] = np.array(pose.Position, np.float64) / coords.CM_PER_M
    return m


def _rest(wf: WireFigure, row: int) -> np.ndarray:
    """``post(parent) · pre``: where a BVH joint's DOFs start, in its BVH parent's frame."""
    p = int(wf.parent[row])
    return (wf.post[p] if p > 0 else np.eye(4)) @ wf.pre[row]


def _moves(rig: Rig, wf: WireFigure, row: int) -> bool:
    e = int(wf.entry[row])
    if e < 0:
        return False
    start = dof_starts(rig.table)[e]
    return bool(rig.translational[start : start + len(wf.joints[e][1])].any())


def _euler_order(rotations: np.ndarray) -> str:
    """Of the six intrinsic orders, the one whose middle angle (``|sin| = |R[first, last]|``) stays furthest
    from gimbal lock over ``rotations`` ``(N, 3, 3)``."""
    axis = {"X": 0, "Y": 1, "Z": 2}
    return min(_ORDERS, key=lambda o: float(np.abs(rotations[:, axis[o[0]], axis[o[2]]]).max()))


def _bvh_locals(rig: Rig, dofs: np.ndarray, placements: list[np.ndarray]) -> np.ndarray:
    """``(N, S, 4, 4)``: per frame each BVH joint's local transform (row 0: the root segment in glTF axes)."""
    wf = rig.wire[0]
    c = _gltf_frame()
    rest = np.array([wf.post[p] if p > 0 else np.eye(4) for p in wf.parent])  # row 0's is replaced below
    out = []
    for i in range(len(dofs)):
        local = local_transforms(rig, dofs[i], [p[i] for p in placements])[0]
        m = rest @ local  # post(parent) · (pre · D)
        m[0] = c @ placements[0][i] @ local[0]
        out.append(m)
    return np.array(out)


def export_bvh(rig: Rig, fps: float, dofs: np.ndarray, placements: list[np.ndarray], out: Path) -> None:
    """Write the soldier's ``dofs`` ``(N, ndof)`` (table order) at ``placements[0]`` ``(N, 4, 4)`` as BVH."""
    wf = rig.wire[0]
    local = _bvh_locals(rig, dofs, placements)
    joints: list[bvhio.BvhJoint] = []
    for row in range(len(wf.segment_names)):
        name = wf.segment_names[0] if row == 0 else rig.joint_names[0][row - 1]
        offset = glm.vec3(*map(float, local[0, row, :3, 3] * coords.CM_PER_M)) if row else None
        j = bvhio.BvhJoint(name, offset)
        rotations = [f"{a}rotation" for a in _euler_order(local[:, row, :3, :3])]
        j.Channels = (_POSITIONS if row == 0 or _moves(rig, wf, row) else []) + rotations
        j.Keyframes = [_pose(m) for m in local[:, row]]
        if row:
            joints[int(wf.parent[row])].Children.append(j)
        joints.append(j)
    out.parent.mkdir(parents=True, exist_ok=True)
    bvhio.writeBvh(str(out), bvhio.BvhContainer(joints[0], len(dofs), 1.0 / fps), percision=9)


def _angles(d: np.ndarray, rot: np.ndarray, axes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A joint's DOF values from its DOF product ``d`` (radians; metres for a T DOF)."""
    if not rot.any():
        return axes @ d[:3, 3]  # T DOFs along orthogonal axes
    if not rot.all():
        raise ValueError("a joint that mixes R and T DOFs is not read back from BVH")
    n = len(rot)
    if n == 1:
        return np.array([float(rotation_log(d[:3, :3]) @ axes[0])])
    if n == 2:
        t1 = float(signed_angle(axes[0], axes[1], d[:3, :3] @ axes[1]))
        return np.array([t1, float(rotation_log(axis_angle(axes[0], -t1) @ d[:3, :3]) @ axes[1])])
    lower = np.where(np.isfinite(lo), lo, -np.inf)
    upper = np.where(np.isfinite(hi), hi, np.inf)
    return decompose_rotation(d, axes, lower=lower, upper=upper)


def import_bvh(path: Path, rig: Rig) -> tuple[float, np.ndarray, np.ndarray]:
    """Read a BVH written by :func:`export_bvh` for ``rig``: fps, the soldier's table-order DOFs
    ``(N, ndof0)``
    and its placement ``(N, 4, 4)`` (Performer)."""
    bvh = bvhio.readAsBvh(str(path))
    wf = rig.wire[0]
    by_name = {j.Name: j for j, _, _ in bvh.Root.layout()}
    starts = dof_starts(rig.table)
    ndof = sum(len(v[1]) for v in wf.joints.values())
    dofs = np.zeros((bvh.FrameCount, ndof))
    c_inv = rigid_inverse(_gltf_frame())
    root = [c_inv @ _matrix(k) @ rigid_inverse(wf.pre[0]) for k in bvh.Root.Keyframes]
    for row in range(1, len(wf.segment_names)):
        e = int(wf.entry[row])
        if e < 0:
            continue
        _, rot, axes, lo, hi = wf.joints[e]
        rest_inv = rigid_inverse(_rest(wf, row))
        for i, key in enumerate(by_name[rig.joint_names[0][row - 1]].Keyframes):
            d = rest_inv @ _matrix(key)
            if wf.reverse[row]:  # walked site2 -> site1: the product of the inverses, reversed
                d = rigid_inverse(d)
            dofs[i, starts[e] : starts[e] + len(rot)] = _angles(d, rot, axes, lo, hi)
    return 1.0 / bvh.FrameTime, dofs, np.array(root)


def bvh_to_channelset(path: Path, rig: Rig, name: str) -> Channelset:
    """A BVH written for ``rig`` (by :func:`export_bvh`, or by a tool that kept its skeleton) as a channelset
    of the soldier: one joint channel per joint with DOFs and a figure channel at its root site."""
    fps, dofs, placements = import_bvh(path, rig)
    fig = rig.figures[0]
    poses = dofs.copy()
    n = poses.shape[1]
    poses[:, rig.translational[:n]] *= coords.CM_PER_M
    locations = coords.transforms_performer_to_jack(placements)
    recording = Recording([fig])
    root = FigureKinematics(fig).root_name
    for pose, location in zip(poses, locations, strict=True):
        recording.append(fig.name, pose, root, location)
    return recording_to_channelset(name, recording, 0, len(poses) - 1, fps)
