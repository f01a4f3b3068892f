"""A slaved clip's body figure, as every slaving stage reads and writes it: played, its parts' heights, the
joints that move a site, and a solved pose written back into the channelset.

The stages (:mod:`~authoring.slave_contacts`, :mod:`~authoring.slave_ground`, :mod:`~authoring.slave_rest`,
...) each solve one thing on the same played frames; they share these so each measures a part as the quality
check does and writes its result the same way.
"""

from __future__ import annotations

import numpy as np

from authoring.postures import SIDES
from authoring.quality_frames import FigureSet, play
from peabody import quaternion
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset


def played_body(cs: Channelset, figures: FigureSet) -> tuple[np.ndarray, np.ndarray, str]:
    """A clip's body figure played: poses, root globals and its file type (the figure with most DOFs)."""
    f = play(cs, figures)
    ptype = max(f.poses, key=lambda k: figures.kin[k].ndof)
    return f.poses[ptype], f.locations[ptype], ptype


def part_heights(
    poses: np.ndarray,
    locations: np.ndarray,
    figures: FigureSet,
    ptype: str,
    part: str = "kneecap",
    sides: tuple[str, ...] = SIDES,
) -> dict[str, np.ndarray]:
    """Per side, the height (cm) of the lowest node of ``{side}_{part}`` (as the quality check names body
    parts: ``kneecap``, ``foot``; ``sides=("",)``: a part with no side, ``belly``) in every frame ``(n,)``."""
    kin = figures.kin[ptype]
    nodes, segs = figures.nodes(ptype)
    parts = figures.node_parts(ptype)
    out = {}
    g = kin.segment_globals(poses, locations)[..., 1, :]  # (n, nseg, 4): the rows giving world y
    for side in sides:
        sel = parts == (f"{side}_{part}" if side else part)
        if sel.any():
            out[side] = np.einsum("fkj,kj->fk", g[:, segs[sel]], nodes[sel]).min(axis=1)
    return out


def joint_chain(site: str) -> tuple[str, ...]:
    """The joints that move ``site``: the whole arm or leg from the clavicle or hip, the neck for the head."""
    seg = site.split(".", 1)[0]
    side = seg.split("_", 1)[0]
    if seg.endswith(("arm", "palm")):
        return tuple(f"{side}_{j}" for j in ("clavicle", "shoulder", "elbow", "wrist"))
    if seg.endswith(("leg", "foot", "toes")):
        return tuple(f"{side}_{j}" for j in ("hip", "knee", "ankle", "toes"))
    if seg == "lower_torso":
        return ()  # the pelvis moves with the root alone
    if seg.endswith("_torso"):
        return ("waist", "belly", "upper_spine")[: 1 if seg == "middle_torso" else 3]
    return ("neck", "head")


def heights_of(
    poses: np.ndarray, locs: np.ndarray, figures: FigureSet, ptype: str, parts: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """Per part of ``parts``, its lowest node's height (cm) in every frame."""
    out: dict[str, np.ndarray] = {}
    for part in parts:
        side, _, rest = part.partition("_")
        found = (
            part_heights(poses, locs, figures, ptype, rest, (side,))
            if side in SIDES
            else part_heights(poses, locs, figures, ptype, part, ("",))
        )
        for h in found.values():
            out[part] = h
    return out


def write_pose(
    slave: Channelset, figures: FigureSet, stype: str, pose: np.ndarray, moved: np.ndarray
) -> None:
    """``pose`` into ``slave``'s joint channels; its body's figure channel moved by ``moved`` ``(n, 4, 4)``
    (world)."""
    bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
    slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    chan = next(c for c in slave.figure_channels() if c.column == bf.figure_channel)
    placed = moved @ slave.transforms(chan)
    slave.fig_pos[:, chan.column] = placed[:, :3, 3].astype(slave.fig_pos.dtype)
    slave.fig_quat[:, chan.column] = quaternion.from_matrix(placed[:, :3, :3]).astype(slave.fig_quat.dtype)
