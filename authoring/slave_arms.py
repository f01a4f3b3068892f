"""A dying slave's hands and forearms on the ground stay where they come to rest (issue 14).

:func:`~authoring.slave_ground.rest_limbs` lays the slave's parts at the master's heights frame by frame and
holds each limb part's two sites where it touched down (``slave_ground._plants``); nothing holds the part's
turn about them, and the trunk's settle (the root dropped and rolled onto the ground) moves under it, so
each frame's solve leaves the hand a little otherwise turned: stfire2dead's DI left hand, on the ground
from frame 71 to the end where the master's lies still, rolled to and fro and its nodes slid 4.0 cm (the
right forearm 3.1). Where a death asks for it (:attr:`~authoring.deaths.DeathSpec.slave_arms_pinned`)
the slave's arms are held as the prone masters' forearms are (:func:`authoring.contact_pin.pin_contacts`
with ``held_turns``): each hand and forearm on the ground keeps its place and its turn from the rifle's
release on, where it lies at the stance's end (for a hand resting to the clip's end: its last frame, so
the DEAD rest the trunk stage found is unchanged), the arm with its clavicle carrying it; the move eases
in over the frames before it lands.
"""

from __future__ import annotations

from dataclasses import replace

from authoring.contact_pin import PINS, Pin, pin_contacts
from authoring.death_specs import spec_of
from authoring.quality_frames import FigureSet
from authoring.slave_body import played_body
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset

# the arms' pins: a hand held in its turn too (contact_pin's hand pin holds only its palm's place)
ARM_PINS: tuple[Pin, ...] = tuple(
    replace(p, turns=True) for p in PINS if p.parts[0].endswith(("_hand", "_forearm"))
)


def arms_pinned(master: Channelset) -> bool:
    """Whether this death's slave holds its arms on the ground (``DeathSpec.slave_arms_pinned``)."""
    spec = spec_of(master.name)
    return spec is not None and spec.slave_arms_pinned


def pin_slave_arms(master: Channelset, slave: Channelset, figures: FigureSet) -> float:
    """Hold the dying ``slave``'s hands and forearms on the ground still from its ``release_frame`` on (its
    joint channels, in place; see the module docstring); returns the largest move of a held site (cm), 0
    where the death does not ask for it or the clip keeps its rifle."""
    release = getattr(slave, "release_frame", None)
    if release is None or not arms_pinned(master):
        return 0.0
    q, loc, stype = played_body(slave, figures)
    pose, moved = pin_contacts(
        q, loc, figures, stype, held_turns=True, held_from=release, table=ARM_PINS, head=False
    )
    if moved > 0.0:
        bf = bind_channelset(slave, [figures.figures[stype]]).figures[0]
        slave.joint_data[:, bf.src] = pose[:, bf.dst].astype(slave.joint_data.dtype)
    return moved
