"""``ttes crowd``: thousands of soldiers on the terrain, rendered offscreen, with frame-rate statistics.

Per frame: the pose source updates its :class:`~client_stub.crowd.sources.CrowdState`; each soldier is
culled against the view frustum and given a level of detail by distance; the *local* part matrices of the
near and mid levels (every body part in the soldier's frame) are recomputed only for soldiers whose pose
changed, or that just entered the level (:class:`CrowdRenderer` caches them per level); one product with
each soldier's entity transform gives the world matrices; :class:`~client_stub.crowd.gl.CrowdGL` draws.
The frame time measured is all of that, up to ``glFinish``; reading pixels back and encoding the output file
are not part of it.
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from client_stub.crowd.camera import FreeCamera, orbit
from client_stub.crowd.fk import F32, FastFigure, entity_transforms, mul
from client_stub.crowd.lod import (
    FAR,
    LEVEL_NAMES,
    MID,
    NEAR,
    LodModel,
    body_bounds,
    choose_levels,
    dof_map,
    figure_model,
    impostor_for,
    visible,
)
from client_stub.crowd.sources import CrowdState
from client_stub.data_paths import CROWD_DATA, STUB_DATA
from client_stub.link.auth import Credentials
from client_stub.stub.scene_graph import FigureGraph
from client_stub.stub.tips import TipsFigure, load_tips

log = logging.getLogger("ttes.crowd")
NEAR_TIPS = CROWD_DATA / "soldier.tips"
MID_TIPS = STUB_DATA / "DI.tips"
RIFLE_TIPS = STUB_DATA / "AK_47.tips"
PALM_SITE = "right_palm.palmcenter"
GRIP_SITE = "root.grip"


@dataclass
class CrowdConfig:
    soldiers: int = 1000
    seconds: float = 10.0
    width: int = 1280
    height: int = 720
    out: str | None = None  # .png (last frame) or .mp4 (every frame)
    source: str = "offline"  # offline | server
    host: str = "127.0.0.1"
    port: int = 7000
    spawn_server: bool = False
    server_data: str = "auto"
    clients: int = 2
    mix: str = "realistic"
    seed: int = 1
    spacing: float = 3.0
    centre: tuple[float, float] | None = None  # default: the terrain's "fields" side of the centre
    near_m: float = 10.0
    mid_m: float = 30.0
    camera: str = "orbit"  # orbit | fixed
    camera_pose: tuple[float, ...] | None = None  # x, y, z, heading, pitch (fixed camera)
    terrain: str | None = None  # default: client_stub/data/village.glb; "none" for no terrain
    max_frames: int = 100_000
    video_fps: float = 10.0
    warmup_frames: int = 2  # not counted in the frame-time statistics (first uploads, shader JIT)
    credentials: Credentials = field(default_factory=Credentials)  # token / TLS for a server's connections

    def check(self) -> None:
        if self.soldiers < 1:
            raise ValueError("--soldiers must be at least 1")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError("--seconds must be > 0")
        if not (16 <= self.width <= 8192 and 16 <= self.height <= 8192):
            raise ValueError("image size must be 16..8192 pixels")
        if self.source not in ("offline", "server"):
            raise ValueError("source must be offline or server")
        if self.out and Path(self.out).suffix.lower() not in (".png", ".mp4"):
            raise ValueError("--out must end in .png or .mp4")
        if not 0 < self.near_m <= self.mid_m:
            raise ValueError("level distances must satisfy 0 < near <= mid")


@dataclass
class Figures:
    """The three figures of the crowd, loaded from TIPS files (the client never reads Peabody files)."""

    near: FigureGraph
    mid: FigureGraph
    rifle: FigureGraph
    mid_tips: TipsFigure
    rifle_tips: TipsFigure
    near_is_soldier: bool

    @classmethod
    def load(cls, near: Path = NEAR_TIPS, mid: Path = MID_TIPS, rifle: Path = RIFLE_TIPS) -> Figures:
        mid_t = load_tips(mid).figures[0]
        rifle_t = load_tips(rifle).figures[0]
        if near.is_file():
            near_g, is_soldier = FigureGraph(load_tips(near).figures[0]), True
        else:
            log.warning("%s missing (run `ttes crowd prepare`): the near level uses DI.fig", near)
            near_g, is_soldier = FigureGraph(mid_t), False
        return cls(near_g, FigureGraph(mid_t), FigureGraph(rifle_t), mid_t, rifle_t, is_soldier)


class _Level:
    """One body level's figure, mesh, DOF mapping and cache of local part matrices."""

    def __init__(self, name: str, body: FigureGraph, rifle: FastFigure, mid: FigureGraph, n: int) -> None:
        self.body = FastFigure(body)
        self.rifle = rifle
        self.model: LodModel = figure_model(name, [body, rifle.graph], boxed=(False, name == "mid"))
        self.map = None if body is mid else dof_map(mid, body)
        body_parts = [node for f, node in self.model.parts if f == 0]
        self.body_part_nodes = np.array(body_parts, np.int64)
        self.rifle_part = [k for k, (f, _) in enumerate(self.model.parts) if f == 1]
        palm = body.sites.get(PALM_SITE)
        self.palm = None if palm is None else (palm[0] + 1, palm[1][:3, 3].astype(F32))
        grip = rifle.graph.sites.get(GRIP_SITE)
        self.grip = np.zeros(3, F32) if grip is None else grip[1][:3, 3].astype(F32)
        self.cache = np.zeros((n, len(self.model.parts), 3, 4), F32)
        self.valid = np.zeros(n, bool)

    def refresh(self, rows: np.ndarray, st: CrowdState) -> None:
        """Recompute the local part matrices of ``rows`` (the batched FK)."""
        if not len(rows):
            return
        q = st.dofs[rows] if self.map is None else st.dofs[rows] @ self.map.T
        nodes = self.body.local_nodes(q, st.placement[rows, 0])
        nbody = len(self.body_part_nodes)
        self.cache[rows, :nbody] = nodes[:, self.body_part_nodes]
        if self.rifle_part:
            place = st.placement[rows, 1].copy()
            palm_rows = np.flatnonzero(st.rifle_from_palm[rows])
            if len(palm_rows) and self.palm is not None:
                node, offset = self.palm
                m = nodes[palm_rows, node]
                place[palm_rows] = 0.0
                place[palm_rows, 0, 0] = place[palm_rows, 1, 1] = place[palm_rows, 2, 2] = 1.0
                place[palm_rows, :, 3] = m[:, :, :3] @ offset + m[:, :, 3] - self.grip
            self.cache[rows, self.rifle_part[0]] = mul(place, self.rifle.root_inverse)
        self.valid[rows] = True


class CrowdRenderer:
    """CPU side of the crowd: culling, levels of detail, cached FK, instance matrices; owns a CrowdGL. A
    :class:`client_stub.renderer.Renderer`: it draws the :class:`CrowdState` given to :meth:`show`."""

    def __init__(
        self, figures: Figures, n: int, width: int, height: int, near_m: float, mid_m: float
    ) -> None:
        from client_stub.crowd.gl import CrowdGL

        self.n = n
        self.width, self.height = width, height
        self.camera = FreeCamera()
        self.state: CrowdState | None = None
        self.near_m, self.mid_m = near_m, mid_m
        self.rifle = FastFigure(figures.rifle)
        self.levels = [
            _Level("near", figures.near, self.rifle, figures.mid, n),
            _Level("mid", figures.mid, self.rifle, figures.mid, n),
        ]
        mid_body = self.levels[MID].body
        lo, hi = body_bounds(mid_body)
        self.impostor = impostor_for(lo, hi)
        self.root_inverse = mid_body.root_inverse
        models = [self.levels[NEAR].model, self.levels[MID].model]
        self.gl = CrowdGL(width, height, models, self.impostor, max_instances=n)
        self.counts = [0, 0, 0]

    def set_terrain(self, meshes: dict) -> None:
        from client_stub.crowd.gl import terrain_mesh

        self.gl.set_terrain(terrain_mesh(meshes))

    def show(self, state: CrowdState) -> None:
        """The crowd to draw from now on (its rows change in place)."""
        self.state = state

    def set_camera(self, pose: np.ndarray) -> None:
        self.camera.set_pose(pose)

    def render(self) -> np.ndarray:
        self.draw()
        return self.read()

    def close(self) -> None:
        self.gl.release()

    def draw(self) -> None:
        """Draw one frame of the state from the camera (:meth:`read` fetches it)."""
        assert self.state is not None, "show() a crowd first"
        st, camera = self.state, self.camera
        gl = self.gl
        aspect = gl.width / gl.height
        vp = camera.viewproj(aspect)
        dirty = st.dirty
        for lv in self.levels:
            lv.valid &= ~dirty
        dirty[:] = False
        centre = st.position + np.array([0.0, 0.0, 0.9])
        shown = np.flatnonzero(
            visible(centre, vp) & (np.linalg.norm(centre - camera.position, axis=1) < camera.far)
        )
        dist = np.linalg.norm(centre[shown] - camera.position, axis=1)
        level = choose_levels(dist, self.near_m, self.mid_m)
        ent = entity_transforms(st.heading[shown], st.position[shown])
        instances = []
        for k in (NEAR, MID):
            sel = level == k
            rows = shown[sel]
            lv = self.levels[k]
            lv.refresh(rows[~lv.valid[rows]], st)
            instances.append(mul(ent[sel][:, None], lv.cache[rows]))
        sel = level == FAR
        rows = shown[sel]
        root = mul(st.placement[rows, 0], self.root_inverse)
        instances.append(mul(ent[sel], root)[:, None])
        self.counts = [len(m) for m in instances]
        gl.draw(vp, camera.position, instances)

    def read(self) -> np.ndarray:
        return self.gl.read()


def default_centre(terrain: Any, side: float) -> tuple[float, float]:
    """The terrain's ``fields`` landmark, moved so that a crowd ``side`` metres wide stays on the terrain."""
    if terrain is None:
        return (0.0, 0.0)
    b = np.asarray(terrain.bounds, np.float64)
    try:
        c = np.asarray(terrain.landmark("fields"), np.float64)
    except (KeyError, ValueError, TypeError):
        c = (b[0, :2] + b[1, :2]) / 2
    half = side / 2 + 2.0
    lo, hi = b[0, :2] + half, b[1, :2] - half
    c = np.where(lo <= hi, np.clip(c, lo, np.maximum(lo, hi)), (b[0, :2] + b[1, :2]) / 2)
    return float(c[0]), float(c[1])


def run_crowd(cfg: CrowdConfig) -> dict[str, Any]:
    """Render the crowd for ``cfg.seconds``; returns frame statistics (and writes ``cfg.out``)."""
    cfg.check()
    from client_stub.crowd.sources import NetworkSource, OfflineSource

    t_setup = time.perf_counter()
    figures = Figures.load()
    terrain = None
    if cfg.terrain != "none":
        from client_stub.stub.terrain import DEFAULT_TERRAIN, load_terrain

        terrain = load_terrain(cfg.terrain or DEFAULT_TERRAIN)
    n = cfg.soldiers
    side = math.ceil(math.sqrt(n)) * cfg.spacing
    centre = cfg.centre or default_centre(terrain, side)
    server = None
    source: Any
    if cfg.source == "server":
        host, port = cfg.host, cfg.port
        if cfg.spawn_server:
            from client_stub.link.spawn import spawn_server
            from client_stub.loadtest.session import server_args

            server = spawn_server(server_args(30.0, 0.0), data=cfg.server_data)
            host, port = server.host, server.port
        try:
            source = NetworkSource(
                n, figures.mid, figures.rifle, figures.mid_tips, figures.rifle_tips, host=host, port=port,
                clients=max(1, min(cfg.clients, n)), terrain=terrain, centre=centre, spacing=cfg.spacing,
                mix=cfg.mix, seed=cfg.seed, credentials=cfg.credentials,
            )  # fmt: skip
        except BaseException:
            if server is not None:
                server.close()
            raise
    else:
        source = OfflineSource(
            n, figures.mid, figures.rifle, terrain=terrain, centre=centre, spacing=cfg.spacing, mix=cfg.mix,
            seed=cfg.seed,
        )  # fmt: skip
    renderer = None
    writer = None
    try:
        renderer = CrowdRenderer(figures, n, cfg.width, cfg.height, cfg.near_m, cfg.mid_m)
        renderer.show(source.state)
        if terrain is not None:
            renderer.set_terrain(terrain.meshes)
        camera = FreeCamera()
        c3 = np.array([centre[0], centre[1], 0.0])
        if terrain is not None:
            c3[2] = float(terrain.height(np.array([centre]))[0])
        if cfg.camera_pose is not None:
            x, y, z, h, p = cfg.camera_pose
            camera.position, camera.heading, camera.pitch = np.array([x, y, z], float), h, p
        radius = 0.5 * side + 2.0  # low and close: the nearest soldiers in view are in the near level
        height = 2.0 + 0.03 * side
        period = 120.0
        setup_s = time.perf_counter() - t_setup
        if cfg.out and cfg.out.lower().endswith(".mp4"):
            import imageio.v2 as imageio

            writer = imageio.get_writer(
                cfg.out, fps=cfg.video_fps, codec="libx264", quality=7, macro_block_size=8
            )
        times: list[float] = []
        cpu = 0.0
        counts = np.zeros(3)
        t0 = time.perf_counter()
        frames = 0
        while frames < cfg.max_frames:
            t = time.perf_counter() - t0
            if t >= cfg.seconds and frames > cfg.warmup_frames:
                break
            f0 = time.perf_counter()
            c0 = os.times()
            source.update(t)
            if cfg.camera_pose is None and cfg.camera == "orbit":
                orbit(camera, c3, radius, height, t, period)
            elif cfg.camera_pose is None and frames == 0:
                orbit(camera, c3, radius, height, 0.0, period)
            renderer.set_camera(camera.pose())
            renderer.draw()
            if frames >= cfg.warmup_frames:
                times.append(time.perf_counter() - f0)
                c1 = os.times()
                cpu += (c1.user - c0.user) + (c1.system - c0.system)
                counts += renderer.counts
            frames += 1
            if writer is not None:
                writer.append_data(renderer.read())
        image = renderer.read()
        if cfg.out and cfg.out.lower().endswith(".png"):
            from PIL import Image

            Image.fromarray(image).save(cfg.out)
        ft = np.array(times) if times else np.array([math.nan])
        measured = max(len(times), 1)
        return {
            "soldiers": n,
            "seconds": round(time.perf_counter() - t0, 2),
            "frames": frames,
            "fps": round(len(times) / float(ft.sum()), 2) if len(times) else None,
            "frame_ms_mean": round(float(ft.mean()) * 1000, 1),
            "frame_ms_p50": round(float(np.percentile(ft, 50)) * 1000, 1),
            "frame_ms_max": round(float(ft.max()) * 1000, 1),
            # CPU seconds of this process (all threads, llvmpipe's included) per frame: what a frame costs
            # when the machine is shared (wall-clock fps then depends on the other processes)
            "cpu_ms_per_frame": round(1000 * cpu / measured, 1),
            "width": cfg.width,
            "height": cfg.height,
            "mean_drawn": {
                name: round(float(c) / measured, 1) for name, c in zip(LEVEL_NAMES, counts, strict=True)
            },
            "triangles_last_frame": renderer.gl.triangles_drawn,
            "level_triangles": {
                "near": renderer.levels[NEAR].model.triangles,
                "mid": renderer.levels[MID].model.triangles,
                "far": renderer.impostor.triangles,
            },
            "near_figure": "soldier.fig" if figures.near_is_soldier else "DI.fig",
            "renderer": renderer.gl.renderer,
            "setup_s": round(setup_s, 2),
            "out": cfg.out,
            **source.stats(),
            "_image": image,
        }
    finally:
        if writer is not None:
            writer.close()
        if renderer is not None:
            renderer.close()
        source.close()
        if server is not None:
            server.close()


__all__ = ["CrowdConfig", "CrowdRenderer", "Figures", "run_crowd"]
