"""Another rifle in the same hands: the M16 library's rifle placements, derived from the master clip's AK-47.

Every soldier.fig clip is recorded holding ``AK_47.fig``; an M16 soldier must carry ``M16.fig`` the same way.
So the M16 keeps the AK's orientation in every frame (its barrel along the AK's line: fire postures aim
along -Z exactly as the AK, seed 002) and is slid along the rifle's frame so that its butt plate sits where
the AK's does, in the shoulder pocket (:func:`swap_offset`). The palms are not placed here: the slaving IK
puts them on the M16's own grip and handguard (:func:`authoring.slaving.reslave_channelset`).

The M16 is 11 cm longer in front of the butt and shaped differently underneath, so it can reach the ground
where the AK did not (prone): those frames pitch the muzzle up about the butt by the least angle that
clears the ground (:func:`clear_ground`), smoothed over the clip so the rifle does not twitch, and exact at
its first and last frames (a function of the pose there), so clips meeting at a posture node agree there.

After the channelset's ``release_frame`` the rifle is a free body (a death lets go of it): the M16 follows
the AK's fall with its lowest point at the AK's, so it comes to rest where the AK does rather than on a
magazine it does not have.
"""

from __future__ import annotations

import numpy as np

from authoring.death_specs import spec_of
from authoring.quality import FigureSet
from authoring.signal_shaping import smooth_above
from authoring.slaving import MasterSlavePair, create_channelset_motion, reslave_channelset
from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.binding import protofiletype
from server.motion.channelset import Channelset

GROUND_MARGIN_CM = 0.3  # the lowest rifle point is kept this far above the ground
PITCH_STEP_DEG = 0.1  # resolution of the muzzle-up pitch search
PITCH_MAX_DEG = 45.0
PITCH_SIGMA_FRAMES = 4.0  # Gaussian smoothing of the pitch over a clip
RELEASE_BLEND_S = 0.25  # after letting go, matching the AK's lowest point fades in over this time


def _site(kin: FigureKinematics, name: str) -> np.ndarray:
    return kin.site_globals(np.zeros(0))[kin.site_names.index(name)]


def swap_offset(held: Figure, other: Figure) -> np.ndarray:
    """``(4, 4)``: ``other``'s root frame in ``held``'s root frame — same orientation, butt on butt."""
    hk, ok = FigureKinematics(held), FigureKinematics(other)
    out = np.eye(4)
    out[:3, 3] = _site(hk, "rifle.butt")[:3, 3] - _site(ok, "rifle.butt")[:3, 3]
    return out


def lowest_point(figures: FigureSet, ptype: str, locations: np.ndarray) -> np.ndarray:
    """``(n,)``: the height of a one-segment figure's lowest mesh node at root placements ``(n, 4, 4)``."""
    nodes, _ = figures.nodes(ptype)
    return np.einsum("fj,kj->fk", np.asarray(locations)[..., 1, :], nodes).min(axis=-1)


def pitch_about(locations: np.ndarray, pivot: np.ndarray, degrees: np.ndarray) -> np.ndarray:
    """Root placements ``(n, 4, 4)`` turned about the rifle's own X axis through ``pivot`` (rifle frame):
    positive ``degrees`` raise the muzzle (-Z) towards the rifle's +Y."""
    a = np.radians(np.asarray(degrees, np.float64))
    c, s = np.cos(a), np.sin(a)
    rot = np.zeros((len(a), 4, 4))
    rot[:, 0, 0] = 1.0
    rot[:, 1, 1], rot[:, 1, 2] = c, -s
    rot[:, 2, 1], rot[:, 2, 2] = s, c
    rot[:, 3, 3] = 1.0
    to, back = np.eye(4), np.eye(4)
    to[:3, 3], back[:3, 3] = pivot[:3], -pivot[:3]
    return np.asarray(locations) @ (to @ rot @ back)


def clear_ground(
    figures: FigureSet, ptype: str, locations: np.ndarray, frames: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(placements, pitch_deg)``: the rifle pitched muzzle-up about its butt, in the frames (``frames``:
    a mask, default all) where it would be less than ``GROUND_MARGIN_CM`` above the ground, by the least
    angle that clears it (smoothed; where none does, the angle that gets it highest)."""
    kin = figures.kin[ptype]
    butt = _site(kin, "rifle.butt")[:, 3]
    locs = np.asarray(locations, np.float64)
    need = np.zeros(len(locs))
    low = lowest_point(figures, ptype, locs) < GROUND_MARGIN_CM
    if frames is not None:
        low &= frames
    if low.any():
        steps = np.arange(0.0, PITCH_MAX_DEG + PITCH_STEP_DEG / 2, PITCH_STEP_DEG)
        sub = locs[low]
        heights = np.stack(
            [lowest_point(figures, ptype, pitch_about(sub, butt, np.full(len(sub), a))) for a in steps], -1
        )
        clear = heights >= GROUND_MARGIN_CM
        best = steps[np.argmax(heights, axis=-1)]
        need[low] = np.where(clear.any(-1), steps[np.argmax(clear, axis=-1)], best)
    pitch = smooth_above(need, PITCH_SIGMA_FRAMES)
    return pitch_about(locs, butt, pitch), pitch


def place_swapped_rifle(
    held_locations: np.ndarray,
    held_type: str,
    other_type: str,
    figures: FigureSet,
    release_frame: int | None = None,
    fps: float = 60.0,
) -> np.ndarray:
    """``(n, 4, 4)`` root placements of ``other_type`` (``"M16.fig"``) from those of ``held_type``
    (``"AK_47.fig"``) in a clip: butt on butt, same orientation, clear of the ground. From ``release_frame``
    on (a free body: it may lie on its side, where a pitch would swing it over the ground) its height is
    moved instead: its lowest point goes where the AK's is (on the ground or on the body where the AK
    comes to rest, never into the ground)."""
    held = np.asarray(held_locations, np.float64)
    offset = swap_offset(figures.figures[held_type], figures.figures[other_type])
    frames = np.arange(len(held))
    in_hands = None if release_frame is None else frames < release_frame
    placed, _ = clear_ground(figures, other_type, held @ offset, in_hands)
    if release_frame is None:
        return placed
    r = release_frame
    ak_low = lowest_point(figures, held_type, held[r:])
    m_low = lowest_point(figures, other_type, placed[r:])
    fade = np.minimum(1.0, np.arange(len(ak_low)) / max(1.0, RELEASE_BLEND_S * fps))
    rest = np.maximum(ak_low, GROUND_MARGIN_CM)  # where the AK rests (ground or body), never below ground
    shift = fade * (rest - m_low)
    placed[r:, 1, 3] += np.maximum(shift, GROUND_MARGIN_CM - m_low)
    return placed


def reslave_holding(
    channelset: Channelset,
    pair: MasterSlavePair,
    rifle: Figure,
    name: str,
    figures: FigureSet | None = None,
) -> Channelset:
    """Re-record a soldier.fig channelset for the slave holding ``rifle`` (``M16.fig``) where the master
    holds ``pair.rifle`` (``AK_47.fig``): the rifle placed by :func:`place_swapped_rifle`, the palms put on it
    by the slaving."""
    if pair.rifle is None:
        raise ValueError("the master/slave pair holds no rifle to swap")
    held_type, other_type = protofiletype(pair.rifle), protofiletype(rifle)
    figs = figures or FigureSet({held_type: pair.rifle, other_type: rifle})
    rec = create_channelset_motion(channelset, [pair.rifle])
    held = np.asarray(rec.locations[pair.rifle.name], np.float64)
    placed = place_swapped_rifle(
        held, held_type, other_type, figs, channelset.release_frame, float(channelset.fps)
    )
    spec = spec_of(channelset.name)
    in_place = bool(spec and spec.slave_let_go_in_place)
    return reslave_channelset(channelset, pair, name, rifle, placed, in_place)
