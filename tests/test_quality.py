"""Quality checks of the motion library (``ttes author check``) on constructed good and bad clips, and the
contact sheet (``ttes author contact-sheet``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from server.authoring import ik
from server.authoring.quality import FigureSet, check_clip, check_library, foot_skate
from server.motion.channelset import Channelset
from server.motion.channelset_file import save_channelset
from server.motion.posture_graph import Arc, PostureGraph, write_posture_graph
from server.motion.recording import Recording, recording_to_channelset
from server.peabody.loader import read_figure
from ttes.cli import main

FIGURES = Path(__file__).resolve().parents[1] / "figures"
N = 31


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


@pytest.fixture(scope="module")
def holding(figset: FigureSet) -> tuple[np.ndarray, np.ndarray]:
    """A DI pose holding the rifle (palms on grip and handguard) and the rifle's location."""
    kin = figset.kin["DI.fig"]
    rifle = figset.figures["AK_47.fig"]
    loc = np.eye(4)
    loc[:3, 3] = (8.0, 108.0, -32.0)
    grip = (loc @ rifle.site("rifle.grip").location)[:3, 3]
    guard = (loc @ rifle.site("rifle.handguard").location)[:3, 3]
    goals = [ik.Goal("right_palm.palmcenter", grip), ik.Goal("left_palm.palmcenter", guard)]
    q, report = ik.solve(kin, kin.neutral_pose(), goals, iterations=200)
    assert report.max_position_error < 0.05
    return q, loc


def _clip(name: str, figset: FigureSet, poses: np.ndarray, body: np.ndarray, rifle: np.ndarray) -> Channelset:
    di, ak = figset.figures["DI.fig"], figset.figures["AK_47.fig"]
    rec = Recording([di, ak])
    for k in range(len(poses)):
        rec.append("DI", poses[k], "lower_torso.proximal", body[k])
        rec.append("AK_47", np.zeros(0), "rifle.proximal", rifle[k])
    return recording_to_channelset(name, rec, 0, len(poses) - 1, 60.0)


def _standing(figset: FigureSet, holding, n: int = N):
    q, loc = holding
    di = figset.figures["DI.fig"]
    return np.tile(q, (n, 1)), np.tile(di.location, (n, 1, 1)), np.tile(loc, (n, 1, 1))


def test_a_good_clip_passes(figset: FigureSet, holding) -> None:
    row = check_clip(_clip("stand.chset", figset, *_standing(figset, holding)), figset)
    assert row["pass"], row["failures"]
    assert row["foot_skate_cm"] < 0.01
    assert row["palm_rifle_cm"] < 0.05
    assert row["joint_limit_violations"] == 0
    assert row["stance_phases"] >= 6  # heel, ball and toe tip of both feet
    assert row["ground_penetration_cm"] < 1.0


def test_foot_skate_is_measured_in_stance_and_in_the_world_frame(figset: FigureSet, holding) -> None:
    poses, body, rifle = _standing(figset, holding)
    slide = np.linspace(0.0, 10.0, N)
    body[:, 0, 3] += slide
    rifle[:, 0, 3] += slide
    row = check_clip(_clip("slide.chset", figset, poses, body, rifle), figset)
    assert row["foot_skate_cm"] == pytest.approx(10.0, abs=0.05)
    assert "foot_skate_cm" in row["failures"] and not row["pass"]
    # in place locomotion: the planted foot drifts back at the ground speed; adding the entity's motion back
    # (forward = -Z) shows a foot that does not slide
    poses, body, rifle = _standing(figset, holding)
    speed = 60.0  # cm/s
    back = speed * np.arange(N) / 60.0
    body[:, 2, 3] += back
    rifle[:, 2, 3] += back
    cs = _clip("walk_cycle_l.chset", figset, poses, body, rifle)
    cs.ground_speed = speed  # type: ignore[attr-defined]
    cs.stride_length = 70.0  # type: ignore[attr-defined]
    loco = check_clip(cs, figset, locomotion=True)
    assert loco["foot_skate_cm"] < 0.01 and loco["pass"], loco["failures"]
    assert loco["cadence"] == pytest.approx(speed / 70.0, abs=1e-4)
    static = check_clip(cs, figset)  # the same clip judged as a static clip slides 30 cm
    assert static["foot_skate_cm"] == pytest.approx(30.0, abs=0.05)
    del cs.ground_speed  # type: ignore[attr-defined]
    missing = check_clip(cs, figset, locomotion=True)
    assert "locomotion_recorded" in missing["failures"]


def test_foot_skate_ignores_swinging_feet() -> None:
    n = 60
    pts = np.zeros((n, 1, 3))
    pts[:, 0, 0] = np.linspace(0, 100, n)  # fast along x ...
    pts[:, 0, 1] = 10.0  # ... but 10 cm up: a swing, not a stance
    assert foot_skate(pts, 60.0) == (0.0, 0)
    pts[:, 0, 1] = 0.0  # on the ground, sliding fast: still counted (flat on the ground)
    skate, phases = foot_skate(pts, 60.0)
    assert skate == pytest.approx(100.0) and phases == 1


def test_ground_penetration(figset: FigureSet, holding) -> None:
    poses, body, rifle = _standing(figset, holding)
    base = check_clip(_clip("a.chset", figset, poses, body, rifle), figset)["ground_penetration_cm"]
    body[:, 1, 3] -= 4.0
    row = check_clip(_clip("sunk.chset", figset, poses, body, rifle), figset)
    assert base == 0.0  # the soles rest on the ground (within a millimetre above it)
    assert row["ground_penetration_cm"] == pytest.approx(4.0, abs=0.1)
    assert row["lowest_segment"] in ("left_foot", "right_foot", "left_toes", "right_toes")
    assert "ground_penetration_cm" in row["failures"]


def test_palms_off_the_rifle(figset: FigureSet, holding) -> None:
    poses, body, rifle = _standing(figset, holding)
    rifle[N // 2 :, 0, 3] += 3.0
    row = check_clip(_clip("drop.chset", figset, poses, body, rifle), figset)
    assert row["palm_rifle_cm"] == pytest.approx(3.0, abs=0.05)
    assert row["right_palm_rifle_cm"] == pytest.approx(3.0, abs=0.05)
    assert "palm_rifle_cm" in row["failures"]


def test_joint_limit_violations_and_pops(figset: FigureSet, holding) -> None:
    kin = figset.kin["DI.fig"]
    poses, body, rifle = _standing(figset, holding)
    poses[3:8, kin.dof_slices["left_knee"]] = -0.1  # hyperextended knee
    poses[20:, kin.dof_slices["neck"].start + 1] += np.radians(30.0)  # a 30 degree pop
    row = check_clip(_clip("bad.chset", figset, poses, body, rifle), figset)
    assert row["joint_limit_violations"] == 5
    assert row["violating_joints"] == ["left_knee"]
    assert row["max_frame_jump_deg"] == pytest.approx(30.0, abs=1e-3)
    assert set(row["failures"]) >= {"joint_limit_violations", "max_frame_jump_deg"}


def _library(tmp_path: Path, figset: FigureSet, holding, gap_deg: float) -> Path:
    """A two-arc graph A -> B -> C; the second clip starts ``gap_deg`` away from where the first ends."""
    kin = figset.kin["DI.fig"]
    poses, body, rifle = _standing(figset, holding)
    first = poses.copy()
    first[:, kin.dof_slices["neck"].start + 1] += np.linspace(0.0, 0.2, N)  # nod
    second = np.tile(first[-1], (N, 1))
    second[:, kin.dof_slices["neck"].start] += np.radians(gap_deg) + np.linspace(0.0, 0.1, N)
    save_channelset(_clip("a2b.chset", figset, first, body, rifle), tmp_path / "a2b.chset.env")
    save_channelset(_clip("b2c.chset", figset, second, body, rifle), tmp_path / "b2c.chset.env")
    graph = PostureGraph(
        ["A", "B", "C"],
        ["a2b.chset.env", "b2c.chset.env"],
        [Arc("A", "B", 0, True, -1), Arc("B", "A", 0, False, -1), Arc("B", "C", 1, True, -1)],
    )
    path = tmp_path / "soldier_low.graph"
    write_posture_graph(graph, path)
    return path


def test_check_library_continuity_and_cli(tmp_path: Path, figset: FigureSet, holding, capsys) -> None:
    good_dir, bad_dir = tmp_path / "good", tmp_path / "bad"
    good_dir.mkdir()
    bad_dir.mkdir()
    good = _library(good_dir, figset, holding, 0.0)
    bad = _library(bad_dir, figset, holding, 2.0)
    result = check_library([good], FIGURES)
    assert result["summary"]["pass"], result["summary"]
    assert [c["name"] for c in result["clips"]] == ["a2b.chset", "b2c.chset"]
    by_node = {r["posture"]: r for r in result["continuity"]}
    assert by_node["B"]["endpoints"] == 3 and by_node["B"]["continuity_deg"] < 1e-3
    result = check_library([bad], FIGURES)
    row = next(r for r in result["continuity"] if r["posture"] == "B")
    assert row["continuity_deg"] == pytest.approx(2.0, abs=1e-3)
    assert not row["pass"] and not result["summary"]["pass"]
    assert result["summary"]["thresholds"]["continuity_deg"]["where"] == "soldier_low:B"
    # the CLI: one JSON object, exit status 1 when a threshold fails
    assert main(["author", "check", "--graphs", str(good), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["summary"]["pass"] and len(out["clips"]) == 2
    assert main(["author", "check", "--graphs", str(bad)]) == 1
    text = capsys.readouterr().out
    assert "FAIL" in text and "continuity_deg" in text
    assert main(["author", "check", "--graphs"]) == 2  # nothing to check
    assert main(["author", "check", "--graphs", str(tmp_path / "missing.graph")]) == 2


def test_contact_sheet(tmp_path: Path, figset: FigureSet, holding, capsys) -> None:
    from PIL import Image

    from server.authoring.contact_sheet import ContactSheetError, library_sheet_inputs, render_contact_sheet

    graph = _library(tmp_path, figset, holding, 0.0)
    postures, clips, types = library_sheet_inputs([graph], "DI.fig")
    assert [p.label for p in postures] == ["A", "B", "C"]
    assert [c.label for c in clips] == ["a2b.chset.env", "b2c.chset.env"]
    assert types == ["AK_47.fig", "DI.fig"]
    out = tmp_path / "sheet.png"
    try:
        info = render_contact_sheet(
            [FIGURES / t for t in types], clips, out, postures=postures, frames_per_clip=3, tile=64
        )
    except ContactSheetError as exc:  # pragma: no cover - machines without offscreen OpenGL
        pytest.skip(str(exc))
    assert info["tiles"] == 3 + 2 * 3
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape == (info["height"], info["width"], 3)
    tile = img[-64:, 170:234]  # the first frame of the last clip
    assert (np.abs(tile.astype(int) - [236, 238, 242]).sum(axis=2) > 60).mean() > 0.05  # something drawn
    assert main(["author", "contact-sheet", "--graphs", str(graph), "--out", str(tmp_path / "c.png"),
                 "--frames", "2", "--tile", "48", "--json"]) == 0  # fmt: skip
    assert json.loads(capsys.readouterr().out)["clips"] == ["a2b.chset.env", "b2c.chset.env"]
    assert main(["author", "contact-sheet", "--graphs", str(graph), "--out", str(tmp_path / "d.png"),
                 "--figure", "soldier"]) == 2  # fmt: skip
