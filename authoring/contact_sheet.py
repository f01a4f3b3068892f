"""Contact sheets: every posture and a strip of frames from every clip in one PNG, for a person to look at.

Offscreen OpenGL through pyrender (headless EGL: ``PYOPENGL_PLATFORM=egl``, Mesa's llvmpipe is enough). The
soldier and the rifle are drawn from their psurfs (one pyrender node per segment, placed by batched FK of
the recorded poses and figure channels), on a checkered ground plane (50 cm squares, so sliding feet and
strides can be judged), with the same camera orientation and distance in every tile, aimed at the middle of
what the tile shows: a three-quarter view from the soldier's front left (``quarter``: strides and sliding
against the checkerboard), or a ``side`` view from his left or a ``front`` view with the eye just above the
ground (``EYE_HEIGHT``), so that a hovering body shows daylight under it and what touches the ground sits on
the horizon, or a ``top`` view from above (a turn on the ground); several views give each posture one tile
per view and each clip one row per view. The camera
backs off until the body fits. Labels are drawn with Pillow.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from authoring.quality import BACKWARD_WORDS, clip_matches
from peabody.fk import FigureKinematics
from peabody.model import Figure
from server.motion.channelset import Channelset

CAMERA_DIRECTION = np.array([-0.55, 0.38, -0.74])  # from the target towards the camera (front left, above)
# per view, from the target towards the camera; the soldier faces -Z, his left is -X
VIEWS: dict[str, np.ndarray] = {
    "quarter": CAMERA_DIRECTION,
    "side": np.array([-1.0, 0.0, 0.0]),
    "front": np.array([0.0, 0.0, -1.0]),
    "top": np.array([0.0, 1.0, 0.08]),  # from above, a little behind him: his front is up (ground turns)
}
GROUND_LEVEL_VIEWS = (
    "side",
    "front",
)  # the eye just above the ground: a body hovering shows daylight under it
EYE_HEIGHT = 2.0  # cm
CAMERA_DISTANCE = 340.0  # cm
CAMERA_YFOV = np.radians(38.0)
GROUND_SQUARE = 50.0  # cm
GROUND_HALF = 1500.0  # cm
BACKGROUND = (236, 238, 242)
LABEL_HEIGHT = 22


class ContactSheetError(Exception):
    """Nothing to render, or no offscreen OpenGL."""


@dataclass
class SheetClip:
    """One row of the sheet: a label and a channelset."""

    label: str
    channelset: Channelset


@dataclass
class SheetPosture:
    """One posture tile: a label, a channelset and the frame that shows the posture."""

    label: str
    channelset: Channelset
    frame: int


def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera pose (OpenGL: looks down its -Z, +Y up) at ``eye`` looking at ``target``."""
    f = target - eye
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -f, eye
    return m


def _ground_mesh() -> Any:
    """A checkerboard quad grid at y = 0 (own vertices per square, so vertex colours stay crisp)."""
    import trimesh

    k = int(2 * GROUND_HALF / GROUND_SQUARE)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    x0 = -GROUND_HALF + i.ravel() * GROUND_SQUARE
    z0 = -GROUND_HALF + j.ravel() * GROUND_SQUARE
    n = len(x0)
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64) * GROUND_SQUARE
    v = np.zeros((n, 4, 3))
    v[..., 0] = x0[:, None] + corners[:, 0]
    v[..., 2] = z0[:, None] + corners[:, 1]
    base = np.arange(n)[:, None] * 4
    faces = np.concatenate([base + np.array([0, 2, 1]), base + np.array([0, 3, 2])])  # normals up (+Y)
    dark = ((i + j).ravel() % 2 == 0)[:, None]
    col = np.where(dark, [[178, 182, 170, 255]], [[204, 207, 196, 255]]).astype(np.uint8)
    colours = np.repeat(col, 4, axis=0)
    return trimesh.Trimesh(v.reshape(-1, 3), faces, vertex_colors=colours, process=False)


class _FigureNodes:
    """pyrender nodes for one figure's segments and how to place them from poses and root globals."""

    def __init__(self, scene: Any, figure: Figure) -> None:
        import pyrender

        from peabody.psurf import psurf_to_trimesh

        self.figure = figure
        self.kin = FigureKinematics(figure)
        self.nodes: list[tuple[int, Any, np.ndarray]] = []
        self.local_points: list[np.ndarray] = []
        for i, name in enumerate(self.kin.segment_names):
            seg = figure.segments[name]
            if seg.psurf is None or not len(seg.psurf.nodes):
                continue
            mesh = psurf_to_trimesh(seg.psurf)
            pm = pyrender.Mesh.from_trimesh(mesh, smooth=False)
            node = scene.add(pm, pose=np.eye(4))
            offset = np.eye(4) if seg.psurf_transform is None else np.asarray(seg.psurf_transform, np.float64)
            self.nodes.append((i, node, offset))
            pts = np.c_[np.asarray(seg.psurf.nodes, np.float64).reshape(-1, 3), np.ones(len(seg.psurf.nodes))]
            self.local_points.append((offset @ pts.T).T)

    def globals(self, poses: np.ndarray, locations: np.ndarray) -> np.ndarray:
        return self.kin.segment_globals(poses, locations)

    def place(self, scene: Any, segs: np.ndarray) -> None:
        for i, node, offset in self.nodes:
            scene.set_pose(node, segs[i] @ offset)

    def points(self, segs: np.ndarray) -> np.ndarray:
        """World mesh nodes for one frame's segment globals (for framing the camera)."""
        out = [(segs[i] @ p.T).T[:, :3] for (i, _, _), p in zip(self.nodes, self.local_points, strict=True)]
        return np.concatenate(out) if out else np.zeros((0, 3))


def _play(channelset: Channelset, figures: Sequence[Figure]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per figure name: poses ``(n, ndof)`` and root globals ``(n, 4, 4)`` of every frame."""
    from authoring.slaving import create_channelset_motion

    used = {c.protofiletype for c in channelset.channels}
    figs = [f for f in figures if f.filename and Path(f.filename).name in used]
    rec = create_channelset_motion(channelset, figs)
    return {
        f.name: (np.asarray(rec.poses[f.name], np.float64), np.asarray(rec.locations[f.name], np.float64))
        for f in figs
    }


def _font(size: int) -> Any:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # very old Pillow without scalable default font
        return ImageFont.load_default()


def render_contact_sheet(
    figure_files: Sequence[str | os.PathLike[str]] | Sequence[Figure],
    clips: Sequence[SheetClip | Channelset],
    out_png: str | os.PathLike[str],
    *,
    postures: Sequence[SheetPosture] = (),
    frames_per_clip: int = 6,
    tile: int = 200,
    title: str | None = None,
    ground_motion: bool = True,
    views: Sequence[str] = ("quarter",),
) -> dict[str, Any]:
    """Render ``postures`` (one tile each per view) and ``frames_per_clip`` evenly spaced frames of every clip
    (one row each per view, first to last frame) into ``out_png``. ``figure_files``: the soldier figure and
    its rifle (paths or loaded figures with psurfs). With ``ground_motion`` a clip that records a
    ``ground_speed`` is drawn travelling (along -Z, +Z for backward clips) as the entity would. ``views``:
    names from ``VIEWS``. Returns a summary (size, rows, tiles)."""
    unknown = [v for v in views if v not in VIEWS]
    if unknown or not views:
        raise ContactSheetError(
            f"unknown view {unknown[0] if unknown else None!r}; views: {', '.join(VIEWS)}"
        )
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    try:
        import pyrender
    except Exception as exc:  # pragma: no cover - depends on the machine's OpenGL
        raise ContactSheetError(f"pyrender/OpenGL unavailable: {exc}") from exc
    from PIL import Image, ImageDraw

    from peabody.loader import read_figure

    rows = [c if isinstance(c, SheetClip) else SheetClip(c.name, c) for c in clips]
    if not rows and not postures:
        raise ContactSheetError("nothing to render: no clips and no postures")
    figures = [f if isinstance(f, Figure) else read_figure(f) for f in figure_files]
    scene = pyrender.Scene(bg_color=[c / 255 for c in BACKGROUND] + [1.0], ambient_light=[0.38] * 3)
    scene.add(pyrender.Mesh.from_trimesh(_ground_mesh(), smooth=False))
    placed = {f.name: _FigureNodes(scene, f) for f in figures}
    camera = pyrender.PerspectiveCamera(yfov=float(CAMERA_YFOV), znear=10.0, zfar=5000.0)
    cam_node = scene.add(camera, pose=np.eye(4))
    key = pyrender.DirectionalLight(color=np.ones(3), intensity=3.2)
    key_node = scene.add(key, pose=np.eye(4))
    fill = pyrender.DirectionalLight(color=np.ones(3), intensity=1.2)
    scene.add(fill, pose=_look_at(np.array([300.0, 200.0, 250.0]), np.zeros(3)))
    try:
        renderer = pyrender.OffscreenRenderer(tile, tile)
    except Exception as exc:  # pragma: no cover - depends on the machine's OpenGL
        raise ContactSheetError(f"no offscreen OpenGL context ({exc}); set PYOPENGL_PLATFORM=egl") from exc

    def draw(
        states: Mapping[str, np.ndarray],
        frames: Sequence[int],
        aim: tuple[np.ndarray, np.ndarray],
        view: str,
    ):
        images = []
        target, corners = aim
        if view in GROUND_LEVEL_VIEWS:  # aim at the middle of the body, however low it lies
            target = np.r_[target[0], corners[:, 1].mean(), target[2]]
        toward = VIEWS[view] / np.linalg.norm(VIEWS[view])
        rel = corners - target  # back off until what the tile shows fits (a body lying towards the camera)
        along = rel @ toward
        across = np.linalg.norm(rel - along[:, None] * toward, axis=1)
        fit = (along + 1.1 * across / np.tan(CAMERA_YFOV / 2.0)).max()
        eye = target + toward * max(CAMERA_DISTANCE, float(fit))
        if view in GROUND_LEVEL_VIEWS:
            eye[1] = EYE_HEIGHT
        pose = _look_at(eye, target)
        scene.set_pose(cam_node, pose)
        scene.set_pose(key_node, _look_at(eye + np.array([0.0, 200.0, 0.0]), target))
        for name in placed:  # figures a clip does not drive are hidden
            for _, node, _ in placed[name].nodes:
                node.mesh.is_visible = name in states
        for k in frames:
            for name, segs in states.items():
                placed[name].place(scene, segs[k])
            color, _ = renderer.render(scene)
            images.append(Image.fromarray(color))
        return images

    def segment_states(cs: Channelset) -> dict[str, np.ndarray]:
        played = _play(cs, figures)
        speed = cs.ground_speed if ground_motion else None
        if speed:  # in-place locomotion: put the entity's travel back so strides cross the checkerboard
            sign = 1.0 if any(w in cs.name.lower() for w in BACKWARD_WORDS) else -1.0
            travel = sign * speed * np.arange(cs.nframes) / cs.fps
            for _, loc in played.values():
                loc[:, 2, 3] += travel
        return {n: placed[n].globals(q, loc) for n, (q, loc) in played.items() if n in placed}

    def centre(states: Mapping[str, np.ndarray], frames: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """The camera's target and the corners of the box the body sweeps over ``frames``."""
        body = max(states, key=lambda n: placed[n].kin.ndof)
        pts = np.concatenate([placed[body].points(states[body][k]) for k in frames])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        c = (lo + hi) / 2.0
        c[1] = max(c[1], 45.0)
        corners = np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )
        return c, corners

    font = _font(13)
    small = _font(11)
    label_w = 170
    tiles = [(p, v) for p in postures for v in views]
    ncols = max(frames_per_clip, min(len(tiles), 8) if tiles else 0)
    width = label_w + ncols * tile
    posture_rows = (len(tiles) + ncols - 1) // ncols if tiles else 0
    title_h = 30 if title else 0
    section_h = LABEL_HEIGHT
    height = title_h + (section_h + posture_rows * (tile + LABEL_HEIGHT) if postures else 0)
    height += (section_h if rows else 0) + len(rows) * len(views) * (tile + LABEL_HEIGHT)
    sheet = Image.new("RGB", (width, height), BACKGROUND)
    pen = ImageDraw.Draw(sheet)
    y = 0
    if title:
        pen.text((8, 7), title, fill=(20, 20, 20), font=_font(17))
        y = title_h
    if postures:
        pen.text((8, y + 4), "postures", fill=(60, 60, 60), font=font)
        y += section_h
        for i, (p, view) in enumerate(tiles):
            states = segment_states(p.channelset)
            frame = min(max(p.frame, 0), p.channelset.nframes - 1)
            img = draw(states, [frame], centre(states, [frame]), view)[0]
            r, c = divmod(i, ncols)
            x0, y0 = label_w + c * tile, y + r * (tile + LABEL_HEIGHT)
            sheet.paste(img, (x0, y0 + LABEL_HEIGHT))
            label = p.label if len(views) == 1 else f"{p.label} ({view})"
            pen.text((x0 + 4, y0 + 4), label, fill=(20, 20, 20), font=font)
        y += posture_rows * (tile + LABEL_HEIGHT)
    if rows:
        pen.text((8, y + 4), "clips (first to last frame)", fill=(60, 60, 60), font=font)
        y += section_h
    for row in rows:
        cs = row.channelset
        states = segment_states(cs)
        frames = np.unique(np.linspace(0, cs.nframes - 1, frames_per_clip).round().astype(int)).tolist()
        aim = centre(states, frames)
        for view in views:
            images = draw(states, frames, aim, view)
            pen.text((8, y + LABEL_HEIGHT + 6), row.label, fill=(20, 20, 20), font=font)
            pen.text(
                (8, y + LABEL_HEIGHT + 24),
                f"{cs.duration:.2f} s, {cs.nframes} frames",
                fill=(90, 90, 90),
                font=small,
            )
            if len(views) > 1:
                pen.text((8, y + LABEL_HEIGHT + 40), f"{view} view", fill=(90, 90, 90), font=small)
            for c, (k, img) in enumerate(zip(frames, images, strict=True)):
                x0 = label_w + c * tile
                sheet.paste(img, (x0, y + LABEL_HEIGHT))
                pen.text((x0 + 4, y + 5), f"t = {k / cs.fps:.2f} s", fill=(60, 60, 60), font=small)
            y += tile + LABEL_HEIGHT
    renderer.delete()
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(out, optimize=True)
    return {
        "out": str(out),
        "width": width,
        "height": height,
        "postures": [p.label for p in postures],
        "clips": [r.label for r in rows],
        "views": list(views),
        "tiles": len(views) * (len(postures) + sum(min(frames_per_clip, r.channelset.nframes) for r in rows)),
    }


def library_sheet_inputs(
    graphs: Sequence[str | os.PathLike[str]], figure_type: str, clips_pattern: str | None = None
) -> tuple[list[SheetPosture], list[SheetClip], list[str]]:
    """From posture graph files: the clips that drive ``figure_type`` (e.g. ``"DI.fig"``) and match
    ``clips_pattern`` (see :func:`clip_matches`), one posture tile per graph node those clips reach (the
    frame where an arc leaves it, else where one arrives), and every figure type used."""
    from server.motion.posture_change import load_posture_graph

    postures: dict[str, SheetPosture] = {}
    clips: dict[str, SheetClip] = {}
    types: set[str] = set()
    for g in map(Path, graphs):
        loaded = load_posture_graph(g)
        used = [
            figure_type in {c.protofiletype for c in cs.channels} and clip_matches(f, clips_pattern)
            for cs, f in zip(loaded.channelsets, loaded.graph.files, strict=True)
        ]
        if not any(used):
            continue
        for cs, fname, ok in zip(loaded.channelsets, loaded.graph.files, used, strict=True):
            if ok:
                types.update(c.protofiletype for c in cs.channels)
                clips.setdefault(str((g.parent / fname).resolve()), SheetClip(Path(fname).name, cs))
        for arc in loaded.graph.arcs:
            cs = loaded.channelsets[arc.channelset]
            if not used[arc.channelset]:
                continue
            leave = 0 if arc.forward else cs.nframes - 1
            postures.setdefault(arc.start, SheetPosture(arc.start, cs, leave))
        for arc in loaded.graph.arcs:
            cs = loaded.channelsets[arc.channelset]
            if used[arc.channelset] and arc.end not in postures:
                postures[arc.end] = SheetPosture(arc.end, cs, cs.nframes - 1 if arc.forward else 0)
    return list(postures.values()), list(clips.values()), sorted(types)
