"""glTF 2.0 export (issue 20): the .glb read back by pygltflib has the update table's names in the FIGURE
message's tree, its node world transforms are Peabody's FK to 1 mm (neutral pose and every stored frame of a
channelset), and the Khronos validator finds no error in it (skipped where node/npm are missing)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

pygltflib = pytest.importorskip("pygltflib")

from npm_support import npm_dir  # noqa: E402

from authoring.gltf_export import (  # noqa: E402
    ROOT_NODE,
    Rig,
    export_channelset,
    export_figures,
    export_posture_graph,
    segment_node_name,
)
from peabody import quaternion  # noqa: E402
from peabody.fk import FigureKinematics  # noqa: E402
from peabody.loader import read_figure  # noqa: E402
from protocol import coords  # noqa: E402
from protocol.update_table import JointEntry  # noqa: E402
from server.config import DEFAULT_DATA_DIR  # noqa: E402
from server.motion.binding import bind_channelset  # noqa: E402
from server.motion.cache import load_channelset  # noqa: E402
from server.motion.posture_change import load_posture_graph  # noqa: E402

FIGURES = DEFAULT_DATA_DIR / "figures"
WALK = DEFAULT_DATA_DIR / "channelsets" / "bwalk_cycle_l_low.chset.env"
TOOLS = Path(__file__).parent / "tools"
MM = 1e-3


def _trs(node: pygltflib.Node, t: list[float] | None = None, r: list[float] | None = None) -> np.ndarray:
    m = np.eye(4)
    x, y, z, w = r or node.rotation or [0.0, 0.0, 0.0, 1.0]
    m[:3, :3] = quaternion.to_matrix(np.array([w, x, y, z]))
    m[:3, 3] = t or node.translation or [0.0, 0.0, 0.0]
    return m


def _worlds(gltf: pygltflib.GLTF2, frame: int | None = None) -> dict[str, np.ndarray]:
    """Every node's world transform by name, optionally with the first animation's keyframe ``frame`` set."""
    over: dict[tuple[int, str], list[float]] = {}
    if frame is not None:
        anim = gltf.animations[0]
        for ch in anim.channels:
            values = _floats(gltf, anim.samplers[ch.sampler].output)
            over[(ch.target.node, ch.target.path)] = [float(v) for v in values[frame]]
    out: dict[str, np.ndarray] = {}

    def walk(k: int, parent: np.ndarray) -> None:
        node = gltf.nodes[k]
        g = parent @ _trs(node, over.get((k, "translation")), over.get((k, "rotation")))
        assert node.name not in out, f"node name {node.name!r} twice"
        out[node.name] = g
        for c in node.children:
            walk(c, g)

    for k in gltf.scenes[gltf.scene].nodes:
        walk(k, np.eye(4))
    return out


def _floats(gltf: pygltflib.GLTF2, accessor: int) -> np.ndarray:
    acc = gltf.accessors[accessor]
    view = gltf.bufferViews[acc.bufferView]
    blob = gltf.binary_blob()
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
    data = np.frombuffer(blob, np.float32, acc.count * width, view.byteOffset + (acc.byteOffset or 0))
    return data.reshape(acc.count, width)


def _to_gltf(g_jack: np.ndarray) -> np.ndarray:
    """Jack world (cm, +Y up, facing -Z) -> glTF world (m, +Y up, facing +Z), through Performer's axes."""
    c = np.eye(4)
    c[:3, :3] = [[-1, 0, 0], [0, 0, 1], [0, 1, 0]]
    return c @ coords.transforms_jack_to_performer(g_jack)


def _assert_close(got: np.ndarray, want: np.ndarray, what: str) -> None:
    err = np.linalg.norm(got[:3, 3] - want[:3, 3])
    assert err < MM, f"{what}: {err * 1000:.3f} mm off"
    assert np.abs(got[:3, :3] - want[:3, :3]).max() < 1e-4, f"{what}: rotation differs"


@pytest.fixture(scope="module")
def soldier_glb(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Rig]:
    out = tmp_path_factory.mktemp("gltf") / "di.glb"
    rig = export_figures([read_figure(FIGURES / "DI.fig"), read_figure(FIGURES / "AK_47.fig")], out)
    return out, rig


@pytest.fixture(scope="module")
def walk_glb(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("gltf") / "walk.glb"
    export_channelset(WALK, FIGURES, gltf=out)
    return out


def test_nodes_are_named_as_the_update_table_and_nest_as_the_figure_message(
    soldier_glb: tuple[Path, Rig],
) -> None:
    path, rig = soldier_glb
    gltf = pygltflib.GLTF2().load(str(path))
    by_name = {n.name: k for k, n in enumerate(gltf.nodes)}
    root = gltf.nodes[gltf.scenes[0].nodes[0]]
    assert root.name == ROOT_NODE
    assert [gltf.nodes[c].name for c in root.children] == ["soldier", "rifle"]
    for e in rig.table.entries:
        if isinstance(e, JointEntry):
            joint = gltf.nodes[by_name[e.name]]
            assert len(joint.children) == 1, e.name  # the joint's one child: the segment it moves
    knee = gltf.nodes[by_name["left_knee"]]
    assert gltf.nodes[knee.children[0]].name == "left_lower_leg.segment"
    assert gltf.nodes[by_name["left_lower_leg.segment"]].mesh is not None
    rifle = gltf.nodes[by_name["rifle"]]
    assert all(gltf.nodes[c].name.startswith("AK_47.") for c in rifle.children)
    sites = [f"{s.segment.name}.{s.name}" for s in rig.figures[0].sites()]
    assert len(sites) > 100 and all(gltf.nodes[by_name[s]].mesh is None for s in sites)


def test_neutral_pose_node_worlds_are_peabody_fk(soldier_glb: tuple[Path, Rig]) -> None:
    path, rig = soldier_glb
    worlds = _worlds(pygltflib.GLTF2().load(str(path)))
    checked = 0
    for k, fig in enumerate(rig.figures):
        prefix = "" if k == 0 else f"{fig.name}."
        kin = FigureKinematics(fig)
        pose = kin.neutral_pose()
        for name, g in zip(kin.segment_names, kin.segment_globals(pose), strict=True):
            _assert_close(worlds[segment_node_name(prefix, name)], _to_gltf(g), name)
            checked += 1
        for name, g in zip(kin.site_names, kin.site_globals(pose), strict=True):
            _assert_close(worlds[prefix + name], _to_gltf(g), name)
            checked += 1
    assert checked > 150


def test_every_mesh_has_unit_normals_pointing_out_of_its_segment(soldier_glb: tuple[Path, Rig]) -> None:
    """Viewers shade a mesh without normals flat: every primitive carries one unit NORMAL per vertex, and
    on the body's segments they point away from the segment's middle (the psurfs' winding is outward)."""
    gltf = pygltflib.GLTF2().load(str(soldier_glb[0]))
    outward = []
    for mesh in gltf.meshes:
        for prim in mesh.primitives:
            assert prim.attributes.NORMAL is not None, mesh.name
            pos = _floats(gltf, prim.attributes.POSITION)
            nrm = _floats(gltf, prim.attributes.NORMAL)
            assert nrm.shape == pos.shape
            np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-5)
            if not mesh.name.startswith("AK_47."):
                outward.append(np.mean(np.einsum("ij,ij->i", nrm, pos - pos.mean(axis=0)) > 0))
    assert len(outward) > 10 and min(outward) > 0.7


def test_channelset_animation_keyframes_are_fk_of_its_frames(walk_glb: Path) -> None:
    gltf = pygltflib.GLTF2().load(str(walk_glb))
    cs = load_channelset(WALK)
    figures = [read_figure(FIGURES / "DI.fig"), read_figure(FIGURES / "AK_47.fig")]
    bound = bind_channelset(cs, figures)
    anim = gltf.animations[0]
    times = _floats(gltf, anim.samplers[0].input)[:, 0]
    assert len(times) == cs.nframes and times[-1] == pytest.approx(cs.duration)
    for frame in (0, cs.nframes // 3, cs.nframes - 1):
        worlds = _worlds(gltf, frame)
        sample = bound.sample(float(frame), interpolate=False)
        for k, fig in enumerate(figures):
            kin = FigureKinematics(fig)
            pose = sample.poses[fig.name].astype(np.float64)
            place = sample.placements[fig.name]
            assert place is not None
            location = kin.location_for_site_global(place.root, place.matrix(), pose)
            prefix = "" if k == 0 else f"{fig.name}."
            globals_ = kin.site_globals(pose, root_location=location)
            for name, g in zip(kin.site_names, globals_, strict=True):
                _assert_close(worlds[prefix + name], _to_gltf(g), f"frame {frame} {name}")


def test_khronos_validator_finds_no_error(
    soldier_glb: tuple[Path, Rig], walk_glb: Path, tmp_path: Path
) -> None:
    where = npm_dir("gltf-validator")
    if where is None:
        pytest.skip("node/npm or the gltf-validator package is not available")
    crawl = tmp_path / "crawl.glb"
    export_posture_graph(DEFAULT_DATA_DIR / "posture_graphs" / "soldier_crawl.graph", FIGURES, crawl)
    env = {**os.environ, "NODE_PATH": str(where / "node_modules")}
    script = TOOLS / "validate_gltf.js"
    run = subprocess.run(
        ["node", str(script), str(soldier_glb[0]), str(walk_glb), str(crawl)],
        env=env,
        capture_output=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stderr.decode()
    for report in json.loads(run.stdout):
        issues = report["issues"]
        errors = [m for m in issues["messages"] if m["severity"] == 0]
        assert issues["numErrors"] == 0, errors[:5]
        assert issues["numWarnings"] == 0, issues["messages"][:5]


def test_a_posture_graph_is_one_animation_per_channelset_with_its_arcs(tmp_path: Path) -> None:
    graph = DEFAULT_DATA_DIR / "posture_graphs" / "soldier_crawl.graph"
    out = tmp_path / "crawl.glb"
    rig, n = export_posture_graph(graph, FIGURES, out)
    loaded = load_posture_graph(graph)
    gltf = pygltflib.GLTF2().load(str(out))
    assert n == len(gltf.animations) == len(loaded.channelsets) == 2
    for token, (anim, cs) in enumerate(zip(gltf.animations, loaded.channelsets, strict=True)):
        assert anim.name == cs.name
        want = [[a.start, a.end, a.direction] for a in loaded.graph.arcs if a.channelset == token]
        assert anim.extras["arcs"] == want and want
        assert gltf.accessors[anim.samplers[0].input].count == cs.nframes
    # the last frame of the second clip, set from its keys, is FK (the soldier's root segment and left palm)
    frame = loaded.channelsets[1].nframes - 1
    gltf.animations = gltf.animations[1:]
    worlds = _worlds(gltf, frame)
    fig = rig.figures[0]
    kin = FigureKinematics(fig)
    s = bind_channelset(loaded.channelsets[1], [fig]).sample(float(frame), interpolate=False)
    pose, place = s.poses[fig.name].astype(np.float64), s.placements[fig.name]
    assert place is not None
    location = kin.location_for_site_global(place.root, place.matrix(), pose)
    for name in ("lower_torso.proximal", "left_palm.grip"):
        g = kin.site_globals(pose, root_location=location)[kin.site_names.index(name)]
        _assert_close(worlds[name], _to_gltf(g), name)


def test_the_commands_write_the_files_and_say_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from ttes.cli import main

    glb = tmp_path / "di.glb"
    assert (
        main(["figure", "export", str(FIGURES / "DI.fig"), str(FIGURES / "AK_47.fig"), "--gltf", str(glb)])
        == 0
    )
    assert glb.stat().st_size > 10_000 and "soldier, rifle" in capsys.readouterr().out
    assert main(["channelset", "export", str(WALK)]) == 2  # neither --gltf nor --bvh
    assert "--gltf" in capsys.readouterr().err
    bvh, back = tmp_path / "walk.bvh", tmp_path / "back.chset.env"
    assert main(["channelset", "export", str(WALK), "--bvh", str(bvh), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 37
    assert main(["channelset", "import-bvh", str(bvh), str(back), "--figure", str(FIGURES / "DI.fig")]) == 0
    assert load_channelset(back, use_cache=False).nframes == 37
    assert "37 frames at 60 fps" in capsys.readouterr().out
    crawl = DEFAULT_DATA_DIR / "posture_graphs" / "soldier_crawl.graph"
    assert main(["graph", "export", str(crawl), "--gltf", str(tmp_path / "crawl.glb"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["animations"] == 2
