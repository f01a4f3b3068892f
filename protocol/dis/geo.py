"""WGS84 geodesy for DIS: ECEF <-> geodetic, local east-north-up frames, DIS Euler angles and headings.

DIS places entities in geocentric (ECEF) metres and orients them with Euler angles (psi, theta, phi)
that rotate the ECEF axes onto the entity's body axes (x forward, y right, z down): first psi about Z,
then theta about the new Y, then phi about the new X. TTES wants local metres and a compass heading,
so everything here converts between the two, vectorised over entities.

The Performer frame of the TTES stub is east-north-up: +X east, +Y north, +Z up, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_B = WGS84_A * (1.0 - WGS84_F)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)

F64 = NDArray[np.float64]


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, height: ArrayLike = 0.0) -> F64:
    """ECEF metres (..., 3) of geodetic latitude/longitude (degrees) and ellipsoidal height (m)."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    h = np.asarray(height, dtype=np.float64)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(
        np.broadcast_arrays(
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - WGS84_E2) + h) * np.sin(lat),
        ),
        axis=-1,
    )


def ecef_to_geodetic(xyz: ArrayLike) -> tuple[F64, F64, F64]:
    """(latitude deg, longitude deg, height m) of ECEF points (..., 3).

    Bowring's parametric-latitude iteration, three rounds: sub-millimetre anywhere near the surface.
    """
    p3 = np.asarray(xyz, dtype=np.float64)
    x, y, z = p3[..., 0], p3[..., 1], p3[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    beta = np.arctan2(z, (1.0 - WGS84_F) * p)
    lat = beta
    for _ in range(3):
        lat = np.arctan2(
            z + WGS84_EP2 * WGS84_B * np.sin(beta) ** 3, p - WGS84_E2 * WGS84_A * np.cos(beta) ** 3
        )
        beta = np.arctan2((1.0 - WGS84_F) * np.sin(lat), np.cos(lat))
    s = np.sin(lat)
    h = p * np.cos(lat) + z * s - WGS84_A * np.sqrt(1.0 - WGS84_E2 * s * s)
    return np.degrees(lat), np.degrees(lon), h


def enu_basis(lat_deg: ArrayLike, lon_deg: ArrayLike) -> F64:
    """Rows east, north, up (ECEF unit vectors) of the local tangent plane: shape (..., 3, 3)."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    zero = np.zeros_like(sl * so)
    east = np.stack(np.broadcast_arrays(-so, co, zero), axis=-1)
    north = np.stack(np.broadcast_arrays(-sl * co, -sl * so, cl), axis=-1)
    up = np.stack(np.broadcast_arrays(cl * co, cl * so, sl), axis=-1)
    return np.stack([east, north, up], axis=-2)


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """A flat east-north-up frame tangent to WGS84 at an origin: the Performer frame of the TTES stub."""

    lat: float
    lon: float
    height: float = 0.0

    @classmethod
    def at_ecef(cls, xyz: ArrayLike) -> LocalFrame:
        """The frame whose origin is an ECEF point (e.g. the first entity seen)."""
        lat, lon, h = ecef_to_geodetic(np.asarray(xyz, dtype=np.float64).reshape(3))
        return cls(float(lat), float(lon), float(h))

    @property
    def origin_ecef(self) -> F64:
        return geodetic_to_ecef(self.lat, self.lon, self.height)

    @property
    def basis(self) -> F64:
        return enu_basis(self.lat, self.lon)

    def to_local(self, xyz: ArrayLike) -> F64:
        """ECEF positions (..., 3) -> local east, north, up metres."""
        return (np.asarray(xyz, dtype=np.float64) - self.origin_ecef) @ self.basis.T

    def to_ecef(self, enu: ArrayLike) -> F64:
        return np.asarray(enu, dtype=np.float64) @ self.basis + self.origin_ecef

    def vector_to_local(self, v: ArrayLike) -> F64:
        """ECEF vectors (velocities) -> local east, north, up components (no translation)."""
        return np.asarray(v, dtype=np.float64) @ self.basis.T

    def vector_to_ecef(self, v: ArrayLike) -> F64:
        return np.asarray(v, dtype=np.float64) @ self.basis

    to_performer = to_local  # +X east, +Y north, +Z up


def world_to_body(orientation: ArrayLike) -> F64:
    """Rotation matrices (..., 3, 3) whose rows are the body x, y, z axes in ECEF, from (psi, theta, phi)."""
    o = np.asarray(orientation, dtype=np.float64)
    psi, theta, phi = o[..., 0], o[..., 1], o[..., 2]
    cps, sps, cth, sth, cph, sph = (
        np.cos(psi),
        np.sin(psi),
        np.cos(theta),
        np.sin(theta),
        np.cos(phi),
        np.sin(phi),
    )
    m = np.empty((*o.shape[:-1], 3, 3))
    m[..., 0, 0] = cth * cps
    m[..., 0, 1] = cth * sps
    m[..., 0, 2] = -sth
    m[..., 1, 0] = sph * sth * cps - cph * sps
    m[..., 1, 1] = sph * sth * sps + cph * cps
    m[..., 1, 2] = sph * cth
    m[..., 2, 0] = cph * sth * cps + sph * sps
    m[..., 2, 1] = cph * sth * sps - sph * cps
    m[..., 2, 2] = cph * cth
    return m


def euler_from_matrix(m: ArrayLike) -> F64:
    """(psi, theta, phi) of world-to-body matrices (..., 3, 3); the inverse of :func:`world_to_body`."""
    m = np.asarray(m, dtype=np.float64)
    psi = np.arctan2(m[..., 0, 1], m[..., 0, 0])
    theta = -np.arcsin(np.clip(m[..., 0, 2], -1.0, 1.0))
    phi = np.arctan2(m[..., 1, 2], m[..., 2, 2])
    return np.stack([psi, theta, phi], axis=-1)


def heading_deg(location: ArrayLike, orientation: ArrayLike) -> F64:
    """Compass heading (degrees clockwise from true north, [0, 360)) of entities at ECEF ``location``.

    The body x-axis projected on the local tangent plane at each entity's own position.
    """
    loc = np.asarray(location, dtype=np.float64)
    lat, lon, _ = ecef_to_geodetic(loc)
    basis = enu_basis(lat, lon)
    x_body = world_to_body(orientation)[..., 0, :]
    east = np.einsum("...i,...i->...", x_body, basis[..., 0, :])
    north = np.einsum("...i,...i->...", x_body, basis[..., 1, :])
    h = np.mod(np.degrees(np.arctan2(east, north)), 360.0)
    return np.where(h >= 360.0, 0.0, h)  # -tiny mod 360 rounds up to 360


def orientation_from_heading(
    location: ArrayLike, heading: ArrayLike, pitch: ArrayLike = 0.0, roll: ArrayLike = 0.0
) -> F64:
    """DIS (psi, theta, phi) for a compass heading, pitch (nose up) and roll (right side down), degrees."""
    loc = np.asarray(location, dtype=np.float64)
    lat, lon, _ = ecef_to_geodetic(loc)
    basis = enu_basis(lat, lon)  # (..., 3, 3)
    h, p, r = (np.radians(np.asarray(a, dtype=np.float64)) for a in (heading, pitch, roll))
    # body axes in local ENU: x forward, y right, z down
    x = np.stack(np.broadcast_arrays(np.sin(h) * np.cos(p), np.cos(h) * np.cos(p), np.sin(p)), axis=-1)
    y0 = np.stack(np.broadcast_arrays(np.cos(h), -np.sin(h), 0.0 * h), axis=-1)
    z0 = np.cross(x, y0)
    y = np.cos(r)[..., None] * y0 + np.sin(r)[..., None] * z0
    z = np.cross(x, y)
    enu = np.stack([x, y, z], axis=-2)  # rows = body axes in ENU
    m = enu @ basis  # rows = body axes in ECEF
    return euler_from_matrix(m)
