"""BVH (issue 20) through bvhio: a walk cycle written and read back reproduces its joint angles within 0.01°,
and bvhio's own evaluation of the file puts every joint where Peabody's FK puts it, to 1 mm."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

bvh_io = pytest.importorskip("authoring.bvh_io")  # bvhio and pygltflib: the [authoring] extra

from authoring.bvh_io import bvh_to_channelset, bvhio, export_bvh, import_bvh  # noqa: E402
from authoring.gltf_export import Rig, channelset_motion, rig_for  # noqa: E402
from peabody.fk import FigureKinematics  # noqa: E402
from peabody.loader import read_figure  # noqa: E402
from server.config import DEFAULT_DATA_DIR  # noqa: E402
from server.motion.binding import bind_channelset  # noqa: E402
from server.motion.cache import load_channelset  # noqa: E402
from server.motion.channelset import Channelset  # noqa: E402

FIGURES = DEFAULT_DATA_DIR / "figures"
WALK = DEFAULT_DATA_DIR / "channelsets" / "bwalk_cycle_l_low.chset.env"


@pytest.fixture(scope="module")
def walk_bvh(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Rig, Channelset, np.ndarray, list]:
    cs = load_channelset(WALK)
    rig = rig_for([read_figure(FIGURES / "DI.fig"), read_figure(FIGURES / "AK_47.fig")])
    dofs, placements = channelset_motion(cs, rig)
    out = tmp_path_factory.mktemp("bvh") / "walk.bvh"
    export_bvh(rig, cs.fps, dofs, placements, out)
    return out, rig, cs, dofs, placements


def test_round_trip_reproduces_the_joint_angles_within_a_hundredth_of_a_degree(walk_bvh) -> None:
    path, rig, cs, dofs, placements = walk_bvh
    fps, back, root = import_bvh(path, rig)
    assert fps == pytest.approx(cs.fps)
    n = back.shape[1]
    assert back.shape == (cs.nframes, rig.figures[0].dof_count)
    rot = ~rig.translational[:n]
    diff = back - dofs[:, :n]
    wrapped = (diff[:, rot] + np.pi) % (2 * np.pi) - np.pi
    assert np.degrees(np.abs(wrapped)).max() < 0.01
    assert np.abs(diff[:, ~rot]).max() < 1e-6  # metres (spine_compression)
    assert np.abs(root - placements[0]).max() < 1e-5
    assert np.ptp(dofs[:, rot], axis=0).max() > 0.3  # the clip moves: the check is not of a still pose


def test_bvhio_places_every_joint_where_peabody_fk_does(walk_bvh) -> None:
    path, _, cs, _, _ = walk_bvh
    fig = read_figure(FIGURES / "DI.fig")
    kin = FigureKinematics(fig)
    bound = bind_channelset(cs, [fig])
    # a BVH joint is the frame after its DOFs: at the site on the child's side (the near one for R joints)
    far = {
        j: (fig.joints[j].site2 if fwd else fig.joints[j].site1) for j, _, _, fwd, _, _ in kin.tree_steps()
    }
    root = bvhio.readAsHierarchy(str(path))
    for frame in (0, cs.nframes // 2, cs.nframes - 1):
        root.loadPose(frame)
        at = {j.Name: np.array(j.PositionWorld, np.float64) for j, _, _ in root.layout()}
        s = bound.sample(float(frame), interpolate=False)
        pose, place = s.poses[fig.name].astype(np.float64), s.placements[fig.name]
        assert place is not None
        location = kin.location_for_site_global(place.root, place.matrix(), pose)
        sites = dict(zip(kin.site_names, kin.site_globals(pose, root_location=location), strict=True))
        for joint, site in far.items():
            g = sites[f"{site.segment.name}.{site.name}"][:3, 3]  # type: ignore[union-attr]
            want = np.array([-g[0], g[1], -g[2]])  # Jack (cm, facing -Z) -> the file's glTF axes (facing +Z)
            assert np.linalg.norm(at[joint] - want) < 0.1, f"frame {frame} {joint}"


def test_the_bvh_read_into_a_channelset_plays_the_walks_angles(walk_bvh) -> None:
    path, _, cs, _, _ = walk_bvh
    fig = read_figure(FIGURES / "DI.fig")
    back = bvh_to_channelset(path, rig_for([fig]), "walk_back")
    assert (back.nframes, back.fps) == (cs.nframes, cs.fps)
    kin = FigureKinematics(fig)
    a, b = bind_channelset(cs, [fig]), bind_channelset(back, [fig])
    for frame in range(cs.nframes):
        sa, sb = a.sample(float(frame), interpolate=False), b.sample(float(frame), interpolate=False)
        qa, qb = sa.poses[fig.name].astype(np.float64), sb.poses[fig.name].astype(np.float64)
        assert np.degrees(np.abs(qa - qb)[kin.rotational]).max() < 0.01
        pa, pb = sa.placements[fig.name], sb.placements[fig.name]
        assert pa is not None and pb is not None and pa.root == pb.root
        assert np.abs(pa.matrix() - pb.matrix()).max() < 1e-3  # cm and rotation entries
