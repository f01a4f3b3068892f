"""Starts that begin at once (issue 16): a clip that a request starts skips its still lead-in.

Several shipped clips open with frames that show nothing new on the wire: kneel -> stand (``ststow2kstow``
played backwards) holds 5 frames (83 ms), a turn to the right 7 (117 ms), getting up from DEAD up to 10.
The server answers a request between ticks with the pose the next tick would show (``Ticking.answer``); a
clip that has not moved by then answers with the old pose, and the first visible change waits a tick or
more. So a clip that a *request* starts begins at its first moving frame: the first whose pose differs from
the clip's first, in the direction played, by at least one quantisation step of the soldier's update table
in some field (a joint DOF, a figure's root position or quaternion component), so that its code on the wire
differs. The frames skipped each differ from the start by less than that step: the figure does not jump,
and the clip ends as much earlier. Clips that chain at the end of another (the next arc of a path, the next
step of a gait) play whole: they are not starts.

Gait starts (a walk, run or crawl off a rest) skip too: their first frame is still (one frame under a step),
so a request sampled at its own time (one that lands while the tick samples, answered in that tick's first
frames; a tick that runs late) showed nothing new and waited for the next tick. Their travel keeps counting
from the first frame (the root offset is not rebased): the root carries what the skipped frame travelled,
so the planted foot stays put (rebased, it slid 0.45 cm more; the stub's scenario measure 0.59 -> 0.64 cm).
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np

from protocol.update_table import JointEntry, UpdateTable
from server.motion.sampling import ClipLibrary
from server.soldier import root_motion
from server.soldier.core import _IDLE, _TRANSITION, ManagerCore
from server.soldier.wire import update_table_for

CM_PER_M = 100.0


def wire_steps(table: UpdateTable) -> tuple[np.ndarray, float, float]:
    """One code of ``table`` in the library's units: per pose DOF (radians; centimetres for a translational
    DOF), the smallest of a figure's root position (cm) and of a quaternion component."""
    lay = table.layout
    kinds = [d.kind for e in table.entries if isinstance(e, JointEntry) for d in e.dofs]
    dof = lay.step[lay.dof_fields] * np.where(np.array(kinds) == "T", CM_PER_M, 1.0)
    pos = float(lay.step[lay.pos_fields].min()) * CM_PER_M if lay.pos_fields.size else np.inf
    quat = float(lay.step[lay.comp_fields].min()) if lay.comp_fields.size else np.inf
    return dof, pos, quat


def lead_in_fractions(
    clips: ClipLibrary, dof_step: np.ndarray, pos_step: float, quat_step: float
) -> np.ndarray:
    """``(nclips, 2)``: the share of each clip (played forwards, backwards) before its first frame that
    differs from its first by a step in some field; 0 for a clip that never does."""
    out = np.zeros((clips.nclips, 2))
    for c in range(clips.nclips):
        a, n = int(clips.clip_start[c]), int(clips.clip_nframes[c])
        if n < 2:
            continue
        joints, figs = clips.joint_data[a : a + n], clips.fig_data[a : a + n]
        for k, (j, f) in enumerate(((joints, figs), (joints[::-1], figs[::-1]))):
            moved = (np.abs(j - j[0]) >= dof_step).any(axis=1)
            moved |= (np.abs(f[..., :3] - f[0, :, :3]) >= pos_step).any(axis=(1, 2))
            moved |= (np.abs(f[..., 3:] - f[0, :, 3:]) >= quat_step).any(axis=(1, 2))
            first = int(np.argmax(moved))
            out[c, k] = first / (n - 1) if moved[first] else 0.0
    return out


class LeadIn(ManagerCore):
    """The skip: per figure set the lead-in of every clip, applied to the clips a request just started."""

    @cached_property
    def _lead_in(self) -> np.ndarray:
        """``(nsets, nclips, 2)`` lead-in shares (forwards, backwards), against each set's update table."""
        lib = self.library
        return np.stack(
            [
                lead_in_fractions(clips, *wire_steps(update_table_for(lib, k + 1, k)))
                for k, clips in enumerate(lib.sets)
            ]
        )

    def _skip_lead_in(self, idx: np.ndarray, t: np.ndarray) -> None:
        """Soldiers ``idx`` took a request at ``t``: those whose posture change, turn or reaction started
        then begin at its first moving frame (start and end earlier by the lead-in, the root offset's
        reference frame with them)."""
        tb = self.table
        if self._settings.every_frame or not len(idx):
            return
        started = (tb.start[idx] == t) & (tb.mode[idx] != _IDLE)
        i = idx[started]
        if not len(i):
            return
        share = self._lead_in[tb.fset[i], tb.clip[i], (tb.direc[i] < 0).astype(np.int64)]
        shift = share * tb.dur[i]
        tb.start[i] -= shift
        tb.end[i] -= shift
        # a gait start's travel keeps counting from its first frame: the root carries what the skipped frame
        # travelled and the planted foot stays where it stood
        root_motion.rebase(tb, self.library, i[tb.mode[i] == _TRANSITION])
        if self._settings.record_clips:
            self._note_skips(dict(zip(i.tolist(), shift.tolist(), strict=True)))

    def _note_skips(self, skipped: dict[int, float]) -> None:
        """Say in each soldier's last recorded clip start what it skipped (they are the newest records)."""
        log = self.clip_log
        for k in range(len(log) - 1, -1, -1):
            if not skipped:
                return
            c = log[k]
            if c.index in skipped:
                log[k] = dataclasses.replace(c, skipped=skipped.pop(c.index))
