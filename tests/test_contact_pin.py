"""A limb that slides while it is on the ground is held where it touched down (authoring.contact_pin)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.body_parts import contact_runs
from authoring.contact_pin import pin_contacts
from authoring.quality import CONTACT_HEIGHT_CM, THRESHOLDS
from authoring.quality_frames import FigureSet
from peabody.loader import read_figure
from ttes.paths import FIGURES

N, DOWN, UP = 50, 10, 40  # frames; the feet are on the ground from DOWN to UP
SLIDE_CM = 3.0  # the whole figure drifts this far while they are down


def _feet_nodes(figs: FigureSet, q: np.ndarray, loc: np.ndarray) -> np.ndarray:
    kin = figs.kin["body"]
    nodes, segs = figs.nodes("body")
    hand = np.isin(figs.node_parts("body"), ("left_foot", "right_foot"))
    g = kin.segment_globals(q, loc)
    return np.einsum("fkij,kj->fki", g[:, segs[hand], :3, :], nodes[hand])


@pytest.fixture(scope="module")
def slid() -> tuple[FigureSet, np.ndarray, np.ndarray]:
    """soldier.fig standing in its neutral pose, lowered until its feet touch the ground at frame DOWN,
    drifting SLIDE_CM sideways until UP, then raised again: feet sliding on the ground."""
    figs = FigureSet({"body": read_figure(FIGURES / "soldier.fig")})
    kin = figs.kin["body"]
    q = np.zeros((N, kin.ndof))
    loc = np.repeat(np.eye(4)[None], N, axis=0)
    low = float(_feet_nodes(figs, q[:1], loc[:1])[..., 1].min())
    f = np.arange(N)
    lift = np.clip(np.maximum(DOWN - f, f - UP) / 5.0, 0.0, 1.0) * 3.0  # cm above the ground, eased
    loc[:, 1, 3] = lift - low
    loc[:, 0, 3] = SLIDE_CM * np.clip((f - DOWN) / (UP - DOWN), 0.0, 1.0)
    return figs, q, loc


def _slide(points: np.ndarray) -> float:
    return float(contact_runs(points, CONTACT_HEIGHT_CM).slide.max(initial=0.0))


def test_slid_feet_are_pinned(slid: tuple[FigureSet, np.ndarray, np.ndarray]) -> None:
    figs, q, loc = slid
    kin = figs.kin["body"]
    assert _slide(_feet_nodes(figs, q, loc)) > SLIDE_CM - 0.5  # the constructed clip slides
    pinned, moved = pin_contacts(q, loc, figs, "body")
    assert moved > 1.0
    # standing straight-legged the feet cannot be held exactly (the guard keeps the soles out of the ground)
    assert _slide(_feet_nodes(figs, pinned, loc)) < THRESHOLDS["foot_skate_cm"]
    assert np.all(pinned >= kin.lower - 1e-9) and np.all(pinned <= kin.upper + 1e-9)
    assert np.degrees(np.abs(np.diff(pinned, axis=0))).max() < 20.0  # eased in and out: no joint leaps
    np.testing.assert_allclose(pinned[[0, -1]], q[[0, -1]], atol=1e-6)  # the clip's ends stay as they were


def test_a_stance_is_held_where_it_lifts_off_when_asked() -> None:
    """``plant_offsets(at_lift_off=True)``: a node that slides 3 cm over its stance is held where it lifts
    off (the offset none there), not where it touched down; a stance from the first frame stays anchored
    there (the clip's start posture does not move)."""
    from authoring.slave_feet import plant_offsets

    n = 30
    points = np.zeros((n, 1, 3))
    points[:, 0, 1] = np.where((np.arange(n) >= 5) & (np.arange(n) <= 15), 0.0, 5.0)
    points[:, 0, 0] = 0.3 * np.clip(np.arange(n) - 5, 0, 10)  # slides 3 cm while down
    held = points[:, 0, 0] + plant_offsets(points, at_lift_off=True)[:, 0]
    np.testing.assert_allclose(held[5:16], points[15, 0, 0])  # where it lifts off
    touched = points[:, 0, 0] + plant_offsets(points)[:, 0]
    np.testing.assert_allclose(touched[5:16], points[5, 0, 0])  # the default: where it touched down
    points[:5, 0, 1] = 0.0  # now the stance starts at the first frame: anchored there either way
    first = points[:, 0, 0] + plant_offsets(points, at_lift_off=True)[:, 0]
    np.testing.assert_allclose(first[:16], points[0, 0, 0])


def test_a_held_forearm_neither_slides_nor_pivots_on_the_ground() -> None:
    """``held_turns``: a part that slides and pivots while it lies on the ground (prfire2dead's forearm:
    28 degrees, 5 cm) is held at its place and turn where it touched down in the start posture, from
    ``held_from`` on (the hands still held the rifle before), eased out after it lifts off; its ends stay."""
    from scipy.spatial.transform import Rotation

    from authoring.contact_pin import _held_still, _turned

    n, up, held_from = 40, 20, 3
    f = np.arange(n)
    turn = np.radians(30.0) * np.clip(f / up, 0.0, 1.0)
    site = np.repeat(np.eye(4)[None], n, axis=0)
    site[:, :3, :3] = Rotation.from_euler("y", turn[:, None]).as_matrix()
    site[:, 0, 3] = 0.2 * f  # and slides
    points = np.zeros((n, 1, 3))
    points[:, 0, 1] = np.where(f <= up, 0.0, 5.0)  # on the ground until it lifts off
    move, rot = _held_still(site, points, held_from)
    held = _turned(rot, site[:, :3, :3])
    np.testing.assert_allclose(
        site[held_from : up + 1, 0, 3] + move[held_from : up + 1, 0], site[held_from, 0, 3]
    )
    np.testing.assert_allclose(
        held[held_from : up + 1], np.repeat(site[None, held_from, :3, :3], up + 1 - held_from, 0), atol=1e-9
    )
    assert not move[: held_from + 1].any() and not rot[: held_from + 1].any()  # none before held_from
    assert not move[-1].any() and not rot[-1].any()  # none at the last frame
    assert np.abs(np.diff(move[up:, 0])).max() < 2.0  # eased out after lift-off
