"""The shipped figures (figures/*.fig): counts from seed 002 (3.4.3), slaving sites (3.4.4), anatomy."""

from __future__ import annotations

import numpy as np
import pytest

from ttes.paths import FIGURES

loader = pytest.importorskip("peabody.loader")
fk = pytest.importorskip("peabody.fk")

# seed 002, 3.4.3: soldier.fig vs DI.fig
SEED = {
    "soldier": {"segments": 69, "joints": 68, "dofs": 134, "sites": 180, "polygons": 2410},
    "DI": {"segments": 24, "joints": 23, "dofs": 50, "sites": 147, "polygons": 478},
}
# seed 002, 3.4.4: (constraint, endeffector on DI.fig, goal on soldier.fig)
SLAVING = [
    ("DI_belly", "middle_torso.upper_torso", "t12.DI_middletarget"),
    ("DI_torso", "upper_torso.distal", "upper_torso.distal"),
    ("DI_sight", "bottom_head.sight", "bottom_head.sight"),
    ("DI_leftpalm", "left_palm.palmcenter", "left_palm.palmcenter"),
    ("DI_rightpalm", "right_palm.palmcenter", "right_palm.palmcenter"),
    ("DI_leftelbow", "left_upper_arm.distal", "left_upper_arm.distal"),
    ("DI_rightelbow", "right_upper_arm.distal", "right_upper_arm.distal"),
]
SIDES = ("left", "right")


@pytest.fixture(scope="module")
def figures():
    out = {}
    for name in ("soldier", "DI", "AK_47", "M16"):
        path = FIGURES / f"{name}.fig"
        if not path.is_file():
            pytest.skip(f"{path} not generated (ttes author figures)")
        out[name] = loader.read_figure(path)
    return out


@pytest.fixture(scope="module")
def kin(figures):
    return {name: fk.FigureKinematics(fig) for name, fig in figures.items()}


def polygons(fig) -> int:
    return sum(s.psurf.polygon_count for s in fig.segments.values() if s.psurf is not None)


def world_nodes(fig, k, q=None) -> np.ndarray:
    q = k.neutral_pose() if q is None else q
    g = k.segment_globals(q)
    pts = []
    for i, name in enumerate(k.segment_names):
        ps = fig.segments[name].psurf
        if ps is not None:
            pts.append(ps.nodes @ g[i][:3, :3].T + g[i][:3, 3])
    return np.concatenate(pts)


def pose(k, **joints) -> np.ndarray:
    """Neutral pose with some joints set (degrees for rotations)."""
    q = k.neutral_pose()
    for name, values in joints.items():
        sl = k.dof_slices[name]
        vals = np.radians(np.atleast_1d(np.asarray(values, dtype=float)))
        q[sl.start : sl.start + len(vals)] = vals
    return q


def moved(k, site, **joints) -> np.ndarray:
    return k.site_global(site, pose(k, **joints))[:3, 3] - k.site_global(site, k.neutral_pose())[:3, 3]


# ------------------------------------------------------------------------------------------ counts


def test_di_counts_are_exactly_the_seed(figures):
    di = figures["DI"]
    assert (len(di.segments), len(di.joints), di.dof_count) == (24, 23, 50)
    assert len(di.sites()) == pytest.approx(SEED["DI"]["sites"], rel=0.10)
    assert polygons(di) == pytest.approx(SEED["DI"]["polygons"], rel=0.10)


def test_soldier_counts_match_the_seed(figures):
    s = figures["soldier"]
    assert (len(s.segments), len(s.joints), s.dof_count) == (69, 68, 134)
    assert len(s.sites()) == pytest.approx(SEED["soldier"]["sites"], rel=0.10)
    assert polygons(s) == pytest.approx(SEED["soldier"]["polygons"], rel=0.10)


def test_soldier_has_the_17_joint_spine_and_fingers(figures):
    s = figures["soldier"]
    vertebrae = [f"l{i}" for i in range(5, 0, -1)] + [f"t{i}" for i in range(12, 0, -1)]
    assert all(v in s.segments for v in vertebrae)
    assert all(f"v{v}" in s.joints for v in vertebrae)
    assert s.joints["waist"].site2.segment.name == "l5"
    assert s.joints["vt1"].site2.segment.name == "upper_torso"
    for side in SIDES:
        digits = [n for n in s.segments if n.startswith(f"{side}_") and n[-1].isdigit()]
        assert len(digits) == 15  # thumb + 4 fingers, 3 segments each
        assert f"{side}_eyeball" in s.segments


def test_di_has_no_fingers_spine_or_eyeballs_and_a_virtual_clavicle(figures):
    di = figures["DI"]
    assert not any(n.startswith(("l", "t")) and n[1:].isdigit() for n in di.segments)
    assert not any("eyeball" in n or n[-1].isdigit() for n in di.segments)
    for side in SIDES:
        assert di.segments[f"{side}_clavicle"].psurf is None
        assert figures["soldier"].segments[f"{side}_clavicle"].psurf is not None
    # the torso: two rotational joints and one translational joint replace the spine (7 DOFs)
    torso = [di.joints[n] for n in ("belly", "spine_compression", "upper_spine")]
    assert [d.kind for j in torso for d in j.dofs] == ["R"] * 3 + ["T"] + ["R"] * 3


def test_same_joint_structure_from_the_waist_down(figures):
    """Seed 3.4.4: below the waist the two figures share joints, so angles copy across."""
    s, di = figures["soldier"], figures["DI"]
    names = ["waist"] + [f"{side}_{j}" for side in SIDES for j in ("hip", "knee", "ankle", "toes")]
    for name in names:
        a, b = s.joints[name], di.joints[name]
        assert [d.kind for d in a.dofs] == [d.kind for d in b.dofs]
        assert np.allclose([d.axis for d in a.dofs], [d.axis for d in b.dofs])
        assert np.allclose([d.lower for d in a.dofs], [d.lower for d in b.dofs])
    for name in ["neck", "head", *(f"{s_}_{j}" for s_ in SIDES for j in ("shoulder", "elbow", "wrist"))]:
        assert name in s.joints and name in di.joints


# ------------------------------------------------------------------------------------------ sites


@pytest.mark.parametrize(("constraint", "effector", "goal"), SLAVING)
def test_slaving_sites_exist_and_coincide_in_the_neutral_pose(figures, kin, constraint, effector, goal):
    figures["DI"].site(effector)
    figures["soldier"].site(goal)
    a = kin["DI"].site_global(effector, kin["DI"].neutral_pose())[:3, 3]
    b = kin["soldier"].site_global(goal, kin["soldier"].neutral_pose())[:3, 3]
    assert np.linalg.norm(a - b) < 0.05, constraint


def test_every_segment_has_proximal_and_distal_sites(figures):
    for name in ("soldier", "DI"):
        for seg in figures[name].segments.values():
            assert {"proximal", "distal"} <= set(seg.sites), seg.fullname
            assert np.allclose(seg.sites["proximal"].location, np.eye(4))


def test_root_and_foot_and_hand_sites(figures, kin):
    for name in ("soldier", "DI"):
        fig, k = figures[name], kin[name]
        assert fig.root is fig.segments["lower_torso"].sites["proximal"]
        q = k.neutral_pose()
        for side in SIDES:
            heel = k.site_global(f"{side}_foot.heel", q)[:3, 3]
            toe = k.site_global(f"{side}_foot.toe", q)[:3, 3]
            assert abs(heel[1]) < 1e-3 and abs(toe[1]) < 1e-3  # on the ground
            assert 24.0 < heel[2] - toe[2] < 33.0  # a foot's length, toes forward (-Z)
            for site in ("palmcenter", "grip"):
                fig.site(f"{side}_palm.{site}")
        sight = k.site_global("bottom_head.sight", q)
        assert abs(sight[0, 3]) < 1e-6 and 165.0 < sight[1, 3] < 180.0
        assert np.allclose(sight[:3, :3] @ [0.0, 0.0, -1.0], [0.0, 0.0, -1.0])  # looks along -Z
        pelvis = k.site_global("lower_torso.proximal", q)[:3, 3]
        assert 90.0 < pelvis[1] < 115.0 and abs(pelvis[0]) < 1e-6


# ------------------------------------------------------------------------------------------ geometry


def test_height_is_the_95th_percentile_male_and_feet_touch_the_ground(figures, kin):
    for name in ("soldier", "DI"):
        pts = world_nodes(figures[name], kin[name])
        assert pts[:, 1].max() - pts[:, 1].min() == pytest.approx(186.0, abs=3.0)
        assert abs(pts[:, 1].min()) < 0.5
        # the figure faces -Z: the toes are further forward than the heels
        assert pts[:, 2].min() < -15.0 and pts[:, 2].max() < 15.0


def test_psurfs_face_outward(figures, kin):
    """Faces run counter-clockwise seen from outside: the body's signed volume is positive and plausible."""
    from peabody.psurf import fan_triangles

    for name in ("soldier", "DI"):
        fig, k = figures[name], kin[name]
        g = k.segment_globals(k.neutral_pose())
        volume = 0.0
        for i, seg_name in enumerate(k.segment_names):
            ps = fig.segments[seg_name].psurf
            if ps is None:
                continue
            p = ps.nodes @ g[i][:3, :3].T + g[i][:3, 3]
            tri, _ = fan_triangles(ps)
            assert tri.min() >= 0 and tri.max() < len(ps.nodes)
            a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
            volume += np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
        assert 30_000.0 < volume < 120_000.0, name  # cm^3: positive, and of the order of a body's


def test_caps_fan_from_their_first_corner(figures):
    """Cap polygons close the cuts at joints; a fan from their first corner must stay inside them."""
    caps = 0
    for name in ("soldier", "DI"):
        for seg in figures[name].segments.values():
            if seg.psurf is None:
                continue
            for face in seg.psurf.faces:
                if len(face) <= 3:
                    continue
                caps += 1
                p = seg.psurf.nodes[face]
                normal = np.cross(p[1:-1] - p[0], p[2:] - p[0])
                assert np.all(normal @ normal.sum(axis=0) > 0), seg.fullname
    assert caps > 50


def test_psurfs_sit_in_their_segment_frames(figures):
    for name in ("soldier", "DI"):
        for seg in figures[name].segments.values():
            if seg.psurf is None:
                continue
            lo, hi = seg.psurf.nodes.min(axis=0), seg.psurf.nodes.max(axis=0)
            assert np.all(lo < 8.0) and np.all(hi > -8.0), seg.fullname  # the proximal joint is at/near it


# ------------------------------------------------------------------------------------------ limits, anatomy


def test_neutral_pose_is_zero_and_within_limits(kin):
    for name in ("soldier", "DI"):
        k = kin[name]
        q = k.neutral_pose()
        assert np.all(q == 0.0)
        assert np.all(k.lower <= q) and np.all(q <= k.upper)
        assert np.all(k.lower < k.upper)
        assert np.all(np.isfinite(k.lower)) and np.all(np.isfinite(k.upper))


def test_knees_and_elbows_cannot_hyperextend(figures, kin):
    for name in ("soldier", "DI"):
        fig, k = figures[name], kin[name]
        for side in SIDES:
            knee = fig.joints[f"{side}_knee"].dofs
            assert len(knee) == 1 and knee[0].lower == 0.0 and knee[0].upper > np.radians(120)
            elbow = fig.joints[f"{side}_elbow"].dofs
            assert elbow[0].lower == 0.0 and elbow[0].upper > np.radians(120)
            # the positive direction really is flexion: the ankle goes back, the wrist goes forward
            assert moved(k, f"{side}_lower_leg.distal", **{f"{side}_knee": 90})[2] > 30.0
            assert moved(k, f"{side}_lower_arm.distal", **{f"{side}_elbow": 90})[2] < -20.0
            q = pose(k, **{f"{side}_knee": -10})
            assert not np.all(k.clamp(q) == q)  # hyper-extension is outside the limits


@pytest.mark.parametrize(
    ("site", "joints", "axis", "sign"),
    [
        ("right_upper_arm.distal", {"right_shoulder": 90}, 0, 1),  # abduction: out to the right (+X)
        ("left_upper_arm.distal", {"left_shoulder": 90}, 0, -1),  # ... and to the left (-X)
        ("right_upper_arm.distal", {"right_shoulder": [0, 90]}, 2, -1),  # flexion: forward
        ("left_upper_leg.distal", {"left_hip": [0, 90]}, 2, -1),  # hip flexion: forward
        ("left_upper_leg.distal", {"left_hip": [30]}, 0, -1),  # hip abduction: out
        ("bottom_head.sight", {"waist": [0, 30]}, 2, -1),  # waist flexion: lean forward
        ("bottom_head.nose", {"neck": [0, 0, 45]}, 0, -1),  # positive twist turns to the left
        ("right_palm.distal", {"right_wrist": 60}, 0, -1),  # wrist flexion toward the palm (medial)
        ("left_palm.distal", {"left_wrist": 60}, 0, 1),
        ("right_index1.distal", {"right_index_mcp": 80}, 0, -1),  # fingers curl toward the palm
        ("left_toes.distal", {"left_ankle": 20}, 1, 1),  # dorsiflexion lifts the toes
        ("right_clavicle.distal", {"right_clavicle": 30}, 1, 1),  # elevation
    ],
)
def test_positive_angles_mean_the_same_anatomical_motion(kin, site, joints, axis, sign):
    d = moved(kin["soldier"], site, **joints)
    assert sign * d[axis] > 2.0


def test_pronation_turns_the_palm_down_with_the_elbow_flexed(kin):
    k = kin["soldier"]
    for side in SIDES:
        bent = pose(k, **{f"{side}_elbow": 90})
        prone = pose(k, **{f"{side}_elbow": [90, 80]})
        site = f"{side}_palm.palmcenter"
        assert k.site_global(site, prone)[1, 3] < k.site_global(site, bent)[1, 3] - 1.0


# ------------------------------------------------------------------------------------------ rifles


@pytest.mark.parametrize(("name", "length"), [("AK_47", 88.0), ("M16", 100.0)])
def test_rifles(figures, kin, name, length):
    fig, k = figures[name], kin[name]
    assert len(fig.segments) == 1 and len(fig.joints) == 0
    (seg,) = fig.segments.values()
    for site in ("grip", "handguard", "butt", "muzzle"):
        assert site in seg.sites
    assert fig.root is not None and fig.root.segment is seg
    q = k.neutral_pose()
    muzzle, butt, grip, guard = (
        k.site_global(f"{seg.name}.{s}", q)[:3, 3] for s in ("muzzle", "butt", "grip", "handguard")
    )
    assert muzzle[2] < guard[2] < grip[2] < butt[2]  # barrel along -Z, hands between muzzle and butt
    assert butt[2] - muzzle[2] == pytest.approx(length, abs=3.0)
    assert grip[1] < muzzle[1]  # the pistol grip hangs below the barrel
    span = seg.psurf.nodes.max(axis=0) - seg.psurf.nodes.min(axis=0)
    assert span[2] == pytest.approx(length, abs=3.0) and span[2] > 2 * span[1]
