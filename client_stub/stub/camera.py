"""The stub's views (seed 002, 4.1–4.3): bird's eye, SOLDIER CAM (tethered), overhead, fly.

The tethered camera keeps a distance and an azimuth relative to the current soldier's heading (azimuth 0
is behind him) and an elevation; keys move it away/towards by 5 m and swing it by 10°. ``o`` raises it
overhead; swinging (``i``/``j``) from overhead also brings it down 10° a press, so "press [i] again until you
are looking at him from the side" (4.3) works. Poses are pyrender camera poses: the camera looks along its
own -Z with +Y up, in Performer axes (+Z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from protocol import coords

TETHER_ELEVATION = 15.0  # degrees: the normal tethered view
OVERHEAD_ELEVATION = 85.0
MIN_DISTANCE = 2.0
LOOK_HEIGHT = 1.0  # metres above the feet the tethered camera looks at


class View(Enum):
    BIRDS_EYE = "bird's eye"
    SOLDIER_CAM = "SOLDIER CAM"
    OVERHEAD = "overhead"
    FLY = "fly"


@dataclass
class CameraState:
    view: View = View.BIRDS_EYE
    distance: float = 6.0
    azimuth: float = 0.0  # degrees, clockwise from behind the soldier
    elevation: float = TETHER_ELEVATION
    fly_position: np.ndarray = field(default_factory=lambda: np.array([0.0, -60.0, 20.0]))
    fly_heading: float = 0.0
    fly_pitch: float = -15.0

    def tether(self) -> None:
        self.view = View.SOLDIER_CAM
        self.elevation = TETHER_ELEVATION

    def away(self, metres: float = 5.0) -> None:
        self.distance = max(MIN_DISTANCE, self.distance + metres)

    def swing(self, degrees: float) -> None:
        self.azimuth = (self.azimuth + degrees) % 360.0
        if self.view is View.OVERHEAD:
            self.view = View.SOLDIER_CAM
        if self.elevation > TETHER_ELEVATION:
            self.elevation = max(TETHER_ELEVATION, self.elevation - 10.0)

    def overhead(self) -> None:
        self.view = View.OVERHEAD
        self.elevation = OVERHEAD_ELEVATION

    def fly(self, forward: float = 0.0, up: float = 0.0, turn: float = 0.0) -> None:
        self.view = View.FLY
        self.fly_heading = (self.fly_heading + turn) % 360.0
        self.fly_position = self.fly_position + coords.compass_to_direction(self.fly_heading) * forward
        self.fly_position[2] += up


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """Camera pose at ``eye`` looking at ``target`` (pyrender convention: the camera looks along -Z)."""
    eye = np.asarray(eye, np.float64)
    f = np.asarray(target, np.float64) - eye
    f /= max(np.linalg.norm(f), 1e-12)
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, np.float64)
    x = np.cross(f, up)
    if np.linalg.norm(x) < 1e-6:  # looking straight down: any horizontal right vector
        x = np.cross(f, np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(x, f)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, -f, eye
    return pose


def tethered_eye(state: CameraState, feet: np.ndarray, heading: float) -> tuple[np.ndarray, np.ndarray]:
    """Eye and target of the tethered camera around a soldier standing at ``feet`` facing ``heading``."""
    target = np.asarray(feet, np.float64) + np.array([0.0, 0.0, LOOK_HEIGHT])
    behind = -coords.compass_to_direction(heading + state.azimuth)
    el = np.radians(state.elevation)
    eye = target + state.distance * (np.cos(el) * behind + np.array([0.0, 0.0, np.sin(el)]))
    return eye, target


def camera_pose(state: CameraState, feet: np.ndarray, heading: float, bounds: np.ndarray) -> np.ndarray:
    """The pose of the current view; ``bounds`` (2, 3) is the terrain's box (for the bird's eye)."""
    if state.view is View.SOLDIER_CAM or state.view is View.OVERHEAD:
        eye, target = tethered_eye(state, feet, heading)
        return look_at(eye, target)
    if state.view is View.FLY:
        d = coords.compass_to_direction(state.fly_heading)
        p = np.radians(state.fly_pitch)
        forward = np.cos(p) * d + np.array([0.0, 0.0, np.sin(p)])
        return look_at(state.fly_position, state.fly_position + forward)
    lo, hi = np.asarray(bounds, np.float64)
    centre = (lo + hi) / 2
    span = float(np.max(hi[:2] - lo[:2]))
    eye = centre + np.array([0.0, -0.55 * span, 0.45 * span])
    eye[2] = hi[2] + 0.35 * span
    return look_at(eye, centre)
