"""Scenario files (timed requests for one soldier) and ``ttes stub --scenario --record``: the parser reads
back what it writes and refuses bad text with the line; a short scenario records one frame per server tick."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from client_stub.stub.scenario import (
    Camera,
    Event,
    Scenario,
    ScenarioError,
    Start,
    format_scenario,
    parse_scenario,
)
from protocol.entity import Appearance, WeaponState

SHIPPED = Path(__file__).resolve().parents[1] / "docs" / "scenarios" / "issue16.scenario"


def test_the_documented_example_parses() -> None:
    s = parse_scenario(
        """
        soldier weapon=M16.fig x=0 y=0 heading=90     # who and where
        camera azimuth=135 distance=5 elevation=8
        end 30
        1.0  speed=1.4
        8.0  turn=90
        12.0 speed=0.4 dir=-90
        14.0 heading=0 posture=KNEEL weapon=FIRING
        """
    )
    assert s.start == Start(weapon="M16.fig", heading=90.0) and s.camera == Camera(135.0, 5.0, 8.0)
    assert s.seconds == 30.0
    assert s.events == (
        Event(1.0, speed=1.4),
        Event(8.0, turn=90.0),
        Event(12.0, speed=0.4, direction=-90.0),
        Event(14.0, heading=0.0, posture=Appearance.KNEEL, weapon=WeaponState.FIRING),
    )
    assert parse_scenario("2 speed=1").seconds == 5.0  # no end: the last event and 3 s


def test_the_shipped_issue16_scenario_parses() -> None:
    s = parse_scenario(SHIPPED.read_text())
    assert s.start.weapon == "M16.fig" and len(s.events) >= 10 and s.seconds >= s.events[-1].time


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("1 speed=fast", 1, "not a number"),
        ("\n1 speed=-1", 2, "outside"),
        ("1 speed=1\n0.5 speed=0", 2, "before the previous"),
        ("1", 1, "what changes"),
        ("1 run=3", 1, "unknown event key"),
        ("1 turn=9 heading=3", 1, "heading and turn"),
        ("1 posture=FLYING", 1, "no Appearance"),
        ("1 speed", 1, "key=value"),
        ("1 speed=1 speed=2", 1, "twice"),
        ("end", 1, "one number"),
        ("soldier weapon=../x.fig", 1, "figure file"),
        ("camera zoom=2", 1, "unknown key"),
        ("camera distance=0", 1, "outside"),
        ("1 speed=nan", 1, "outside"),
    ],
)
def test_bad_lines_are_refused_with_their_number(text: str, line: int, words: str) -> None:
    with pytest.raises(ScenarioError, match=words) as err:
        parse_scenario(text)
    assert err.value.line == line


finite = st.floats(-300.0, 300.0, allow_nan=False)
events = st.builds(
    Event,
    time=st.floats(0.0, 100.0),
    speed=st.none() | st.floats(0.0, 12.0),
    direction=st.none() | finite,
    heading=st.none() | finite,
    posture=st.none() | st.sampled_from(list(Appearance)),
    weapon=st.none() | st.sampled_from(list(WeaponState)),
).filter(
    lambda e: any(getattr(e, k) is not None for k in ("speed", "direction", "heading", "posture", "weapon"))
)
scenarios = st.builds(
    Scenario,
    events=st.lists(events, max_size=8).map(lambda es: tuple(sorted(es, key=lambda e: e.time))),
    start=st.builds(
        Start, weapon=st.sampled_from(["AK_47.fig", "M16.fig"]), x=finite, y=finite, heading=finite
    ),
    camera=st.builds(
        Camera, azimuth=finite, distance=st.floats(0.5, 500.0), elevation=st.floats(-80.0, 80.0)
    ),
    end=st.none() | st.floats(0.0, 3600.0),
)


@given(scenarios)
def test_a_formatted_scenario_reads_back_the_same(s: Scenario) -> None:
    assert parse_scenario(format_scenario(s)) == s


@settings(max_examples=300)
@given(st.text(alphabet=st.sampled_from("0123456789.=- #\nendspeedirtunhgposwamcflKNEELDPYOT"), max_size=80))
def test_any_text_parses_or_is_a_scenario_error(text: str) -> None:
    try:
        s = parse_scenario(text)
    except ScenarioError:
        return
    times = [e.time for e in s.events]
    assert times == sorted(times)


def test_a_short_scenario_records_one_frame_per_server_tick(tmp_path: Path, capsys) -> None:
    """0.2 s at 30 Hz: 7 frames (ticks 0..6), each posed by the tick it shows; the entity walked 0.28 m."""
    pytest.importorskip("pyrender")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    import imageio.v2 as imageio

    from ttes.cli import main

    scenario = tmp_path / "walk.scenario"
    scenario.write_text("end 0.2\n0 speed=1.4\n")
    out = tmp_path / "walk.mp4"
    try:
        code = main(["stub", "--scenario", str(scenario), "--record", str(out), "--size", "64x48",
                     "--artic-dir", str(tmp_path), "--json"])  # fmt: skip
    except Exception as exc:  # no EGL / OpenGL on this machine
        pytest.skip(f"offscreen rendering unavailable: {exc!r}")
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["frames"] == 7 and summary["hz"] == 30.0
    assert summary["last_tick"] >= 6 and summary["soldier_updates"] >= 6  # walking: an update every tick
    assert summary["entity_moved_m"] == pytest.approx(0.28, abs=1e-6)
    frames = [f for f in imageio.get_reader(out)]  # list() would ask len(): inf for ffmpeg
    assert len(frames) == 7 and frames[0].shape[:2] == (48, 64)
    assert Path(summary["sheet"]).is_file()


def test_the_recorded_soldier_keeps_his_feet_planted(tmp_path: Path, capsys) -> None:
    """What the stub draws (server poses and root offset on the dead-reckoned entity): starting to walk and
    walking, no heel or ball slides over 2 cm while it touches (a tick shown a frame late slid 4.7 cm)."""
    pytest.importorskip("pyrender")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    from ttes.cli import main

    scenario = tmp_path / "walk.scenario"
    scenario.write_text("end 3.5\n0.5 speed=1.4\n")
    try:
        out = tmp_path / "w.mp4"
        code = main(["stub", "--scenario", str(scenario), "--record", str(out), "--size", "32x24",
                     "--artic-dir", str(tmp_path), "--json"])  # fmt: skip
    except Exception as exc:  # no EGL / OpenGL on this machine
        pytest.skip(f"offscreen rendering unavailable: {exc!r}")
    assert code == 0
    feet = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["feet"]
    assert [w["event"] for w in feet] == ["start", "speed=1.4"]
    assert all(w["touchdowns"] >= 2 and w["max_slide_cm"] <= 2.0 for w in feet), feet


def test_scenario_and_record_go_together(tmp_path: Path, capsys) -> None:
    from ttes.cli import main

    assert main(["stub", "--scenario", str(SHIPPED)]) == 2
    bad = tmp_path / "bad.scenario"
    bad.write_text("1 speed=fast\n")
    assert main(["stub", "--scenario", str(bad), "--record", str(tmp_path / "x.mp4")]) == 1
    assert "line 1" in capsys.readouterr().err


def test_touchdowns_measure_the_slide_of_a_planted_point() -> None:
    """Heel down for frames 0-9 sliding 0.5 cm a frame, lifted, then down again and still."""
    import numpy as np

    from client_stub.stub.feet import SOLE_SITES, touchdowns, worst_by_window

    n = 30
    pts = np.zeros((n, len(SOLE_SITES), 3))
    pts[:, 1:, 2] = 0.2  # the other points stay up
    pts[:10, 0, 0] = np.arange(10) * 0.005
    pts[10:20, 0, 2] = 0.05  # swing
    pts[20:, 0, 0] = 0.3
    downs = touchdowns(pts, np.zeros(n), hz=10.0)
    assert [(d.start, d.end, d.site, d.slide_cm) for d in downs if d.site == "left_foot.heel"] == [
        (0.0, 0.9, "left_foot.heel", 4.5),
        (2.0, 2.9, "left_foot.heel", 0.0),
    ]
    windows = worst_by_window(downs, [0.0, 1.5])
    assert [w["max_slide_cm"] for w in windows] == [4.5, 0.0]


def test_on_a_slope_the_figure_stands_on_the_ground_under_its_feet(tmp_path: Path, capsys) -> None:
    """Up a 10 % slope (the demo's uphill walk): the figure trails its entity by up to a metre, so the ground
    under the entity is up to 10 cm above the ground under the figure. Placed at the entity's ground height
    the lowest sole point was -3.3..12.6 cm above the ground under it and no touchdown was found while walking
    (the recorder measured the feet against the ground under the entity). Stood on the ground under the foot
    carrying it (client_stub.stub.grounding) and measured against the ground under each sole point:
    -0.6..2.4 cm (flat ground: -0.6..0.5; a rigid flat foot on a 10 % slope has one end 2 cm up), every
    touchdown planted (0.3 cm)."""
    pytest.importorskip("pyrender")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    import trimesh

    from ttes.cli import main

    corners = [[-100.0, -100.0, -10.0], [100.0, -100.0, -10.0], [100.0, 100.0, 10.0], [-100.0, 100.0, 10.0]]
    slope = trimesh.Trimesh(vertices=corners, faces=[[0, 1, 2], [0, 2, 3]])
    terrain = tmp_path / "slope.obj"
    slope.export(terrain)
    scenario = tmp_path / "uphill.scenario"
    scenario.write_text("soldier heading=0\nend 6\n0.5 speed=1.4\n4.0 speed=0\n")
    try:
        code = main(["stub", "--scenario", str(scenario), "--record", str(tmp_path / "u.mp4"), "--json",
                     "--size", "32x24", "--terrain", str(terrain), "--artic-dir", str(tmp_path)])  # fmt: skip
    except Exception as exc:  # no EGL / OpenGL on this machine
        pytest.skip(f"offscreen rendering unavailable: {exc!r}")
    assert code == 0
    feet = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["feet"]
    assert [w["event"] for w in feet] == ["start", "speed=1.4", "speed=0.0"]
    assert all(w["touchdowns"] >= 1 and w["max_slide_cm"] <= 2.0 for w in feet), feet  # standing: the balls
    assert feet[1]["touchdowns"] >= 8  # walking 3.5 s: every heel and ball strike
    lowest = [w["sole_above_ground_cm"] for w in feet]
    assert all(low >= -1.0 and high <= 3.0 for low, high in lowest), lowest
