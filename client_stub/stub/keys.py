"""The stub's keyboard (seed 002, 4.2), as a pure mapping from keys to soldier and camera changes.

No window is needed: :meth:`StubController.handle` takes a key name (``"1"``, ``"n"``, ``"UP"``, ...) and
changes the :class:`~client_stub.stub.simsoldier.SimSoldiers` (whose next entity requests carry the change)
and the :class:`~client_stub.stub.camera.CameraState`; it returns the line to show, if any. The seed's keys
come first; the View menu of 1994's ``pickfly`` is keys ``b`` / ``c`` / ``f`` / ``v`` here, ``x`` is our
ACTION CAM (the current soldier and those near him, framed), and fly mode moves with ``w`` ``s`` ``q`` ``e``
``r`` ``g`` (our additions, listed by ``?`` too).
"""

from __future__ import annotations

import numpy as np

from client_stub.stub.camera import CameraState, View
from client_stub.stub.simsoldier import Force, SimSoldiers
from protocol.entity import Appearance, WeaponState

HEADING_STEP = 10.0
SPEED_STEP = 0.5
CAMERA_STEP = 5.0
SWING_STEP = 10.0

KEY_HELP: tuple[tuple[str, str], ...] = (
    ("1", "Set posture to DEAD on current soldier."),
    ("2", "Set posture to STANDING on current soldier."),
    ("3", "Set posture to KNEELING on current soldier."),
    ("4", "Set posture to PRONE on current soldier."),
    ("5", "Set weapon state to DEPLOYED on current soldier."),
    ("6", "Set weapon state to FIRING on current soldier."),
    ("n or N", "Next soldier."),
    ("p or P", "Previous soldier."),
    ("a", "Add another soldier, standing near the low office building."),
    ("A", "Add a Jack controlled soldier (reactive behaviours: not implemented)."),
    ("u or U", "Move the tethered camera AWAY from soldier by +5 meters."),
    ("d or D", "Move the tethered camera TOWARDS the soldier by -5 meters."),
    ("i or I", "Rotate tethered camera +10 degrees about current soldier."),
    ("j or J", "Rotate tethered camera -10 degrees about current soldier."),
    ("o or O", "Move tethered camera to OVERHEAD view on current soldier."),
    ("Left, Right Arrows", "Change heading -10 or +10 degrees on current soldier."),
    ("Up, Down Arrows", "Change velocity +0.5 or -0.5 meters/second on current soldier."),
    ("?", "Prints a list of keyboard commands to the stdout (console); shows or hides them on screen."),
    ("b / c / f / v", "View: bird's eye / SOLDIER CAM / fly / next view."),
    ("x", "View: ACTION CAM, the current soldier and the soldiers near him."),
    ("w s q e r g", "Fly: forward, back 5 m; turn -10, +10 degrees; up, down 2 m."),
)

_APPEARANCE = {"1": Appearance.DEAD, "2": Appearance.UPRIGHT, "3": Appearance.KNEEL, "4": Appearance.PRONE}
_WEAPON = {"5": WeaponState.DEPLOYED, "6": WeaponState.FIRING}
_FLY = {"w": (CAMERA_STEP, 0.0, 0.0), "s": (-CAMERA_STEP, 0.0, 0.0), "q": (0.0, 0.0, -SWING_STEP),
        "e": (0.0, 0.0, SWING_STEP), "r": (0.0, 2.0, 0.0), "g": (0.0, -2.0, 0.0)}  # fmt: skip
_VIEWS = [View.BIRDS_EYE, View.SOLDIER_CAM, View.OVERHEAD, View.FLY, View.ACTION]


def help_text() -> str:
    width = max(len(k) for k, _ in KEY_HELP)
    return "\n".join(f"{k:<{width}}  {text}" for k, text in KEY_HELP)


class StubController:
    """The current soldier and what the keys do to him and to the camera."""

    def __init__(
        self,
        soldiers: SimSoldiers,
        camera: CameraState | None = None,
        *,
        max_soldiers: int = 64,
        add_near: np.ndarray | None = None,
    ) -> None:
        self.soldiers = soldiers
        self.camera = camera if camera is not None else CameraState()
        self.current = 0
        self.max_soldiers = max_soldiers
        self.add_near = (
            np.asarray(add_near, np.float64) if add_near is not None else soldiers.terrain.landmark("office")
        )

    def handle(self, key: str) -> str | None:
        """Apply one key; returns a message for the console or None."""
        s = self.soldiers
        cur = self.current
        have = 0 <= cur < s.count
        if key in _APPEARANCE and have:
            s.set_appearance(cur, _APPEARANCE[key])
            return f"soldier {cur}: {_APPEARANCE[key].name}"
        if key in _WEAPON and have:
            s.set_weapon(cur, _WEAPON[key])
            return f"soldier {cur}: weapon {_WEAPON[key].name}"
        if key in ("LEFT", "RIGHT") and have:
            s.turn(cur, -HEADING_STEP if key == "LEFT" else HEADING_STEP)
            return f"soldier {cur}: heading {s.heading[cur]:.0f}"
        if key in ("UP", "DOWN") and have:
            s.accelerate(cur, SPEED_STEP if key == "UP" else -SPEED_STEP)
            return f"soldier {cur}: velocity {s.speed[cur]:+.1f} m/s"
        if key == "A":
            return "Jack controlled soldiers (reactive behaviours) are not implemented"
        k = key.lower() if len(key) == 1 else key
        if k in ("n", "p") and s.count:
            self.current = (cur + (1 if k == "n" else -1)) % s.count
            return f"current soldier {self.current}"
        if k == "a":
            return self._add()
        if k in ("u", "d", "i", "j", "o"):
            return self._tether(k)
        if k == "?":
            return help_text()
        if k in ("b", "c", "f", "v", "x"):
            return self._view(k)
        if k in _FLY and self.camera.view is View.FLY:
            self.camera.fly(*_FLY[k])
            return None
        return None

    def _add(self) -> str:
        s = self.soldiers
        if s.count >= self.max_soldiers:
            return f"no more soldiers: the maximum is {self.max_soldiers}"
        k = s.count
        offset = np.array([(k % 5) * 2.5 - 5.0, -((k // 5) % 4) * 2.5])
        slot = s.add(self.add_near + offset, 0.0, force=Force.FRIENDLY)
        self.current = slot
        return f"added soldier {slot} near the office building"

    def _tether(self, k: str) -> str:
        cam = self.camera
        if cam.view not in (View.SOLDIER_CAM, View.OVERHEAD):
            cam.tether()
        if k == "u":
            cam.away(CAMERA_STEP)
        elif k == "d":
            cam.away(-CAMERA_STEP)
        elif k == "i":
            cam.swing(SWING_STEP)
        elif k == "j":
            cam.swing(-SWING_STEP)
        else:
            cam.overhead()
        return (
            f"camera {cam.view.value}: {cam.distance:.0f} m, azimuth {cam.azimuth:.0f}, "
            f"elevation {cam.elevation:.0f}"
        )

    def _view(self, k: str) -> str:
        cam = self.camera
        if k == "b":
            cam.view = View.BIRDS_EYE
        elif k == "c":
            cam.tether()
        elif k == "f":
            cam.view = View.FLY
        elif k == "x":
            cam.action_view()
        else:
            cam.view = _VIEWS[(_VIEWS.index(cam.view) + 1) % len(_VIEWS)]
            cam.action = None
        return f"view: {cam.view.value}"
