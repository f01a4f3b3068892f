"""prfire2dead's slaves' arms leave PRONE_FIRE late, lifted off the ground with the body (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.death_specs import death_specs
from authoring.quality import THRESHOLDS
from authoring.slave_arms_late import arms_source
from tests.test_shipped_slides import shipped_slides


def test_the_arms_hold_their_start_then_catch_up_at_rest() -> None:
    src = arms_source(5, 19)
    assert np.all(src[:6] == 0.0) and src[-1] == 19.0
    assert np.all(np.diff(src) >= 0.0) and np.diff(src)[-1] < 0.5  # no step back, arriving at rest


def test_only_prfire2dead_asks_for_it() -> None:
    late = {name for name, spec in death_specs().items() if any(spec.slave_arms_late)}
    assert late == {"prfire2dead"}


@pytest.mark.parametrize("clip", ["prfire2dead_low"])
def test_the_slaves_right_forearm_stays_where_it_lies(clip: str) -> None:
    """Before, the DI's right forearm dragged 5.4 cm over frames 0-9 as its arm swung back on the ground."""
    assert shipped_slides(clip)["contact_slides"]["right_forearm"] <= THRESHOLDS["contact_slide_cm"]
