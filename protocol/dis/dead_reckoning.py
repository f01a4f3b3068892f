"""Dead reckoning, IEEE 1278.1 Annex E, algorithms 1..9, vectorised over entities.

TTES places every figure itself between Entity State PDUs (seed report section 2), extrapolating from
the last PDU of each entity. Names are DRM(rotation, order, frame): F fixed / R rotating orientation,
P first order (velocity) / V second order (velocity and acceleration), W world / B body axes.

===  =====  ====================================================================
alg  name   position after dt
===  =====  ====================================================================
1    STATIC P0
2    FPW    P0 + V dt
3    RPW    P0 + V dt, orientation rotated by omega
4    RVW    P0 + V dt + A dt^2 / 2, orientation rotated
5    FVW    P0 + V dt + A dt^2 / 2
6    FPB    P0 + M0^T (v_b dt)
7    RPB    P0 + M0^T (R1 v_b), orientation rotated
8    RVB    P0 + M0^T (R1 v_b + R2 a_b), orientation rotated
9    FVB    P0 + M0^T (v_b dt + a_b dt^2 / 2)
===  =====  ====================================================================

V, A are world (ECEF) vectors; M0 is the world-to-body matrix of the last orientation; the body-axis
algorithms take the body velocity v_b = M0 V (the PDU velocity field is always in world axes) and the
body acceleration a_b straight from the PDU (its acceleration field is in body axes for 6..9). With
omega = |w| and W = skew(w) (body angular velocity):

    R1 = (w dt - sin w dt)/w^3 ww^T + sin(w dt)/w I + (1 - cos w dt)/w^2 W
    R2 = (w^2 dt^2/2 - cos w dt - w dt sin w dt + 1)/w^4 ww^T + (cos w dt + w dt sin w dt - 1)/w^2 I
         + (sin w dt - w dt cos w dt)/w^3 W
    DR orientation:  M(dt) = [ (1 - cos w dt)/w^2 ww^T + cos(w dt) I - sin(w dt)/w W ] M0

As w -> 0, R1 -> dt I and R2 -> dt^2/2 I; the coefficients switch to Taylor series below w dt = 0.1 so
the limits are exact rather than 0/0. Frozen entities (appearance bit 21) and algorithms 0 / >9 are
not extrapolated.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from peabody.rotations import skew
from protocol.dis.geo import euler_from_matrix, world_to_body

F64 = NDArray[np.float64]
_SERIES_BELOW = 0.1


class DrAlgorithm(IntEnum):
    OTHER = 0
    STATIC = 1
    FPW = 2
    RPW = 3
    RVW = 4
    FVW = 5
    FPB = 6
    RPB = 7
    RVB = 8
    FVB = 9


_ROTATING = np.zeros(256, bool)
_ROTATING[[3, 4, 7, 8]] = True
_SECOND_ORDER = np.zeros(256, bool)
_SECOND_ORDER[[4, 5, 8, 9]] = True
_BODY = np.zeros(256, bool)
_BODY[[6, 7, 8, 9]] = True
_MOVING = np.zeros(256, bool)
_MOVING[2:10] = True


def _coefficients(omega: F64, dt: F64) -> tuple[F64, ...]:
    """(a1, b1, c1, a2, b2, c2): R1 = a1 ww^T + b1 I + c1 W, R2 = a2 ww^T + b2 I + c2 W."""
    x = omega * dt
    small = x < _SERIES_BELOW
    xs = np.where(small, 1.0, x)  # keep the exact branch away from 0/0
    ws = np.where(small, 1.0, omega)
    s, c = np.sin(xs), np.cos(xs)
    x2, x4 = x * x, x**4
    dt2, dt3, dt4 = dt * dt, dt**3, dt**4
    a1 = np.where(small, dt3 * (1 / 6 - x2 / 120 + x4 / 5040), (xs - s) / ws**3)
    b1 = np.where(small, dt * (1 - x2 / 6 + x4 / 120), s / ws)
    c1 = np.where(small, dt2 * (1 / 2 - x2 / 24 + x4 / 720), (1 - c) / ws**2)
    a2 = np.where(small, dt4 * (1 / 8 - x2 / 144 + x4 / 5760), (0.5 * xs * xs - c - xs * s + 1) / ws**4)
    b2 = np.where(small, dt2 * (1 / 2 - x2 / 8 + x4 / 144), (c + xs * s - 1) / ws**2)
    c2 = np.where(small, dt3 * (1 / 3 - x2 / 30 + x4 / 840), (s - xs * c) / ws**3)
    return a1, b1, c1, a2, b2, c2


def r1_r2(angular_velocity: ArrayLike, dt: ArrayLike) -> tuple[F64, F64]:
    """The R1 and R2 matrices (..., 3, 3) for body angular velocities (..., 3) over ``dt`` seconds."""
    w = np.asarray(angular_velocity, dtype=np.float64)
    dt = np.broadcast_to(np.asarray(dt, dtype=np.float64), w.shape[:-1])
    omega = np.linalg.norm(w, axis=-1)
    a1, b1, c1, a2, b2, c2 = _coefficients(omega, dt)
    wwt = w[..., :, None] * w[..., None, :]
    eye = np.eye(3)
    k = skew(w)
    r1 = a1[..., None, None] * wwt + b1[..., None, None] * eye + c1[..., None, None] * k
    r2 = a2[..., None, None] * wwt + b2[..., None, None] * eye + c2[..., None, None] * k
    return r1, r2


def dr_rotation(angular_velocity: ArrayLike, dt: ArrayLike) -> F64:
    """The DR orientation matrix: M(dt) = dr_rotation @ M0 (world-to-body)."""
    w = np.asarray(angular_velocity, dtype=np.float64)
    dt = np.broadcast_to(np.asarray(dt, dtype=np.float64), w.shape[:-1])
    omega = np.linalg.norm(w, axis=-1)
    x = omega * dt
    small = x < _SERIES_BELOW
    ws = np.where(small, 1.0, omega)
    xs = np.where(small, 1.0, x)
    k1 = np.where(small, dt * dt * (0.5 - x * x / 24 + x**4 / 720), (1 - np.cos(xs)) / ws**2)
    k2 = np.cos(x)
    k3 = np.where(small, dt * (1 - x * x / 6 + x**4 / 120), np.sin(xs) / ws)
    wwt = w[..., :, None] * w[..., None, :]
    return k1[..., None, None] * wwt + k2[..., None, None] * np.eye(3) - k3[..., None, None] * skew(w)


def dead_reckon(
    algorithm: ArrayLike,
    location: ArrayLike,
    velocity: ArrayLike,
    acceleration: ArrayLike,
    angular_velocity: ArrayLike,
    orientation: ArrayLike,
    dt: ArrayLike,
    frozen: ArrayLike | None = None,
) -> tuple[F64, F64]:
    """Extrapolated (location (N, 3), orientation (N, 3)) after ``dt`` seconds (scalar or per entity).

    Inputs are the fields of each entity's last Entity State PDU; shapes (N,) and (N, 3).
    """
    alg = np.asarray(algorithm, dtype=np.int64).reshape(-1) & 0xFF
    n = alg.shape[0]
    p0 = np.asarray(location, dtype=np.float64).reshape(n, 3)
    v = np.asarray(velocity, dtype=np.float64).reshape(n, 3)
    a = np.asarray(acceleration, dtype=np.float64).reshape(n, 3)
    w = np.asarray(angular_velocity, dtype=np.float64).reshape(n, 3)
    o0 = np.asarray(orientation, dtype=np.float64).reshape(n, 3)
    t = np.broadcast_to(np.asarray(dt, dtype=np.float64), (n,)).copy()
    moving = _MOVING[alg]
    if frozen is not None:
        moving &= ~np.broadcast_to(np.asarray(frozen, dtype=bool), (n,))
    t[~moving] = 0.0
    rotating, second, body = _ROTATING[alg] & moving, _SECOND_ORDER[alg] & moving, _BODY[alg] & moving

    location_out = p0.copy()
    orientation_out = o0.copy()
    world = moving & ~body
    if world.any():
        tw = t[world, None]
        acc = np.where(second[world, None], a[world], 0.0)
        location_out[world] = p0[world] + v[world] * tw + 0.5 * acc * tw * tw
    if body.any():
        m0 = world_to_body(o0[body])
        v_body = np.einsum("nij,nj->ni", m0, v[body])
        a_body = np.where(second[body, None], a[body], 0.0)
        w_body = np.where(rotating[body, None], w[body], 0.0)  # fixed-orientation: R1 = dt I, R2 = dt^2/2 I
        r1, r2 = r1_r2(w_body, t[body])
        d_body = np.einsum("nij,nj->ni", r1, v_body) + np.einsum("nij,nj->ni", r2, a_body)
        location_out[body] = p0[body] + np.einsum("nji,nj->ni", m0, d_body)
    if rotating.any():
        m0 = world_to_body(o0[rotating])
        m = dr_rotation(w[rotating], t[rotating]) @ m0
        orientation_out[rotating] = euler_from_matrix(m)
    return location_out, orientation_out
