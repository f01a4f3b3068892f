"""A free camera (position, compass heading, pitch) in Performer axes, and its OpenGL matrices.

Free means not tethered to a soldier: it flies anywhere (:meth:`FreeCamera.move`, :meth:`turn`), or looks
at a point (:meth:`look_at`). Headless runs drive it along a scripted path (:func:`orbit`). Heading is a
compass angle (0° looks north, +Y; 90° east, +X), pitch is up from the horizon, +Z is up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class FreeCamera:
    position: np.ndarray = field(default_factory=lambda: np.array([0.0, -60.0, 20.0]))
    heading: float = 0.0  # compass degrees
    pitch: float = -15.0  # degrees above the horizon
    fovy: float = 50.0  # vertical field of view, degrees
    near: float = 0.3
    far: float = 1500.0

    def forward(self) -> np.ndarray:
        h, p = math.radians(self.heading), math.radians(self.pitch)
        return np.array([math.sin(h) * math.cos(p), math.cos(h) * math.cos(p), math.sin(p)])

    def move(self, forward: float = 0.0, right: float = 0.0, up: float = 0.0) -> None:
        """Fly along the view direction, sideways (horizontally) and straight up, in metres."""
        h = math.radians(self.heading)
        side = np.array([math.cos(h), -math.sin(h), 0.0])
        self.position = self.position + forward * self.forward() + right * side + np.array([0.0, 0.0, up])

    def turn(self, heading: float = 0.0, pitch: float = 0.0) -> None:
        self.heading = (self.heading + heading) % 360.0
        self.pitch = float(np.clip(self.pitch + pitch, -89.0, 89.0))

    def look_at(self, target: np.ndarray) -> None:
        d = np.asarray(target, np.float64) - self.position
        self.heading = math.degrees(math.atan2(d[0], d[1])) % 360.0
        self.pitch = math.degrees(math.atan2(d[2], math.hypot(d[0], d[1])))

    def view(self) -> np.ndarray:
        """4×4 world → eye (OpenGL: the eye looks down its -Z, +Y up)."""
        f = self.forward()
        right = np.cross(f, [0.0, 0.0, 1.0])
        norm = np.linalg.norm(right)
        right = right / norm if norm > 1e-9 else np.array([1.0, 0.0, 0.0])
        up = np.cross(right, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = right, up, -f
        m[:3, 3] = -m[:3, :3] @ self.position
        return m

    def pose(self) -> np.ndarray:
        """4×4 camera → world (the inverse of :meth:`view`)."""
        return np.linalg.inv(self.view())

    def set_pose(self, pose: np.ndarray) -> None:
        """Position, heading and pitch from a camera → world pose (a free camera has no roll)."""
        pose = np.asarray(pose, np.float64)
        f = -pose[:3, 2] / np.linalg.norm(pose[:3, 2])
        self.position = pose[:3, 3].copy()
        self.heading = math.degrees(math.atan2(f[0], f[1])) % 360.0
        self.pitch = math.degrees(math.asin(float(np.clip(f[2], -1.0, 1.0))))

    def projection(self, aspect: float) -> np.ndarray:
        return perspective(self.fovy, aspect, self.near, self.far)

    def viewproj(self, aspect: float) -> np.ndarray:
        return self.projection(aspect) @ self.view()


def orbit(
    camera: FreeCamera, centre: np.ndarray, radius: float, height: float, t: float, period: float
) -> None:
    """Place ``camera`` on a circle around ``centre`` (one turn per ``period`` seconds) looking at it."""
    a = 2 * math.pi * t / period
    c = np.asarray(centre, np.float64)
    camera.position = c + np.array([radius * math.sin(a), -radius * math.cos(a), height])
    camera.look_at(c + np.array([0.0, 0.0, 1.0]))


def perspective(yfov_deg: float, aspect: float, znear: float = 0.2, zfar: float = 2000.0) -> np.ndarray:
    """OpenGL projection matrix (pyrender's ``PerspectiveCamera``): the crowd's and the stub's."""
    t = 1.0 / np.tan(np.radians(yfov_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = t / aspect, t
    m[2, 2], m[2, 3] = (zfar + znear) / (znear - zfar), 2 * zfar * znear / (znear - zfar)
    m[3, 2] = -1.0
    return m
