"""A slave turned over on its belly by its master keeps the belly just clear of sliding (crawl2prstow).

Going prone from the crawl the soldier turns 55 degrees on his belly (:mod:`authoring.crawl_prone`). The
master's belly sits 1.4 cm off the ground as it turns, resting but not pressed down (the check's contact
height is 1.25 cm); DI.fig's belly reaches about 1.4 cm lower, so the slave's lay pressed into the ground
and slid 13 cm round with the turn. While the master turns, the slave is raised (its rifle with it) by what
keeps its trunk at :data:`CLEAR_CM`, still within the support height; the lift fades out once the turn is
done, so the slave's belly comes straight down onto the ground where its ``PRONE_STOWED`` has it.
"""

from __future__ import annotations

import numpy as np

from authoring.quality_frames import FigureSet
from authoring.signal_shaping import smooth_above, smoothstep
from authoring.slave_body import part_heights, played_body
from server.motion.channelset import Channelset

CLEAR_CM = 1.4  # cm: the slave's trunk while the master turns on his belly (the master's: 1.4-1.6)
SIGMA_FRAMES = 3.0  # the lift smoothed over the frames, at or above what is needed


def lift_slave_belly(
    master: Channelset, slave: Channelset, figures: FigureSet, until_s: float, fade_s: float
) -> np.ndarray:
    """Raise ``slave`` (every figure channel, in place) so its belly and chest stay :data:`CLEAR_CM` up while
    ``master`` turns on his belly (until ``until_s``), fading out over ``fade_s`` after; returns the lift."""
    q, loc, stype = played_body(slave, figures)
    trunk = [h for p in ("belly", "chest") for h in part_heights(q, loc, figures, stype, p, ("",)).values()]
    t = np.arange(slave.nframes) / slave.fps
    keep = 1.0 - smoothstep((t - until_s) / fade_s)
    need = np.maximum(0.0, CLEAR_CM - np.min(trunk, axis=0))
    lift = keep * smooth_above(need, SIGMA_FRAMES)
    slave.fig_pos[:, :, 1] += lift[:, None].astype(slave.fig_pos.dtype)
    return lift
