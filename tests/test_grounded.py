"""A falling body that hovers a little is lowered onto the ground (authoring/grounded.py, issue 14):
kstow2dead's soldier rode 2.2-2.7 cm up on his foot's edge (frames 40-52), its DI slave 4.6 cm."""

from __future__ import annotations

import numpy as np

from authoring.grounded import CLEAR_CM, GROUNDED_CM, PELVIS, drop, pelvis_down
from authoring.quality import LIFT_OFF_CM
from authoring.quality_support import SUPPORT_CM, longest_unsupported


def _hover(peak: float, n: int = 60, first: int = 20, frames: int = 16) -> np.ndarray:
    """The lowest node's height: on the ground, rising to ``peak`` cm over ``frames`` from ``first`` and
    back (a half sine), on the ground again."""
    t = np.clip((np.arange(n) - first) / frames, 0.0, 1.0)
    return 0.3 + (peak - 0.3) * np.sin(np.pi * t)


def test_a_body_hovering_on_its_foot_s_edge_is_lowered_until_supported() -> None:
    """Hovering 2.7 cm (the soldier) or 4.6 cm (the DI slave), it is unsupported for 0.15-0.3 s; lowered
    by :func:`drop`, it keeps a node within the check's 2 cm in every frame, comes no lower than
    :data:`CLEAR_CM` where it was higher, comes down no faster than it rose and is not moved where it
    touched the ground."""
    for peak in (2.7, 4.6):
        lowest = _hover(peak)
        assert longest_unsupported(lowest[:, None])[1] - longest_unsupported(lowest[:, None])[0] > 3
        down = drop(lowest)
        after = lowest - down
        assert (after <= max(GROUNDED_CM, SUPPORT_CM) + 1e-9).all()
        assert longest_unsupported(after[:, None]) == (0, 0)
        assert (after >= np.minimum(lowest, CLEAR_CM) - 1e-9).all() and (down >= 0.0).all()
        assert np.abs(np.diff(down)).max() <= np.abs(np.diff(lowest)).max()
        assert (down[lowest <= CLEAR_CM] == 0.0).all()


def test_a_body_on_the_ground_is_not_moved() -> None:
    assert not drop(np.full(30, 0.5)).any()
    assert not drop(np.full(30, GROUNDED_CM)).any()


def test_a_hover_after_the_pelvis_is_down_is_left_as_it_is() -> None:
    """kstow2dead's DI slaves hovered twice: off the knee (frames 33-49) and rolling onto their back after
    the pelvis was down (68-82); lowered there too, their pelvis then rose 5.7 cm (trunk_rise_cm limit 2).
    With ``until`` (the pelvis-down frame) the first is lowered, the second left alone."""
    lowest = np.maximum(_hover(4.6, n=100, first=10), _hover(6.9, n=100, first=60))
    down = drop(lowest, until=50)
    assert longest_unsupported((lowest - down)[:50, None]) == (0, 0)
    assert not down[50:].any()
    assert np.array_equal(down[:45], drop(lowest)[:45])


def test_a_pelvis_is_down_where_the_check_s_legs_rise_starts() -> None:
    """The window ends where ``legs_rise_cm`` starts: the pelvis' lowest node within PELVIS_NEAR_CM (10 cm)
    of where it finally lies."""
    pelvis = np.array([43.0, 40.0, 30.0, 20.0, 15.9, 12.0, 6.0, 9.0, 7.0, 6.0])
    assert pelvis_down({PELVIS: pelvis, "left_foot": np.zeros(10)}) == 4


def test_only_these_deaths_slaves_are_lowered_alone() -> None:
    """``DeathSpec.slave_grounded`` lowers the slaves where they hover (crawl2dead's DI floated 2-3 cm for
    0.10 s after its solved belly was lifted out of the ground; ststow2dead's and stfire2dead's DI/M16 hung
    2-7 cm up as they fell forward), not the master: his clip, recorded with ``grounded`` unset, is the
    same, and no other death's slaves change; stfire2dead's alone keep the hover's end in the air."""
    from authoring.deaths import DEATHS

    alone = [d for d in DEATHS if d.slave_grounded]
    assert [d.name for d in alone] == ["ststow2dead", "stfire2dead", "crawl2dead"]
    assert not any(d.grounded for d in alone)
    assert [d.name for d in DEATHS if d.slave_grounded_leave] == ["stfire2dead"]


def test_a_fall_left_in_the_air_at_its_end_is_lowered_at_its_start_only() -> None:
    """stfire2dead's DI slaves hover 4 frames (62-65) as they push off their toes and reach for the ground
    with their hands; lowered whole, a hand 2.5 cm up came down two frames early and slid 4.29 cm. With
    ``leave`` 3 only the hover's first frame comes down (the check allows 3 in the air), and no part off
    the ground elsewhere comes within the check's lift-off height: the hand lands where and when it did."""
    toes = np.r_[np.full(8, 0.5), 1.6, 1.96, 3.34, 5.9, 8.7, 9.5, np.full(6, 10.0)]
    hand = np.r_[np.full(10, 30.0), 20.0, 12.0, 7.2, 2.52, np.full(6, 0.9)]
    parts = np.stack([toes, hand])
    lowest = parts.min(axis=0)
    assert longest_unsupported(lowest[:, None]) == (10, 14)  # 4 frames: 0.067 s
    down = drop(lowest, leave=3, parts=parts)
    a, b = longest_unsupported((lowest - down)[:, None])
    assert b - a == 3 and not down[14:].any()
    assert (lowest - down >= np.minimum(lowest, CLEAR_CM) - 1e-9).all()
    off = parts > LIFT_OFF_CM
    off[:, 9:11] = False  # the hover's first frames (above GROUNDED_CM from frame 9), lowered
    assert ((parts - down)[off] > LIFT_OFF_CM).all()  # the reaching hand not put down a frame early
    whole = drop(lowest)  # lowered whole: the hand comes within the lift-off height before it landed
    assert (hand - whole)[13] <= LIFT_OFF_CM
