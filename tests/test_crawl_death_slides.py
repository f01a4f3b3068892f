"""Whose slide is it: crawl2dead's master or the slaving's (issue 14)?

The check judges every figure's clip alone, so a part dragged along the ground in a DI or M16 slave may be
the soldier.fig master's own drag carried over, or one the slaving adds. A slave drags a part no further
than its master drags the same part (or the check's limit, where his is under it): a slave part over that
is the slaving's. crawl2dead's DI right forearm (8.3 cm) and M16 right upper arm (10.0 cm) are: the master's
lie still (1.7 and 1.8 cm); both are dragged out sideways at 1.3-1.7 cm up (inside ``LIFT_OFF_CM``) over
frames 125-131, as :func:`authoring.slave_ground.rest_limbs` lets the master's arm go where he lifts it, and
hover 0.1 s at frames 161-166 once its fourth trunk pass has put the belly 3.5 cm into the ground and
:func:`authoring.build.lift_off_ground` lifted the whole body out, its lift smoothed behind the belly
coming back up by itself. The master's own thighs and left knee dragged 3.1-3.3 cm in his physics (frames
36-72, as the legs roll out) and in the settle (left thigh, frames 129-161) until session 20
(``DeathSpec.legs_lift_off``, ``legs_lift``, ``legs_eased``): 2.8 cm at most. Since the slaves' arms are held
where his go once he lifts them (``DeathSpec.slave_arms_follow``: DI 8.3 -> 6.5 cm, M16 10.0 -> 6.7, now the
left forearm, still put out sideways as it lifts) and the slaves are lowered where they hover
(``slave_grounded``: no hover)."""

from __future__ import annotations

import pytest

from authoring.quality import THRESHOLDS
from tests.known_faults import known_faults
from tests.test_shipped_slides import shipped_slides

MASTER = "crawl2dead"
SLAVES = ("crawl2dead_low", "crawl2dead_m16_low")
SLAVING_SLIDES = {
    "crawl2dead_low": "left forearm dragged 6.5 cm at frames 0-132 (belly 3.7, right forearm 3.7) "
    "(slave_ground.rest_limbs puts it out sideways as his lifts, frames 127-133)",
    "crawl2dead_m16_low": "left forearm dragged 6.7 cm at frames 15-132, right upper arm 5.2 "
    "(slave_ground.rest_limbs, as his arms lift, frames 127-133)",
}


def slaving_drags(slave: str, master: str = MASTER) -> dict[str, tuple[float, float]]:
    """Per part the ``slave`` clip drags further than both the check's limit and ``master``'s same part:
    ``(slave cm, master cm)``."""
    mine, his = shipped_slides(slave)["contact_slides"], shipped_slides(master)["contact_slides"]
    limit = THRESHOLDS["contact_slide_cm"]
    return {
        part: (cm, his.get(part, 0.0))
        for part, cm in mine.items()
        if not part.endswith("_foot") and cm > max(limit, his.get(part, 0.0))
    }


@pytest.mark.parametrize("slave", known_faults(SLAVES, SLAVING_SLIDES))
def test_a_slave_drags_no_part_further_than_its_master(slave: str) -> None:
    assert slaving_drags(slave) == {}
