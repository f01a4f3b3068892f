"""Channelset files (seed 002, Figure 6): ``*.chset.env`` Peabody text, read through the Peabody parser.

::

    channelset crawl2prstow.chset {
      size = 48;          // intervals: frames 0..48 (a file whose size counts frames, 0..47, reads too)
      fps = 60;
      count = 2;          // number of sharedchannels
      stride_length = 71.5;   // optional, locomotion clips: cm covered by the recorded step
      ground_speed = 143;     // optional: cm/s the step was recorded at
      release_frame = 40;     // optional: from this frame the hands no longer hold the rifle (deaths)
      end_offset = (0, 0, 90);  // optional: the entity's move over the clip (x cm, z cm, yaw deg, + = left)
      sharedchannel soldier {
        type = "sharedfigure";  protofiletype = "soldier_cam.fig";  object = "soldier";
        frame[0] = ("lower_torso.proximal", trans(31.68cm,43.53cm,-31.05cm));
        frame[1] = ("lower_torso.proximal", xyz(0deg,90deg,0deg) * trans(31.68cm,42.77cm,-31.05cm));
      }
      sharedchannel right.toes {
        type = "sharedjoint";  protofiletype = "soldier_cam.fig";  object = "right.toes";
        frame[0] = (0);   frame[1] = (0.1);     // radians (bare numbers), or with units (5deg)
      }
    }

Figure frames are ``(root site, transform)`` evaluated by :mod:`peabody.values` (``xyz(a,b,c) *
trans(x,y,z)`` is the frame rotated by ``Rx(a) Ry(b) Rz(c)`` placed at ``(x,y,z)``). Importing this module
registers the ``channelset`` block with the Peabody loader, so channelsets inside any environment file land
in ``env.extensions["channelset"][name]``.

Writing: ``size`` = number of intervals; joint angles and positions are written as the shortest decimal that
reads back to the same float32 (the data round-trips exactly); rotations as ``xyz`` angles in degrees with 6
decimals (about 2e-8 rad), so orientations round-trip within 1e-6 per quaternion component.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from peabody import quaternion
from peabody import values as V
from peabody.language import Assign, Block, Loc, Number, PeabodyError, Value, Vector, parse
from peabody.loader import LoadContext, register_block
from peabody.model import Environment
from server.motion.channelset import (
    CHANNEL_TYPES,
    Channelset,
    FigureTrack,
    JointTrack,
    make_channelset,
)
from server.motion.errors import ChannelsetError

_OPTIONAL_FIELDS = ("stride_length", "ground_speed")
_PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)*")


def _err(message: str, loc: Loc) -> ChannelsetError:
    return ChannelsetError(message, loc.file, loc.line, loc.col)


# --- reading -----------------------------------------------------------------------------------------------


def _int_field(a: Assign, what: str) -> int:
    v = V.number(a.value)
    if not (math.isfinite(v) and v == int(v) and v >= 0):
        raise _err(f"{what} must be a non-negative integer", a.value.loc)
    return int(v)


def _joint_frame(value: Value) -> list[float]:
    items = value.items if isinstance(value, Vector) else (value,)
    out = [it.value if isinstance(it, Number) and it.unit is None else V.number(it) for it in items]
    if not out:
        raise _err("a joint frame needs at least one angle", value.loc)
    return out


def _figure_frame(value: Value) -> tuple[str, np.ndarray]:
    if not isinstance(value, Vector) or len(value.items) != 2:
        raise _err('a figure frame is ("root.site", transform)', value.loc)
    root = V.string(value.items[0])
    m = V.transform(value.items[1])
    if not V.is_rigid(m, atol=1e-4):
        raise _err("a figure frame's transform must be a rotation and a translation", value.items[1].loc)
    return root, m


def _sharedchannel(block: Block) -> JointTrack | FigureTrack:
    fields: dict[str, str] = {}
    frames: dict[int, Assign] = {}
    for st in block.body:
        if isinstance(st, Assign) and st.owner is None and st.target == "frame" and st.index is not None:
            if st.index in frames:
                raise _err(f"frame[{st.index}] given twice", st.loc)
            frames[st.index] = st
        elif (
            isinstance(st, Assign)
            and st.owner is None
            and st.index is None
            and st.target
            in (
                "type",
                "protofiletype",
                "object",
            )
        ):
            if st.target in fields:
                raise _err(f"{st.target} given twice", st.loc)
            fields[st.target] = V.string(st.value)
        else:
            raise _err(f"unexpected statement in sharedchannel {block.name!r}", st.loc)
    ctype = fields.get("type")
    if ctype not in CHANNEL_TYPES:
        raise _err(f'sharedchannel {block.name!r}: type must be "sharedfigure" or "sharedjoint"', block.loc)
    if "protofiletype" not in fields:
        raise _err(f"sharedchannel {block.name!r} has no protofiletype", block.loc)
    if not frames:
        raise _err(f"sharedchannel {block.name!r} has no frames", block.loc)
    n = len(frames)
    if max(frames) != n - 1:
        missing = min(set(range(n)) - set(frames))
        raise _err(f"sharedchannel {block.name!r}: frame[{missing}] is missing", block.loc)
    order = [frames[i] for i in range(n)]
    ptype, obj = fields["protofiletype"], fields.get("object", block.name)
    if ctype == "sharedjoint":
        rows = [_joint_frame(a.value) for a in order]
        width = len(rows[0])
        for a, r in zip(order, rows, strict=True):
            if len(r) != width:
                raise _err(f"frame[{a.index}] has {len(r)} angles, frame[0] has {width}", a.loc)
        return JointTrack(block.name, ptype, obj, np.array(rows, dtype=np.float64))
    pairs = [_figure_frame(a.value) for a in order]
    return FigureTrack(block.name, ptype, obj, [p[0] for p in pairs], np.stack([p[1] for p in pairs]))


def channelset_from_block(block: Block) -> Channelset:
    """Build a channelset from a parsed ``channelset NAME { ... }`` block."""
    header: dict[str, Assign] = {}
    tracks: list[JointTrack | FigureTrack] = []
    for st in block.body:
        if isinstance(st, Block) and st.keyword == "sharedchannel":
            tracks.append(_sharedchannel(st))
        elif (
            isinstance(st, Assign)
            and st.owner is None
            and st.index is None
            and st.target in ("size", "fps", "count", "release_frame", "end_offset", *_OPTIONAL_FIELDS)
        ):
            if st.target in header:
                raise _err(f"{st.target} given twice", st.loc)
            header[st.target] = st
        else:
            raise _err(f"unexpected statement in channelset {block.name!r}", st.loc)
    if "fps" not in header:
        raise _err(f"channelset {block.name!r} has no fps", block.loc)
    fps = V.number(header["fps"].value)
    if not (math.isfinite(fps) and fps > 0):
        raise _err("fps must be a positive number", header["fps"].value.loc)
    if "count" in header and _int_field(header["count"], "count") != len(tracks):
        raise _err(
            f"count = {_int_field(header['count'], 'count')} but there are {len(tracks)} sharedchannels",
            header["count"].loc,
        )
    if not tracks:
        raise _err(f"channelset {block.name!r} has no sharedchannels", block.loc)
    nframes = {len(t.angles) if isinstance(t, JointTrack) else len(t.transforms) for t in tracks}
    if len(nframes) != 1:
        raise _err(f"channelset {block.name!r}: sharedchannels have different numbers of frames", block.loc)
    n = nframes.pop()
    if "size" in header:
        size = _int_field(header["size"], "size")
        if size not in (n - 1, n):  # intervals (what we write) or, tolerated, a frame count
            raise _err(f"size = {size} but the sharedchannels have frames 0..{n - 1}", header["size"].loc)
    extra: dict[str, Any] = {}
    for what in _OPTIONAL_FIELDS:
        if what in header:
            v = V.number(header[what].value)
            if not (math.isfinite(v) and v >= 0):
                raise _err(f"{what} must be a non-negative number", header[what].value.loc)
            extra[what] = v
    if "release_frame" in header:
        r = _int_field(header["release_frame"], "release_frame")
        if r >= n:
            raise _err(f"release_frame = {r} but the frames are 0..{n - 1}", header["release_frame"].loc)
        extra["release_frame"] = r
    if "end_offset" in header:
        value = header["end_offset"].value
        try:
            extra["end_offset"] = tuple(V.numbers(value, 3, "numbers (x cm, z cm, yaw deg)"))
        except PeabodyError as exc:
            raise _err(f"end_offset: {exc.message}", value.loc) from None
    try:
        chset = make_channelset(block.name, fps, tracks, block.loc.file)
    except ChannelsetError as exc:
        raise _err(exc.message, block.loc) from None
    return dataclasses.replace(chset, **extra) if extra else chset


def _decode(data: str | bytes, filename: str) -> str:
    if isinstance(data, str):
        return data
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ChannelsetError("not UTF-8 text", filename, line) from None


def parse_channelsets(data: str | bytes, filename: str = "<string>") -> list[Channelset]:
    """Every channelset in Peabody text (str or UTF-8 bytes) that holds only channelset blocks."""
    text = _decode(data, filename)
    out: list[Channelset] = []
    for st in parse(text, filename):
        if not (isinstance(st, Block) and st.keyword == "channelset"):
            raise _err("a channelset file holds only 'channelset NAME { ... }' blocks", st.loc)
        out.append(channelset_from_block(st))
    return out


def read_channelset(path: str | Path) -> Channelset:
    """The one channelset in a ``.chset.env`` file (``cache.load_channelset`` caches it)."""
    path = Path(path)
    found = parse_channelsets(path.read_bytes(), str(path))
    if len(found) != 1:
        raise ChannelsetError(f"expected one channelset, found {len(found)}", str(path), 1)
    return found[0]


def _handler(block: Block, env: Environment, ctx: LoadContext) -> None:
    chset = channelset_from_block(block)
    env.extensions.setdefault("channelset", {})[chset.name] = chset


# --- writing -----------------------------------------------------------------------------------------------


def _name(name: str) -> str:
    if _PLAIN_NAME.fullmatch(name):
        return name
    return _string(name)


def _string(s: str) -> str:
    if "\n" in s:
        raise ChannelsetError(f"cannot write a name with a newline: {s!r}")
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _num(x: np.floating) -> str:
    return np.format_float_positional(np.float32(x), unique=True, trim="-")


def _fps_text(fps: float) -> str:
    return str(int(fps)) if float(fps).is_integer() else repr(float(fps))


def format_channelset(chset: Channelset) -> str:
    """Peabody text for ``chset`` that :func:`parse_channelsets` reads back (see the module docstring)."""
    out = [
        f"channelset {_name(chset.name)} {{",
        f"  size = {chset.size};",
        f"  fps = {_fps_text(chset.fps)};",
        f"  count = {chset.count};",
    ]
    for what in _OPTIONAL_FIELDS:
        v = getattr(chset, what)
        if v is not None:
            out.append(f"  {what} = {_fps_text(v)};")
    if chset.release_frame is not None:
        out.append(f"  release_frame = {chset.release_frame};")
    if chset.end_offset is not None:
        out.append(f"  end_offset = ({', '.join(_fps_text(round(v, 4)) for v in chset.end_offset)});")
    for c in chset.channels:
        kind = "figure position" if c.is_figure else "joint angles"
        out += [
            f"  sharedchannel {_name(c.name)} {{ /* {kind} */",
            f"    type = {_string(c.type)};",
            f"    protofiletype = {_string(c.protofiletype)};",
            f"    object = {_string(c.object)};",
        ]
        if c.is_joint:
            a = chset.angles(c)
            for i, row in enumerate(a):
                out.append(f"    frame[{i}] = ({', '.join(_num(v) for v in row)});")
        else:
            k = c.column
            mats = quaternion.to_matrix(chset.fig_quat[:, k])
            for i in range(chset.nframes):
                site = _string(chset.root_names[chset.fig_root[i, k]])
                p = chset.fig_pos[i, k]
                tr = f"trans({_num(p[0])}cm,{_num(p[1])}cm,{_num(p[2])}cm)"
                if chset.fig_quat[i, k, 1:].any():
                    rx, ry, rz = (math.degrees(x) for x in V.matrix_to_xyz(mats[i]))
                    tr = f"xyz({rx:.6f}deg,{ry:.6f}deg,{rz:.6f}deg) * {tr}"
                out.append(f"    frame[{i}] = ({site}, {tr});")
        out.append("  }")
    out.append("}")
    return "\n".join(out) + "\n"


def save_channelset(chset: Channelset, path: str | Path) -> None:
    Path(path).write_text(format_channelset(chset), encoding="utf-8")


register_block("channelset", _handler, lambda name, obj: format_channelset(obj))  # type: ignore[arg-type]

__all__ = [
    "PeabodyError",
    "channelset_from_block",
    "format_channelset",
    "parse_channelsets",
    "read_channelset",
    "save_channelset",
]
