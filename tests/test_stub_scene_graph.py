"""The stub's run-time scene graph (Figures 13, 14) against Peabody forward kinematics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from client_stub.stub.scene_graph import ENTITY_NODE, Crowd, EntityLayout, FigureGraph
from client_stub.stub.tips import parse_tips
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from peabody.model import Environment, Figure
from peabody.tips import format_tips
from protocol import coords

FIGURES = Path(__file__).resolve().parent.parent / "figures"


def _graph(fig: Figure) -> FigureGraph:
    env = Environment()
    env.add_figure(fig)
    return FigureGraph(parse_tips(format_tips(env)).figures[0])


@pytest.fixture(scope="module")
def di() -> tuple[Figure, FigureKinematics, FigureGraph]:
    fig = read_figure(FIGURES / "DI.fig")
    return fig, FigureKinematics(fig), _graph(fig)


@pytest.fixture(scope="module")
def rerooted() -> tuple[Figure, FigureKinematics, FigureGraph]:
    """DI rooted at the right heel: the traversal walks the leg joints backwards (reverse flag)."""
    fig = read_figure(FIGURES / "DI.fig")
    heel = FigureKinematics(fig).site_global("right_foot.heel")
    fig.root = fig.site("right_foot.heel")
    fig.location = heel
    return fig, FigureKinematics(fig), _graph(fig)


def _segment_of_node(fig: Figure, graph: FigureGraph) -> dict[int, str]:
    """Joint node k -> the segment it carries: the side of the joint away from the root."""
    fk = FigureKinematics(fig)
    side_of_root = {fk.root_name.partition(".")[0]}
    out: dict[int, str] = {}
    pending = list(fig.joints.values())
    while pending:  # grow the tree outwards from the root segment
        rest = []
        for j in pending:
            a, b = j.site1.segment.name, j.site2.segment.name
            if a in side_of_root or b in side_of_root:
                far = b if a in side_of_root else a
                side_of_root.add(far)
                out[graph.joint_names.index(j.name)] = far
            else:
                rest.append(j)
        pending = rest
    return out


def _check_fk(fig: Figure, fk: FigureKinematics, graph: FigureGraph, q: np.ndarray) -> float:
    """Max difference between scene-graph world matrices and Peabody FK (converted to Performer)."""
    layout = EntityLayout([graph])
    crowd = Crowd(layout, len(q))
    rows = np.arange(len(q))
    crowd.active[:] = True
    qp = q.copy()
    qp[:, ~graph.dof_rot] /= 100.0  # translational DOFs travel in metres
    crowd.set_dofs(rows, qp)
    world = crowd.world(rows)
    expected = coords.transforms_jack_to_performer(fk.segment_globals(q))
    names = fk.segment_names
    err = np.abs(world[:, layout.figure_nodes[0]] - expected[:, names.index(fig.root.segment.name)]).max()
    for k, seg in _segment_of_node(fig, graph).items():
        err = max(err, np.abs(world[:, layout.joint_nodes[k]] - expected[:, names.index(seg)]).max())
    return float(err)


def test_pose_order_is_the_peabody_pose_vector(di) -> None:
    fig, fk, graph = di
    assert graph.joint_names == list(fig.joints)
    assert graph.ndof == fk.ndof == 50
    assert all(graph.dof_slices[n] == fk.dof_slices[n] for n in fig.joints)


@settings(max_examples=40)
@given(arrays(np.float64, (3, 50), elements=st.floats(-3.0, 3.0)))
def test_joint_matrices_equal_peabody_fk_for_random_poses(di, q: np.ndarray) -> None:
    fig, fk, graph = di
    assert _check_fk(fig, fk, graph, q) < 1e-9


def test_reversed_joints_equal_peabody_fk(rerooted) -> None:
    fig, fk, graph = rerooted
    tips_joints = {j.name: j for j, _, _ in parse_tips(format_tips(_env(fig))).figures[0].walk()}
    assert tips_joints["right_ankle"].reverse and not tips_joints["left_ankle"].reverse
    rng = np.random.default_rng(5)
    q = rng.uniform(-1.5, 1.5, (16, fk.ndof))
    assert _check_fk(fig, fk, graph, q) < 1e-9


def _env(fig: Figure) -> Environment:
    env = Environment()
    env.add_figure(fig)
    return env


def test_entity_and_figure_dcs_compose_as_figure_13(di) -> None:
    _, fk, graph = di
    layout = EntityLayout([graph])
    crowd = Crowd(layout, 2)
    rows = np.array([0, 1])
    crowd.active[:] = True
    q = np.random.default_rng(1).uniform(-1, 1, (2, fk.ndof))
    q[:, ~graph.dof_rot] = 0.0
    crowd.set_dofs(rows, q)
    # the wire's figure entry: the root site's placement in the soldier's frame (metres, Performer axes)
    turn = coords.heading_transform(np.array([30.0, 0.0]), np.zeros((2, 3)))[:, :3, :3]
    placement = coords.pose7_to_transform(
        np.array([[0.1, 0.2, 0.9], [0.0, 0.0, 0.3]]), coords.matrix_to_quat(turn)
    )
    crowd.set_placements(rows, placement[:, None])
    entity = coords.heading_transform(
        np.array([45.0, 200.0]), np.array([[10.0, 20.0, 1.5], [-3.0, 4.0, 0.2]])
    )
    crowd.set_entity(rows, entity)
    world = crowd.world(rows)
    np.testing.assert_allclose(world[:, ENTITY_NODE], entity)
    np.testing.assert_allclose(world[:, layout.figure_nodes[0]], entity @ placement @ graph.root_inverse)
    # Jack's location for the same placement: Peabody FK under it gives the same joints
    location = coords.transforms_performer_to_jack(placement)
    for i in range(2):
        g = coords.transforms_jack_to_performer(fk.segment_globals(q[i], root_location=location[i]))
        head = fk.segment_names.index("bottom_head")
        node = layout.joint_nodes[graph.joint_names.index("head")]
        np.testing.assert_allclose(world[i, node], entity[i] @ g[head], atol=1e-9)


def test_layout_has_one_joint_node_per_joint_and_an_indexed_array(di) -> None:
    _, _, graph = di
    rifle = _graph(read_figure(FIGURES / "AK_47.fig"))
    layout = EntityLayout([graph, rifle])
    assert layout.names[0] == "Entity Position DCS"
    assert [layout.names[i] for i in layout.figure_nodes] == ["Figure DCS DI", "Figure DCS AK_47"]
    assert [layout.names[i] for i in layout.joint_nodes] == [f"Joint DCS DI.{n}" for n in graph.joint_names]
    assert layout.parent[layout.figure_nodes].tolist() == [ENTITY_NODE, ENTITY_NODE]
    # every segment with geometry hangs under exactly one node; the root segment under the Figure DCS
    assert len(layout.geometry) == sum(1 for g, _ in graph.segments if g is not None) + 1
    assert layout.geometry[0][1] == layout.figure_nodes[0]
    text = layout.describe()
    assert text.splitlines()[0] == "Entity Position DCS" and "  Figure DCS AK_47" in text


def test_geometry_is_shared_between_soldiers(di) -> None:
    _, _, graph = di
    layout = EntityLayout([graph])
    crowd = Crowd(layout, 3)
    crowd.grow(200)
    assert crowd.capacity == 200 and crowd.local.shape == (200, layout.nnodes, 4, 4)
    assert crowd.layout.geometry is layout.geometry  # one copy of the vertices for every soldier
    verts = sum(g.vertices.nbytes for g, _ in layout.geometry)
    assert crowd.local.nbytes / 200 < verts  # a soldier costs his matrices, not a mesh


def test_updates_touch_only_the_rows_they_name(di) -> None:
    _, fk, graph = di
    layout = EntityLayout([graph])
    crowd = Crowd(layout, 4)
    crowd.active[:] = True
    before = crowd.world().copy()
    q = np.zeros((1, fk.ndof))
    q[0, graph.dof_slices["left_knee"]] = 1.0
    crowd.set_dofs([2], q)
    after = crowd.world()
    changed = np.abs(after - before).max(axis=(1, 2, 3)) > 1e-12
    assert changed.tolist() == [False, False, True, False]
    knee = layout.joint_nodes[graph.joint_names.index("left_knee")]
    moved = np.abs(after[2] - before[2]).max(axis=(1, 2)) > 1e-12
    assert moved[knee] and not moved[layout.joint_nodes[graph.joint_names.index("right_knee")]]
