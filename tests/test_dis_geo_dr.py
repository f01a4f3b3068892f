"""WGS84 frames, headings from DIS Euler angles, and the nine dead-reckoning algorithms."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.dis import LocalFrame, dead_reckon, ecef_to_geodetic, geodetic_to_ecef, heading_deg
from protocol.dis.dead_reckoning import dr_rotation, r1_r2
from protocol.dis.geo import enu_basis, euler_from_matrix, orientation_from_heading, world_to_body

HALF_PI = np.pi / 2


# --- geodesy ----------------------------------------------------------------------------------------------


def test_geodetic_ecef_known_points() -> None:
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 0.0, 0.0), [6378137.0, 0.0, 0.0])
    np.testing.assert_allclose(geodetic_to_ecef(90.0, 0.0, 0.0), [0.0, 0.0, 6356752.314245], atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 90.0, 100.0), [0.0, 6378237.0, 0.0], atol=1e-6)


@given(
    st.floats(-89.9, 89.9),
    st.floats(-180.0, 180.0),
    st.floats(-500.0, 10000.0),
)
def test_geodetic_round_trip(lat: float, lon: float, h: float) -> None:
    la, lo, hh = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h))
    assert la == pytest.approx(lat, abs=1e-9)
    assert ((lo - lon + 180.0) % 360.0) - 180.0 == pytest.approx(0.0, abs=1e-9)
    assert hh == pytest.approx(h, abs=1e-5)


def test_local_frame_round_trip_and_axes() -> None:
    frame = LocalFrame(38.52, -77.44, 60.0)
    enu = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 50.0, 2.0], [-30.0, -40.0, 0.0]])
    ecef = frame.to_ecef(enu)
    np.testing.assert_allclose(frame.to_local(ecef), enu, atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(ecef[1] - ecef[0]), 100.0)
    lat, lon, h = ecef_to_geodetic(ecef[0])
    assert (lat, lon, h) == pytest.approx((38.52, -77.44, 60.0), abs=1e-7)
    # north of the origin means a larger latitude, east a larger longitude
    assert ecef_to_geodetic(ecef[2])[0] > 38.52 and ecef_to_geodetic(ecef[1])[1] > -77.44
    assert frame.to_performer is not None
    np.testing.assert_allclose(
        frame.vector_to_local(frame.vector_to_ecef([[1.0, 2.0, 3.0]])), [[1.0, 2.0, 3.0]]
    )
    frame2 = LocalFrame.at_ecef(ecef[3])
    np.testing.assert_allclose(frame2.to_local(ecef[3]), 0.0, atol=1e-6)


# --- headings ---------------------------------------------------------------------------------------------


def test_heading_at_lat0_lon0() -> None:
    # at (0, 0): east = +Y_ecef, north = +Z_ecef, up = +X_ecef
    loc = geodetic_to_ecef(0.0, 0.0, 0.0)
    # psi = 90 deg: body x along +Y = east
    assert heading_deg(loc, [HALF_PI, 0.0, 0.0]) == pytest.approx(90.0)
    # theta = -90 deg: body x along +Z = north
    assert heading_deg(loc, [0.0, -HALF_PI, 0.0]) == pytest.approx(0.0, abs=1e-9)
    # psi = -90 deg: west
    assert heading_deg(loc, [-HALF_PI, 0.0, 0.0]) == pytest.approx(270.0)


def test_heading_at_lat45_lon90() -> None:
    loc = geodetic_to_ecef(45.0, 90.0, 0.0)
    # east is -X there: psi = 180 deg
    assert heading_deg(loc, [np.pi, 0.0, 0.0]) == pytest.approx(90.0)
    # north is (0, -sin45, cos45): psi = -90 deg, theta = -45 deg
    assert heading_deg(loc, [-HALF_PI, -np.pi / 4, 0.0]) == pytest.approx(0.0, abs=1e-9)
    # roll about the body axis does not change the heading
    assert heading_deg(loc, [-HALF_PI, -np.pi / 4, 1.0]) == pytest.approx(0.0, abs=1e-9)


def test_heading_of_the_sample_soldier() -> None:
    # the AK-74 soldier of ../shared/dis-samples (values copied so this runs without the file)
    loc = [1864059.807089591, 4918545.046719982, 3598531.783709617]
    ori = [-1.9330594539642334, -0.9707947969436646, 3.1415927410125732]
    lat, lon, _ = ecef_to_geodetic(loc)
    assert (lat, lon) == pytest.approx((34.5572, 69.2440), abs=1e-4)
    h = float(heading_deg(loc, ori))
    assert min(h, 360.0 - h) < 0.01  # facing due north


@given(
    st.floats(-80.0, 80.0),
    st.floats(-180.0, 180.0),
    st.floats(0.0, 359.9),
    st.floats(-60.0, 60.0),
    st.floats(-80.0, 80.0),
)
def test_orientation_from_heading_round_trip(
    lat: float, lon: float, heading: float, pitch: float, roll: float
) -> None:
    loc = geodetic_to_ecef(lat, lon, 10.0)
    ori = orientation_from_heading(loc, heading, pitch, roll)
    h = float(heading_deg(loc, ori))
    assert ((h - heading + 180.0) % 360.0) - 180.0 == pytest.approx(0.0, abs=1e-6)
    x_body = world_to_body(ori)[0]
    up = enu_basis(lat, lon)[2]
    assert np.degrees(np.arcsin(x_body @ up)) == pytest.approx(pitch, abs=1e-6)


@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))
def test_euler_matrix_round_trip(psi: float, theta: float, phi: float) -> None:
    np.testing.assert_allclose(
        euler_from_matrix(world_to_body([psi, theta, phi])), [psi, theta, phi], atol=1e-9
    )


# --- dead reckoning ---------------------------------------------------------------------------------------

P0 = np.array([1000.0, -2000.0, 3000.0])
V = np.array([1.0, 2.0, -0.5])
A = np.array([0.2, -0.1, 0.05])
W = np.array([0.0, 0.0, 0.3])
DT = 2.0


def dr(alg: int, ori=(0.0, 0.0, 0.0), v=V, a=A, w=W, dt=DT, frozen=None):
    loc, o = dead_reckon([alg], [P0], [v], [a], [w], [ori], dt, frozen)
    return loc[0], o[0]


def test_static_and_unknown_algorithms_do_not_move() -> None:
    for alg in (0, 1, 10, 255):
        loc, o = dr(alg, ori=(0.1, 0.2, 0.3))
        np.testing.assert_array_equal(loc, P0)
        np.testing.assert_array_equal(o, [0.1, 0.2, 0.3])


def test_world_axis_algorithms() -> None:
    first = P0 + V * DT
    second = P0 + V * DT + 0.5 * A * DT**2
    for alg, expect in ((2, first), (3, first), (4, second), (5, second)):
        loc, _ = dr(alg)
        np.testing.assert_allclose(loc, expect, rtol=0, atol=1e-9)
    # fixed-orientation ones keep the orientation, rotating ones turn by w dt about body z
    assert dr(2, ori=(0.1, 0.0, 0.0))[1] == pytest.approx([0.1, 0.0, 0.0])
    assert dr(5, ori=(0.1, 0.0, 0.0))[1] == pytest.approx([0.1, 0.0, 0.0])
    for alg in (3, 4):
        assert dr(alg, ori=(0.1, 0.0, 0.0))[1] == pytest.approx([0.1 + 0.3 * DT, 0.0, 0.0])


def test_body_axis_fixed_orientation_algorithms() -> None:
    ori = (HALF_PI, 0.0, 0.0)  # body x = world +Y, body y = world -X
    v_world = np.array([0.0, 5.0, 0.0])  # straight ahead in body axes
    a_body = np.array([1.0, 0.0, 0.0])  # forward acceleration, in body axes
    loc, o = dr(6, ori=ori, v=v_world, a=a_body)  # FPB ignores w and acceleration
    np.testing.assert_allclose(loc, P0 + np.array([0.0, 5.0 * DT, 0.0]), atol=1e-9)
    assert o == pytest.approx(ori)
    loc, o = dr(9, ori=ori, v=v_world, a=a_body)  # FVB: acceleration rotated into world axes
    np.testing.assert_allclose(loc, P0 + np.array([0.0, 5.0 * DT + 0.5 * DT**2, 0.0]), atol=1e-9)
    assert o == pytest.approx(ori)


def test_constant_rotation_traces_a_circle() -> None:
    speed, rate = 4.0, 0.5  # m/s forward, rad/s yaw about body z
    for t in (0.5, 1.0, 3.0, 2 * np.pi / rate):
        loc, o = dr(7, v=np.array([speed, 0.0, 0.0]), w=np.array([0.0, 0.0, rate]), dt=t)  # RPB
        expect = P0 + np.array([speed * np.sin(rate * t) / rate, speed * (1 - np.cos(rate * t)) / rate, 0.0])
        np.testing.assert_allclose(loc, expect, atol=1e-9)
        assert ((o[0] - rate * t + np.pi) % (2 * np.pi)) - np.pi == pytest.approx(0.0, abs=1e-9)


def test_rvb_matches_numerical_integration() -> None:
    rng = np.random.default_rng(5)
    ori = rng.uniform(-1, 1, 3)
    v_world, a_body, w = rng.normal(size=3) * 3, rng.normal(size=3), rng.normal(size=3) * 0.7
    loc, o = dr(8, ori=ori, v=v_world, a=a_body, w=w, dt=DT)
    # integrate: body frame rotates with w; body velocity v_b + a_b t; world velocity = M(t)^T v_b(t)
    m0 = world_to_body(ori)
    v_b = m0 @ v_world
    n = 20000
    ts = (np.arange(n) + 0.5) * DT / n
    rot = dr_rotation(np.broadcast_to(w, (n, 3)), ts) @ m0
    vel = np.einsum("nji,nj->ni", rot, v_b + np.outer(ts, a_body))
    np.testing.assert_allclose(loc, P0 + vel.sum(axis=0) * DT / n, atol=1e-6)
    np.testing.assert_allclose(world_to_body(o), dr_rotation(w, DT) @ m0, atol=1e-12)


def test_small_omega_limits() -> None:
    for omega in (0.0, 1e-14, 1e-9, 1e-4):
        w = np.array([omega, -omega, omega / 2])
        r1, r2 = r1_r2(w, 3.0)
        np.testing.assert_allclose(r1, 3.0 * np.eye(3), atol=10 * omega + 1e-15)
        np.testing.assert_allclose(r2, 4.5 * np.eye(3), atol=10 * omega + 1e-15)
        assert np.isfinite(r1).all() and np.isfinite(r2).all()
    # the series and closed-form branches agree across the switch at w dt = 0.1
    lo, hi = r1_r2(np.array([[0.0, 0.0, 0.0999999], [0.0, 0.0, 0.1000001]]), 1.0)
    np.testing.assert_allclose(lo[0], lo[1], atol=1e-6)
    np.testing.assert_allclose(hi[0], hi[1], atol=1e-6)
    # RVB with w -> 0 is plain kinematics in body axes (orientation 0: body = world)
    loc, _ = dr(8, w=np.array([0.0, 0.0, 1e-12]))
    np.testing.assert_allclose(loc, P0 + V * DT + 0.5 * A * DT**2, atol=1e-9)


def test_r1_r2_closed_forms() -> None:
    w = np.array([0.3, -0.4, 1.2])
    dt = 1.7
    r1, r2 = r1_r2(w, dt)
    n = 20000
    taus = (np.arange(n) + 0.5) * dt / n
    exps = dr_rotation(np.broadcast_to(w, (n, 3)), taus).transpose(0, 2, 1)  # exp(W tau)
    np.testing.assert_allclose(r1, exps.sum(axis=0) * dt / n, atol=1e-7)
    np.testing.assert_allclose(r2, (exps * taus[:, None, None]).sum(axis=0) * dt / n, atol=1e-7)


def test_frozen_entities_are_not_extrapolated() -> None:
    loc, _ = dr(4, frozen=[True])
    np.testing.assert_array_equal(loc, P0)
    loc, _ = dr(4, frozen=[False])
    assert not np.allclose(loc, P0)


def test_vectorised_over_entities_matches_one_by_one() -> None:
    rng = np.random.default_rng(1)
    n = 400
    alg = rng.integers(0, 11, n)
    p, v, a, w, o = (rng.normal(size=(n, 3)) * s for s in (1e6, 3.0, 0.5, 0.4, 1.0))
    dts = rng.uniform(0, 5, n)
    frozen = rng.random(n) < 0.1
    loc, ori = dead_reckon(alg, p, v, a, w, o, dts, frozen)
    for i in range(0, n, 37):
        l1, o1 = dead_reckon(
            alg[i : i + 1],
            p[i : i + 1],
            v[i : i + 1],
            a[i : i + 1],
            w[i : i + 1],
            o[i : i + 1],
            dts[i],
            frozen[i : i + 1],
        )
        np.testing.assert_allclose(loc[i], l1[0], rtol=1e-12)
        np.testing.assert_allclose(ori[i], o1[0], rtol=1e-12, atol=1e-12)
