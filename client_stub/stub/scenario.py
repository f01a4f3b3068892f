"""Scenario files: timed entity requests for one soldier, so a recorded stub video is a reproducible test.

A scenario is a small text file (``ttes stub --scenario FILE --record OUT.mp4``). One statement a line,
``#`` starts a comment, words are ``key=value``:

    soldier weapon=M16.fig x=0 y=0 heading=90     # who and where (all optional)
    camera azimuth=135 distance=5 elevation=8       # fixed world direction the camera looks from
    end 30                                           # seconds recorded (default: last event + 3 s)
    1.0  speed=1.4                                   # at 1.0 s: walk forward at 1.4 m/s
    5.0  speed=0                                     # stop
    8.0  turn=90                                     # heading +90 degrees (clockwise seen from above)
    12.0 speed=0.4 dir=-90                           # side-step left: velocity 90 degrees left of heading
    14.0 heading=0 posture=KNEEL weapon=FIRING       # absolute heading, any Appearance / WeaponState

An event's keys: ``speed`` (m/s), ``dir`` (degrees of the velocity from the heading: 0 ahead, 90 right,
-90 left, 180 back), ``heading`` (compass degrees) or ``turn`` (degrees added to it), ``posture`` (an
``Appearance`` name), ``weapon`` (a ``WeaponState`` name). What an event leaves out stays as it was. The
soldier's velocity turns with his heading (``dir`` is relative), as a DIS entity's would not: a scenario
says what the soldier does, not how a simulator encodes it. The camera follows the figure's root from a
fixed world azimuth (compass degrees it looks *from*), so turns show as turns and planted feet as still.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from protocol.entity import Appearance, WeaponState

DEFAULT_TAIL_S = 3.0  # seconds recorded after the last event when the file gives no ``end``
MAX_SECONDS = 3600.0
MAX_SPEED = 12.0  # m/s: faster is no soldier


class ScenarioError(ValueError):
    """A bad scenario file; names the line."""

    def __init__(self, message: str, line: int = 0) -> None:
        self.line = line
        super().__init__(f"line {line}: {message}" if line else message)


@dataclass(frozen=True)
class Event:
    """What changes at ``time`` seconds; ``None``: unchanged."""

    time: float
    speed: float | None = None
    direction: float | None = None  # degrees of the velocity from the heading
    heading: float | None = None
    turn: float | None = None
    posture: Appearance | None = None
    weapon: WeaponState | None = None


@dataclass(frozen=True)
class Camera:
    azimuth: float = 135.0  # compass degrees the camera looks from (135: from the south-east)
    distance: float = 5.0
    elevation: float = 8.0  # low, so the feet and the ground under them show


@dataclass(frozen=True)
class Start:
    figure: str = "DI.fig"
    weapon: str = "AK_47.fig"
    x: float = 0.0  # metres from the terrain's centre landmark
    y: float = 0.0
    heading: float = 0.0


@dataclass(frozen=True)
class Scenario:
    events: tuple[Event, ...] = ()
    start: Start = field(default_factory=Start)
    camera: Camera = field(default_factory=Camera)
    end: float | None = None

    @property
    def seconds(self) -> float:
        if self.end is not None:
            return self.end
        return (self.events[-1].time if self.events else 0.0) + DEFAULT_TAIL_S


_EVENT_KEYS = {"speed": "speed", "dir": "direction", "heading": "heading", "turn": "turn"}
_BOUNDS = {"speed": (0.0, MAX_SPEED), "direction": (-360.0, 360.0), "heading": (-360.0, 720.0),
           "turn": (-360.0, 360.0)}  # fmt: skip


def _number(text: str, what: str, line: int, lo: float, hi: float) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ScenarioError(f"{what}: {text!r} is not a number", line) from None
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ScenarioError(f"{what}: {text} is outside [{lo:g}, {hi:g}]", line)
    return value


def _pairs(words: list[str], line: int) -> dict[str, str]:
    out: dict[str, str] = {}
    for word in words:
        key, eq, value = word.partition("=")
        if not eq or not key or not value:
            raise ScenarioError(f"expected key=value, not {word!r}", line)
        if key in out:
            raise ScenarioError(f"{key} given twice", line)
        out[key] = value
    return out


def _enum(kind: type[Appearance] | type[WeaponState], text: str, line: int) -> Appearance | WeaponState:
    try:
        return kind[text.upper()]
    except KeyError:
        names = ", ".join(m.name for m in kind)
        raise ScenarioError(f"{text!r} is no {kind.__name__} ({names})", line) from None


def _event(time: float, pairs: dict[str, str], line: int) -> Event:
    values: dict[str, object] = {}
    for key, text in pairs.items():
        if key in _EVENT_KEYS:
            name = _EVENT_KEYS[key]
            values[name] = _number(text, key, line, *_BOUNDS[name])
        elif key == "posture":
            values["posture"] = _enum(Appearance, text, line)
        elif key == "weapon":
            values["weapon"] = _enum(WeaponState, text, line)
        else:
            raise ScenarioError(f"unknown event key {key!r}", line)
    if "heading" in values and "turn" in values:
        raise ScenarioError("heading and turn in one event", line)
    return Event(time, **values)  # type: ignore[arg-type]


def _settings(kind: type[Start] | type[Camera], pairs: dict[str, str], line: int) -> dict[str, object]:
    fields = {f: type(getattr(kind(), f)) for f in kind.__dataclass_fields__}
    out: dict[str, object] = {}
    for key, text in pairs.items():
        if key not in fields:
            raise ScenarioError(f"unknown key {key!r} (one of {', '.join(fields)})", line)
        if fields[key] is str:
            if not text.endswith(".fig") or "/" in text:
                raise ScenarioError(f"{key}: {text!r} is no figure file name", line)
            out[key] = text
        else:
            lo, hi = (0.5, 500.0) if key == "distance" else (-1e4, 1e4)
            out[key] = _number(text, key, line, lo, hi)
    return out


def parse_scenario(text: str) -> Scenario:
    """The scenario of a file's text (see the module docstring); ScenarioError names the bad line."""
    scenario = Scenario()
    events: list[Event] = []
    for number, raw in enumerate(text.splitlines(), 1):
        words = raw.split("#", 1)[0].split()
        if not words:
            continue
        head, rest = words[0], words[1:]
        if head == "end":
            if len(rest) != 1:
                raise ScenarioError("end takes one number of seconds", number)
            scenario = replace(scenario, end=_number(rest[0], "end", number, 0.0, MAX_SECONDS))
        elif head == "soldier":
            start = _settings(Start, _pairs(rest, number), number)
            scenario = replace(scenario, start=replace(scenario.start, **start))  # type: ignore[arg-type]
        elif head == "camera":
            camera = _settings(Camera, _pairs(rest, number), number)
            scenario = replace(scenario, camera=replace(scenario.camera, **camera))  # type: ignore[arg-type]
        else:
            time = _number(head, "time", number, 0.0, MAX_SECONDS)
            if events and time < events[-1].time:
                raise ScenarioError(f"time {time:g} is before the previous event's", number)
            if not rest:
                raise ScenarioError("an event says what changes", number)
            events.append(_event(time, _pairs(rest, number), number))
    return replace(scenario, events=tuple(events))


def load_scenario(path: str | Path) -> Scenario:
    """Read and parse a scenario file (ScenarioError: bad content, OSError: unreadable)."""
    return parse_scenario(Path(path).read_text(encoding="utf-8"))


def describe(e: Event) -> str:
    """An event's changes as the file writes them (``speed=1.4 dir=-90.0``)."""
    words = [
        f"{key}={getattr(e, name)!r}" for key, name in _EVENT_KEYS.items() if getattr(e, name) is not None
    ]
    words += [f"{key}={getattr(e, key).name}" for key in ("posture", "weapon") if getattr(e, key) is not None]
    return " ".join(words)


def format_scenario(scenario: Scenario) -> str:
    """The text of a scenario that :func:`parse_scenario` reads back as the same scenario."""
    s, c = scenario.start, scenario.camera
    lines = [
        f"soldier figure={s.figure} weapon={s.weapon} x={s.x!r} y={s.y!r} heading={s.heading!r}",
        f"camera azimuth={c.azimuth!r} distance={c.distance!r} elevation={c.elevation!r}",
    ]
    if scenario.end is not None:
        lines.append(f"end {scenario.end!r}")
    lines += [f"{e.time!r} {describe(e)}" for e in scenario.events]
    return "\n".join(lines) + "\n"
