"""A prone dying slave's belly slides less while the trunk turns on it (issue 14).

DI's belly is flatter than soldier.fig's: as prfire2dead's master rocks on his belly, his lowest nodes roll
(none slides over 1.1 cm), while the DI slave's one lowest belly node, 0.6-1 cm up, swings 3.8 cm and back
as its root moves 2.5 cm over the pelvis (frames 25-96). Where the death asks (:attr:`~authoring.death_specs
.DeathSpec.slave_belly_held`, a share), over that node's run on the ground (as the check judges it, after
the release) the slave's root moves back by that share of the node's move from where it lies at the run's
end (the DEAD rest kept) or start, eased in and out over :data:`EASE_FRAMES`. Only a share: the pelvis,
thighs and feet ride with the root (all of it: the pelvis slid 3.85 cm, a thigh 3.94). Held by the spine
instead (waist and belly joints), the chest turned 14 degrees and dragged the right forearm 13.8 cm.
"""

from __future__ import annotations

import numpy as np

from authoring.body_parts import contact_runs
from authoring.death_specs import spec_of
from authoring.quality import CONTACT_HEIGHT_CM, LIFT_OFF_CM
from authoring.quality_frames import FigureSet
from authoring.slave_body import played_body
from authoring.slave_feet import part_points
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

EASE_FRAMES = 6  # the hold eases in and out over this many frames (0.1 s)


def held_weights(n: int, first: int, last: int) -> np.ndarray:
    """Per frame how far the hold applies: all of ``first..last``, eased either side (:data:`EASE_FRAMES`)."""
    f = np.arange(n)
    u = np.clip(np.minimum(1.0 - (first - f) / EASE_FRAMES, 1.0 - (f - last) / EASE_FRAMES), 0.0, 1.0)
    u[first : last + 1] = 1.0
    return u * u * (3.0 - 2.0 * u)


def hold_slave_belly(master: Channelset, slave: Channelset, figures: FigureSet) -> np.ndarray:
    """Move the dying ``slave``'s body (its figure channel, in place) back by the death's share of its
    sliding belly node's move (see the module docstring); returns the move ``(n, 2)`` (cm, X and Z)."""
    spec = spec_of(master.name)
    release = getattr(slave, "release_frame", None)
    moved = np.zeros((slave.nframes, 2))
    if spec is None or not spec.slave_belly_held or release is None:
        return moved
    pose, loc, stype = played_body(slave, figures)
    pts = part_points(pose, loc, figures, stype, ("belly",))
    runs = contact_runs(pts, CONTACT_HEIGHT_CM, LIFT_OFF_CM)
    late = runs.last > release
    if not late.any():
        return moved
    i = int(np.flatnonzero(late)[np.argmax(runs.slide[late])])
    node, first, last = int(runs.node[i]), max(int(runs.first[i]), release), int(runs.last[i])
    anchor = last if last == len(pose) - 1 else first
    xz = pts[:, node][:, [0, 2]]
    moved = -spec.slave_belly_held * held_weights(len(pose), first, last)[:, None] * (xz - xz[anchor])
    bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
    chan = next(c for c in slave.figure_channels() if c.column == bf.figure_channel)
    slave.fig_pos[:, chan.column, 0] += moved[:, 0].astype(slave.fig_pos.dtype)
    slave.fig_pos[:, chan.column, 2] += moved[:, 1].astype(slave.fig_pos.dtype)
    return moved
