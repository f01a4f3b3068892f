"""`ttes figure info` and the figure summaries `ttes demo` shows."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ttes.cli import main
from ttes.commands.figure import figure_summaries

DATA = Path(__file__).parent / "data" / "peabody"


def test_info_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["figure", "info", str(DATA / "arm.fig"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out == {
        "name": "arm",
        "file": "arm.fig",
        "segments": 3,
        "joints": 2,
        "dofs": 2,
        "sites": 6,
        "polygons": 18,
        "nodes": 24,
        "edges": 36,
        # base 10 cm, upper 30 cm straight up, lower (4 cm wide, centred) 20 cm bent 30deg: its top corner
        # reaches 10 + 30 + 20 cos(30deg) + 2 sin(30deg) = 58.32 cm; the base box starts at 0
        "height_cm": pytest.approx(58.321, abs=1e-3),
        "root": "base.bottom",
    }


def test_info_text_and_rifle_length(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["figure", "info", str(DATA / "rifle.fig")]) == 0
    text = capsys.readouterr().out
    assert "figure rifle" in text and "length    90.0 cm" in text and "root      gun.grip" in text


def test_info_reports_located_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    bad = tmp_path / "bad.fig"
    bad.write_text("figure f {\n  segment s { psurf = 3; }\n}\n")
    assert main(["figure", "info", str(bad)]) == 1
    assert f"{bad}:2:23: expected a string or a name" in capsys.readouterr().err


def test_figure_summaries_of_a_folder(tmp_path: Path) -> None:
    summaries = figure_summaries(DATA)
    assert [s["file"] for s in summaries] == ["arm.fig", "rifle.fig", "slider.fig"]
    assert summaries[2]["polygons"] == 0 and summaries[2]["height_cm"] == 0.0
    assert figure_summaries(tmp_path / "missing") == []
