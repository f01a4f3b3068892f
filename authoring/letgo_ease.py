"""The arms eased off the grip after the physics (issue 14: the let-go pop).

As the ragdoll's hands let go of the rifle (:meth:`authoring.ragdoll.Ragdoll.release`), the welds that held
the arms against springs already aimed at the slump are dropped in one step: ststow2dead's arms turn 5-16
degrees in the one frame after (left wrist 16.2, right shoulder 7.2), its right hand jumps 15 cm and the check
scores a 5.04 m/s pop (:mod:`authoring.quality_pops`). Eased in the physics instead
(:attr:`DeathSpec.letgo_blend`, :attr:`DeathSpec.letgo_fingers`), the chaotic fall re-rolls: he landed curled
on his side, pelvis 18 cm up.

So, after the physics, the arms' joints from the release frame on go on as they went while held (their last
held frame's pace), turning into the recorded fall over :attr:`DeathSpec.letgo_eased` frames (a smoothstep):
the arms' turn is spread over those frames, and the body, the legs and the fall as a whole stay as recorded.
"""

from __future__ import annotations

import numpy as np

from authoring.signal_shaping import smoothstep
from authoring.transitions import ClipFrames
from peabody.fk import FigureKinematics

ARM_JOINTS = ("clavicle", "shoulder", "elbow", "wrist")  # the joints the grip's welds held


def arm_dofs(kin: FigureKinematics) -> np.ndarray:
    """The pose vector's indices of both arms' :data:`ARM_JOINTS`."""
    s = [np.arange(kin.ndof)[sl] for j, sl in kin.dof_slices.items() if j.endswith(ARM_JOINTS)]
    return np.concatenate(s) if s else np.zeros(0, dtype=np.intp)


def eased_letgo(frames: ClipFrames, kin: FigureKinematics, release: int, span: int) -> ClipFrames:
    """``frames`` with the arms' joints eased off the grip: from the ``release`` frame (the last one held)
    they keep its pace and turn into the recorded angles over ``span`` frames."""
    n = frames.nframes
    if span <= 0 or not 0 < release < n - 1:
        return frames
    dofs = arm_dofs(kin)
    q = frames.poses.astype(np.float64, copy=True)
    k = np.arange(1, min(span, n - 1 - release) + 1)
    held = q[release, dofs] + k[:, None] * (q[release, dofs] - q[release - 1, dofs])
    w = smoothstep(k / span)[:, None]
    t = release + k
    q[t[:, None], dofs] = held + w * (q[t[:, None], dofs] - held)
    q[t] = kin.clamp(q[t])
    return ClipFrames(q.astype(frames.poses.dtype), frames.roots, frames.rifles, frames.fps)
