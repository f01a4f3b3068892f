"""Jack ↔ Performer coordinates (section 3.5), vectorised over leading axes.

=============  ===========  ================
               Jack         Performer
=============  ===========  ================
up             +Y           +Z
zero heading   −Z           +Y ("north")
right          +X           +X
units          cm           m
=============  ===========  ================

Both frames are right-handed, so the change of axes is the proper rotation ``A`` with
``(x, y, z)_performer = A (x, y, z)_jack = (x, −z, y)``, plus the cm → m scale.

Headings on the wire are *compass* degrees: clockwise from north (+Y) seen from above (+Z), so 90° faces +X.
(Performer's own pfCoord heading turns the other way, counter-clockwise about +Z: ``h_pf = −compass``.)
In Jack a heading is a right-handed rotation about +Y starting from −Z: ``yaw_jack = −radians(compass)``.
Transforms are 4x4 matrices acting on column vectors (``p' = T @ p``); quaternions are (w, x, y, z).
"""

from __future__ import annotations

import numpy as np

from peabody import quaternion

# The quaternion conversions are peabody's (one implementation for server, clients and codecs); these are
# their names on the protocol side.
quat_to_matrix = quaternion.to_matrix
matrix_to_quat = quaternion.from_matrix
transform_to_pose7 = quaternion.from_transform
pose7_to_transform = quaternion.to_transform

CM_PER_M = 100.0
JACK_TO_PERFORMER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
PERFORMER_TO_JACK = JACK_TO_PERFORMER.T
JACK_TO_PERFORMER.setflags(write=False)
PERFORMER_TO_JACK.setflags(write=False)


def _rotate(v: np.ndarray, m: np.ndarray) -> np.ndarray:
    return np.asarray(v, np.float64) @ m.T


def points_jack_to_performer(p_cm: np.ndarray) -> np.ndarray:
    """Points (..., 3) in Jack centimetres → Performer metres."""
    return _rotate(p_cm, JACK_TO_PERFORMER) / CM_PER_M


def points_performer_to_jack(p_m: np.ndarray) -> np.ndarray:
    """Points (..., 3) in Performer metres → Jack centimetres."""
    return _rotate(p_m, PERFORMER_TO_JACK) * CM_PER_M


# Free vectors (velocities, displacements) change exactly like points: no translation is involved.
vectors_jack_to_performer = points_jack_to_performer
vectors_performer_to_jack = points_performer_to_jack


def directions_jack_to_performer(d: np.ndarray) -> np.ndarray:
    """Unit directions / rotation axes (..., 3): axes swapped, not scaled."""
    return _rotate(d, JACK_TO_PERFORMER)


def directions_performer_to_jack(d: np.ndarray) -> np.ndarray:
    return _rotate(d, PERFORMER_TO_JACK)


def _conjugate_transform(t: np.ndarray, m: np.ndarray, scale: float) -> np.ndarray:
    t = np.asarray(t, np.float64)
    out = np.zeros(t.shape)
    out[..., :3, :3] = m @ t[..., :3, :3] @ m.T
    out[..., :3, 3] = (t[..., :3, 3] @ m.T) * scale
    out[..., 3, :] = t[..., 3, :]
    return out


def transforms_jack_to_performer(t_cm: np.ndarray) -> np.ndarray:
    """4x4 transforms (..., 4, 4) on Jack points (cm) → the same motion on Performer points (m)."""
    return _conjugate_transform(t_cm, JACK_TO_PERFORMER, 1.0 / CM_PER_M)


def transforms_performer_to_jack(t_m: np.ndarray) -> np.ndarray:
    return _conjugate_transform(t_m, PERFORMER_TO_JACK, CM_PER_M)


def quats_jack_to_performer(q: np.ndarray) -> np.ndarray:
    """Rotation quaternions (..., 4) (w, x, y, z): the vector part changes like a direction."""
    q = np.asarray(q, np.float64)
    return np.concatenate([q[..., :1], directions_jack_to_performer(q[..., 1:])], axis=-1)


def quats_performer_to_jack(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, np.float64)
    return np.concatenate([q[..., :1], directions_performer_to_jack(q[..., 1:])], axis=-1)


def compass_to_jack_yaw(compass_deg: np.ndarray | float) -> np.ndarray:
    """Compass heading (degrees clockwise from +Y_performer) → Jack yaw (radians about +Y from −Z)."""
    return -np.radians(np.asarray(compass_deg, np.float64))


def jack_yaw_to_compass(yaw_rad: np.ndarray | float) -> np.ndarray:
    """Jack yaw (radians) → compass heading in [0, 360)."""
    return np.mod(-np.degrees(np.asarray(yaw_rad, np.float64)), 360.0)


def compass_to_direction(compass_deg: np.ndarray | float) -> np.ndarray:
    """Compass heading → horizontal unit vector (..., 3) in Performer axes: 0° → +Y, 90° → +X."""
    h = np.radians(np.asarray(compass_deg, np.float64))
    out = np.empty((*h.shape, 3))  # (np.stack's values, without its overhead: every request batch calls it)
    out[..., 0] = np.sin(h)
    out[..., 1] = np.cos(h)
    out[..., 2] = 0.0
    return out


def direction_to_compass(d: np.ndarray) -> np.ndarray:
    """Horizontal part of Performer vectors (..., 3) → compass heading in [0, 360)."""
    d = np.asarray(d, np.float64)
    return np.mod(np.degrees(np.arctan2(d[..., 0], d[..., 1])), 360.0)


def heading_transform(compass_deg: np.ndarray | float, position_m: np.ndarray) -> np.ndarray:
    """Performer 4x4 placing a soldier's local frame (forward +Y, up +Z) at ``position_m``, facing compass."""
    h = np.radians(np.asarray(compass_deg, np.float64))
    p = np.asarray(position_m, np.float64)
    c, s = np.cos(h), np.sin(h)
    t = np.zeros((*np.broadcast_shapes(h.shape, p.shape[:-1]), 4, 4))
    t[..., 0, 0], t[..., 0, 1] = c, s  # clockwise: local +Y (forward) goes to (sin h, cos h)
    t[..., 1, 0], t[..., 1, 1] = -s, c
    t[..., 2, 2] = 1.0
    t[..., :3, 3] = p
    t[..., 3, 3] = 1.0
    return t
