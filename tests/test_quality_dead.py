"""The check sees dead and face-down bodies that do not look dead (issue 14): shins straight up while the
chest faces the ground (``feet_up_cm``), and at DEAD a head held up or an arm raised (``rest_head_cm``,
``rest_arm_cm``), on constructed good and bad clips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_quality import FIGURES, N, _clip, _floored, _graph, _lying

from authoring.quality import THRESHOLDS, FigureSet, check_clip, check_library
from peabody.loader import read_figure
from ttes.cli import main


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


def _face_down(figset: FigureSet, knees_deg: float = 0.0):
    """DI lying on his front (turned 180 degrees about the long axis from his back), knees bent this much."""
    poses, body, rifle = _lying(figset)
    flip = np.eye(4)
    flip[1:3, 1:3] = [[-1.0, 0.0], [0.0, -1.0]]
    poses = poses.copy()
    kin = figset.kin["DI.fig"]
    for side in ("left", "right"):
        poses[:, kin.dof_slices[f"{side}_knee"].start] = np.radians(knees_deg)
    return _floored(figset, poses, flip @ body, rifle)


def test_a_face_down_body_with_its_shins_up_fails(figset: FigureSet) -> None:
    """stfire2dead lay face down with both shins straight up, the feet 80 cm over the pelvis, and passed."""
    flat = check_clip(_clip("flat.chset", figset, *_face_down(figset)), figset)
    assert flat["feet_up_cm"] < 0.0 and "feet_up_cm" not in flat["failures"]  # the feet lower than the pelvis
    bent = check_clip(_clip("bent.chset", figset, *_face_down(figset, knees_deg=90.0)), figset)
    assert bent["feet_up_cm"] > 40.0 and "feet_up_cm" in bent["failures"]
    assert bent["feet_up_where"].startswith(("left_foot[", "right_foot["))
    assert THRESHOLDS["feet_up_cm"] == 20.0
    # on his back the chest faces up: shins raised there are another matter (not judged)
    poses, body, rifle = _lying(figset)
    kin = figset.kin["DI.fig"]
    for side in ("left", "right"):
        poses[:, kin.dof_slices[f"{side}_knee"].start] = np.radians(90.0)
    back = check_clip(_clip("back.chset", figset, *_floored(figset, poses, body, rifle)), figset)
    assert back["feet_up_cm"] is None and "feet_up_cm" not in back["failures"]


def test_a_body_that_starts_lying_keeps_its_feet_down(figset: FigureSet) -> None:
    """proneheels-s13's prone deaths lifted both lower legs 13-17 cm as the chest came down (feet_up_cm: 20
    passed it): a man shot while lying has no fall to fling them. Knees bending from 0 to 20 degrees lift
    the feet about 15 cm; lying still passes; the same lift in a clip that starts standing is not judged."""
    kin = figset.kin["DI.fig"]
    poses, body, rifle = _floored(figset, *_face_down(figset), lift=-6.0)  # his toes in: the pelvis down
    lifted = poses.copy()
    for side in ("left", "right"):
        lifted[:, kin.dof_slices[f"{side}_knee"].start] = np.radians(np.linspace(0.0, 20.0, len(poses)))
    still = check_clip(_clip("still.chset", figset, poses, body, rifle), figset)
    assert still["lying_feet_up_cm"] < 1.0 and "lying_feet_up_cm" not in still["failures"]
    kick = check_clip(_clip("kick.chset", figset, lifted, body, rifle), figset)
    assert 6.0 < kick["lying_feet_up_cm"] < 20.0, kick["lying_feet_up_cm"]
    assert "lying_feet_up_cm" in kick["failures"] and "feet_up_cm" not in kick["failures"]
    assert kick["lying_feet_up_where"].startswith(("left_foot[", "right_foot["))
    raised = body.copy()  # the same body held 50 cm up in the first frames: he does not start lying
    raised[:3, 1, 3] += 50.0
    falling = check_clip(_clip("fall.chset", figset, lifted, raised, rifle), figset)
    assert falling.get("lying_feet_up_cm") is None


def test_a_dead_body_lies_slack(tmp_path: Path, figset: FigureSet, capsys) -> None:
    """A head held up (the prone deaths' on a hand, 18 cm) or an arm raised (kfire2dead's forearms pointing
    up) at DEAD fails; a body lying flat passes."""
    lying = _clip("lie.chset", figset, *_lying(figset))
    poses, body, rifle = _lying(figset)
    tilt = np.eye(4)
    tilt[1:3, 1:3] = [[np.cos(0.1), np.sin(0.1)], [-np.sin(0.1), np.cos(0.1)]]  # the head (+Y) up 6 degrees
    propped = _clip("propped.chset", figset, *_floored(figset, poses, tilt @ body, tilt @ rifle))
    poses, body, rifle = _lying(figset)
    poses[:, figset.kin["DI.fig"].dof_slices["right_elbow"].start] = np.radians(90.0)  # forearm straight up
    raised = _clip("raised.chset", figset, poses, body, rifle)
    arcs = [("STAND_STOWED", "DEAD", "lie", True), ("STAND_STOWED", "DEAD@prone", "propped", True)]
    arcs += [("STAND_STOWED", "DEAD@kneel", "raised", True)]
    graph = _graph(tmp_path, figset, {"lie": lying, "propped": propped, "raised": raised}, arcs)
    rows = {r["posture"]: r for r in check_library([graph], FIGURES)["continuity"]}
    dead = rows["DEAD"]
    assert dead["pass"] and dead["rest_head_cm"] < 10.0 and dead["rest_arm_cm"] < 25.0, dead
    head = rows["DEAD@prone"]
    assert head["rest_head_cm"] > 15.0 and "rest_head_cm" in head["failures"]
    assert head["rest_head_where"] == f"propped.chset[{N - 1}] head"
    arm = rows["DEAD@kneel"]
    assert arm["rest_arm_cm"] > 30.0 and arm["failures"] == ["rest_arm_cm"]
    assert arm["rest_arm_where"].endswith("right_hand") and arm["rest_head_cm"] == dead["rest_head_cm"]
    assert "rest_head_cm" not in rows["STAND_STOWED"]  # only DEAD lies slack
    assert main(["author", "check", "--graphs", str(graph)]) == 1
    text = capsys.readouterr().out
    assert "FAIL soldier_low:DEAD@kneel rest_arm_cm = " in text and "raised.chset[" in text
    assert "FAIL soldier_low:DEAD@prone rest_head_cm = " in text


@pytest.mark.parametrize("name", ["stfire2dead", "stfire2dead_low", "stfire2dead_m16_low"])
def test_the_shipped_standing_fire_death_keeps_its_feet_down(name: str) -> None:
    """Issue 14: stfire2dead lay face down at 1.4 s with both shins straight up (feet 81 cm over the pelvis);
    its hips, waist and lower back are damped harder until he is down (authoring.deaths)."""
    from server.motion.cache import load_channelset
    from ttes.paths import CHANNELSETS

    cs = load_channelset(CHANNELSETS / f"{name}.chset.env", use_cache=False)
    types = sorted({c.protofiletype for c in cs.channels})
    row = check_clip(cs, FigureSet.from_dir(FIGURES, types))
    assert row["feet_up_cm"] <= THRESHOLDS["feet_up_cm"], row["feet_up_where"]
