"""The stub's views (seed 002, 4.1–4.3): bird's eye, SOLDIER CAM (tethered), overhead, fly; and ours,
ACTION CAM, which frames the current soldier and the soldiers near him (:func:`frame_points`: every one of
them inside the picture, as close as that allows), follows them smoothly and rises over what hides them.

The tethered camera keeps a distance and an azimuth relative to the current soldier's heading (azimuth 0
is behind him) and an elevation; keys move it away/towards by 5 m and swing it by 10°. ``o`` raises it
overhead; swinging (``i``/``j``) from overhead also brings it down 10° a press, so "press [i] again until you
are looking at him from the side" (4.3) works. Poses are pyrender camera poses: the camera looks along its
own -Z with +Y up, in Performer axes (+Z up).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from client_stub.crowd.camera import perspective
from protocol import coords

TETHER_ELEVATION = 15.0  # degrees: the normal tethered view
OVERHEAD_ELEVATION = 85.0
MIN_DISTANCE = 2.0
LOOK_HEIGHT = 1.0  # metres above the feet the tethered camera looks at
ACTION_RADIUS_M = 10.0  # ACTION CAM frames the soldiers this near the current one
ACTION_EASE = 0.2  # fraction of the way to its new framing the ACTION CAM moves each frame
ACTION_CUT_M = 15.0  # ... unless that moved this far: then it cuts there (no glide over empty ground)
ACTION_COMPASS = 200.0  # ACTION CAM looks from this compass direction (south-south-west) ...
ACTION_ELEVATION = 35.0  # ... and this many degrees above the horizon
SOLDIER_HEIGHT_M = 1.9
ACTION_TURN_SECONDS = 10.0  # a touring ACTION CAM turns to a soldier of the next force this often


class View(Enum):
    BIRDS_EYE = "bird's eye"
    SOLDIER_CAM = "SOLDIER CAM"
    OVERHEAD = "overhead"
    FLY = "fly"
    ACTION = "ACTION CAM"


@dataclass
class CameraState:
    view: View = View.BIRDS_EYE
    distance: float = 6.0
    azimuth: float = 0.0  # degrees, clockwise from behind the soldier
    elevation: float = TETHER_ELEVATION
    fly_position: np.ndarray = field(default_factory=lambda: np.array([0.0, -60.0, 20.0]))
    fly_heading: float = 0.0
    fly_pitch: float = -15.0
    action: np.ndarray | None = None  # ACTION CAM's eased box (low x y z, high x y z); None: jump to the next
    action_tour: bool = False  # ACTION CAM turns from force to force (replays); keys that move it stop it

    def action_view(self) -> None:
        self.view = View.ACTION
        self.action = None

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


def viewproj(pose: np.ndarray, yfov_deg: float, aspect: float) -> np.ndarray:
    """World → clip for a camera-to-world ``pose``."""
    return perspective(yfov_deg, aspect) @ np.linalg.inv(np.asarray(pose, np.float64))


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The 8 corners of the axis-aligned box ``lo``..``hi``."""
    return np.array(
        [[(hi if i & 1 else lo)[0], (hi if i & 2 else lo)[1], (hi if i & 4 else lo)[2]] for i in range(8)]
    )


def frame_points(
    points: np.ndarray,
    yfov_deg: float,
    aspect: float,
    compass: float = ACTION_COMPASS,
    elevation: float = ACTION_ELEVATION,
    min_distance: float = 4.0,
    fill: float = 0.85,
) -> np.ndarray:
    """The camera pose that looks from ``compass``/``elevation`` at the middle of ``points`` (n, 3) from as
    close as keeps every one of them inside the middle ``fill`` of the picture (each point's own depth)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    el = np.radians(elevation)
    back = np.cos(el) * coords.compass_to_direction(compass) + np.array([0.0, 0.0, np.sin(el)])
    axes = look_at(back, np.zeros(3))[:3, :3]  # columns: right, up, backwards
    q = (p - centre) @ axes
    tan_y = fill * np.tan(np.radians(yfov_deg) / 2)
    tan_x = aspect * tan_y
    need = np.maximum(np.abs(q[:, 0]) / tan_x, np.abs(q[:, 1]) / tan_y) + q[:, 2]  # depth = d - q_back
    distance = max(min_distance, float(need.max()))
    return look_at(centre + distance * back, centre)


def clear_pose(
    points: np.ndarray,
    yfov_deg: float,
    aspect: float,
    height: Callable[[np.ndarray], np.ndarray] | None = None,
    elevations: tuple[float, ...] = (ACTION_ELEVATION, 50.0, 65.0, 80.0),
) -> np.ndarray:
    """:func:`frame_points` at the lowest of ``elevations`` from which the line of sight to the middle
    clears the ground and the roofs (``height``: ground height under (n, 2) points), else the highest."""
    pose = frame_points(points, yfov_deg, aspect)
    if height is None:
        return pose
    p = np.asarray(points, np.float64).reshape(-1, 3)
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    t = np.linspace(0.0, 0.9, 19)[:, None]
    for elevation in elevations:
        pose = frame_points(points, yfov_deg, aspect, elevation=elevation)
        sight = pose[:3, 3] + t * (centre - pose[:3, 3])
        if np.all(height(sight[:, :2]) < sight[:, 2] - 0.3):
            break
    return pose


def action_pose(
    state: CameraState,
    points: np.ndarray,
    yfov_deg: float,
    aspect: float,
    height: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """ACTION CAM: eases ``state.action`` (a box: low and high corner) towards the box of ``points`` (the
    soldiers in the action; a cut when they are elsewhere) and frames its corners from where the ground does
    not hide them."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    target = np.concatenate([p.min(axis=0), p.max(axis=0)])
    middle = (target[:3] + target[3:]) / 2
    if (
        state.action is None
        or np.linalg.norm((state.action[:3] + state.action[3:]) / 2 - middle) > ACTION_CUT_M
    ):
        state.action = target
    else:
        state.action = state.action + ACTION_EASE * (target - state.action)
    return clear_pose(box_corners(state.action[:3], state.action[3:]), yfov_deg, aspect, height)


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
