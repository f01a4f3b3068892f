"""The stub drawn with moderngl: one instanced draw call per kind of soldier and look, the terrain in tiles.

pyrender (:mod:`client_stub.stub.render`) shades every pixel with its PBR shader at 4× multisampling and
reads the depth buffer back each frame; on Mesa's llvmpipe that fill cost, not the soldiers, set the frame
rate (100 soldiers at 1280×720: 766 ms of CPU a frame; here 43 ms). This back end draws the same meshes
(:func:`~client_stub.stub.render.segment_arrays`: the same colours, force uniforms and smooth normals) lit
the way pyrender lights them (sun, fill and ambient, Lambert on ``c_diff``, gamma 2.2), but per vertex,
and without multisampling by default. Each kind + look is one vertex buffer of all its segments, every
vertex tagged with its scene-graph node; per-soldier node matrices go into a float texture read with
``texelFetch`` (the crowd's scheme, :mod:`client_stub.crowd.gl`). Under each soldier a blob shadow (a soft
dark ellipse over the footprint of his joints) sits him on the ground. The terrain is the crowd's tiled
mesh, with the ground smooth, drawn after the soldiers and nearest tile first (llvmpipe's depth test then
skips the hidden fragments).

Headless only (an EGL standalone context); the window keeps pyrender's renderer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from client_stub.crowd.gl import (
    FS,
    TerrainMesh,
    boxes_visible,
    parts_vs,
    terrain_array,
    terrain_mesh,
    terrain_vs,
)
from client_stub.stub.camera import viewproj
from client_stub.stub.render import (
    AMBIENT,
    FILL,
    FILL_AT,
    FORCE_UNIFORMS,
    SKY,
    SUN,
    StubRenderer,
    segment_arrays,
    sun_pose,
    uniform_colour,
)
from client_stub.stub.shadow import SHADOW_ALPHA, shadow_quads

if TYPE_CHECKING:
    import moderngl
    import trimesh

    from client_stub.stub.overlay import Overlay
    from client_stub.stub.scene_graph import EntityLayout

DIFFUSE = 0.96 / np.pi  # pyrender's c_diff / π (dielectric, min roughness 0.04)

_LIGHT = """
uniform vec3 sun_dir;
uniform vec3 fill_dir;
uniform vec3 sun_rgb;
uniform vec3 fill_rgb;
uniform vec3 ambient;
uniform float diffuse;
vec3 shade(vec3 base, vec3 n) {
    n = normalize(n);
    vec3 c = base * ambient;
    c += diffuse * base * sun_rgb * max(dot(n, sun_dir), 0.0);
    c += diffuse * base * fill_rgb * max(dot(n, fill_dir), 0.0);
    return pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2));
}
"""

SOLDIER_VS = parts_vs(_LIGHT, "shade(in_col, n)")
TERRAIN_VS = terrain_vs(_LIGHT, "shade(in_col, in_norm)")

SHADOW_VS = """
#version 330
uniform mat4 viewproj;
in vec3 in_pos;
in vec2 in_uv;
out vec2 v_uv;
void main() { v_uv = in_uv; gl_Position = viewproj * vec4(in_pos, 1.0); }
"""

SHADOW_FS = """
#version 330
uniform float alpha;
in vec2 v_uv;
out vec4 f_col;
void main() {
    float r = length(v_uv);
    if (r > 1.0) discard;
    f_col = vec4(0.0, 0.0, 0.0, alpha * (1.0 - smoothstep(0.45, 1.0, r)));
}
"""


def _uniform(prog: moderngl.Program, name: str) -> moderngl.Uniform:
    import moderngl

    member = prog[name]
    assert isinstance(member, moderngl.Uniform), name
    return member


class SoldierBatch:
    """One kind of soldier in one look: a vertex buffer of all its segments and a node-matrix texture
    (three texels a segment, one row a soldier), drawn with one instanced call."""

    def __init__(
        self, ctx: moderngl.Context, prog: moderngl.Program, layout: EntityLayout, force: int
    ) -> None:
        self.layout, self.force, self.ctx = layout, force, ctx
        uniform = uniform_colour(layout)
        colour = FORCE_UNIFORMS.get(force)
        rows: list[np.ndarray] = []
        indices: list[np.ndarray] = []
        nodes: list[int] = []
        base = 0
        for geom, node in layout.geometry:
            arrays = segment_arrays(geom, uniform, colour)
            if arrays is None:
                continue
            p, n, c, idx = arrays
            rows.append(np.column_stack([p, n, c, np.full(len(p), len(nodes), np.float32)]))
            indices.append(idx + base)
            base += len(p)
            nodes.append(node)
        self.nodes = np.array(nodes, np.int64)
        self.triangles = sum(len(i) for i in indices)
        self.vao: moderngl.VertexArray | None = None
        if nodes:
            vbo = ctx.buffer(np.ascontiguousarray(np.concatenate(rows), np.float32).tobytes())
            ibo = ctx.buffer(np.concatenate(indices).astype(np.uint32).tobytes())
            fmt = (vbo, "3f 3f 3f 1f", "in_pos", "in_norm", "in_col", "in_part")
            self.vao = ctx.vertex_array(prog, [fmt], index_buffer=ibo, index_element_size=4)
        self.texture: moderngl.Texture | None = None
        self.mats = np.zeros((0, len(nodes), 3, 4), np.float32)
        self.shadows = np.zeros((0, 4, 5), np.float32)

    @property
    def count(self) -> int:
        return len(self.mats)

    def update(self, world: np.ndarray) -> None:
        """Instance matrices from the world matrices ``(n, nodes, 4, 4)`` of the soldiers to draw."""
        self.mats = np.ascontiguousarray(world[:, self.nodes, :3, :4], np.float32)
        self.shadows = shadow_quads(world)

    def draw(self) -> int:
        """Upload the matrices and draw every soldier; the triangles drawn."""
        import moderngl

        n = self.count
        if not n or self.vao is None:
            return 0
        width = 3 * len(self.nodes)
        if self.texture is None or self.texture.height < n:
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture((width, max(n, 16)), 4, dtype="f4")
            self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.texture.write(self.mats.tobytes(), viewport=(0, 0, width, n))
        self.texture.use(0)
        self.vao.render(moderngl.TRIANGLES, instances=n)
        return n * self.triangles


class GLStubRenderer:
    """The stub's headless renderer on moderngl (a :class:`client_stub.renderer.Renderer`); the same calls
    as :class:`~client_stub.stub.render.StubRenderer` for :meth:`StubApp.draw`: ``soldier_meshes`` by kind
    and look, ``set_camera``, ``render``. ``samples`` > 1 multisamples (costly on llvmpipe)."""

    def __init__(self, width: int = 640, height: int = 480, yfov_deg: float = 50.0, samples: int = 0) -> None:
        import moderngl

        self.width, self.height, self.yfov_deg = width, height, yfov_deg
        # moderngl's stub types each **settings value as a dict; the backend name is a str at run time.
        self.ctx = ctx = moderngl.create_standalone_context(backend="egl")  # type: ignore[arg-type]
        self.soldier_prog = ctx.program(vertex_shader=SOLDIER_VS, fragment_shader=FS)
        self.terrain_prog = ctx.program(vertex_shader=TERRAIN_VS, fragment_shader=FS)
        self.shadow_prog = ctx.program(vertex_shader=SHADOW_VS, fragment_shader=SHADOW_FS)
        self.shadow_prog["alpha"] = SHADOW_ALPHA
        for prog in (self.soldier_prog, self.terrain_prog):
            prog["sun_dir"] = tuple(sun_pose()[:3, 2].tolist())
            prog["fill_dir"] = tuple(sun_pose(*FILL_AT)[:3, 2].tolist())
            prog["sun_rgb"] = tuple((np.array(SUN[0]) * SUN[1]).tolist())  # pyrender: colour × intensity
            prog["fill_rgb"] = tuple((np.array(FILL[0]) * FILL[1]).tolist())
            prog["ambient"] = AMBIENT
            prog["diffuse"] = float(DIFFUSE)
        self.soldiers: dict[tuple[int, int], SoldierBatch] = {}
        self.terrain: TerrainMesh | None = None
        self.terrain_vao: moderngl.VertexArray | None = None
        self.pose = np.eye(4)
        self.overlay: Overlay | None = None
        self.shadows = True  # blob shadows under the soldiers
        self.triangles_drawn = 0
        size = (width, height)
        self.fbo = ctx.framebuffer(
            color_attachments=[ctx.renderbuffer(size)], depth_attachment=ctx.depth_renderbuffer(size)
        )
        self.fbo_ms = None
        if samples > 1:
            self.fbo_ms = ctx.framebuffer(
                color_attachments=[ctx.renderbuffer(size, samples=samples)],
                depth_attachment=ctx.depth_renderbuffer(size, samples=samples),
            )

    def set_terrain(self, meshes: dict[str, trimesh.Trimesh]) -> None:
        mesh = terrain_mesh(meshes, smooth=("ground",))
        self.terrain_vao = terrain_array(self.ctx, self.terrain_prog, mesh)
        self.terrain = mesh if self.terrain_vao is not None else None

    def soldier_meshes(self, kind: int, layout: EntityLayout, force: int) -> SoldierBatch:
        key = (kind, int(force))
        if key not in self.soldiers:
            self.soldiers[key] = SoldierBatch(self.ctx, self.soldier_prog, layout, int(force))
        return self.soldiers[key]

    def set_camera(self, pose: np.ndarray) -> None:
        self.pose = np.asarray(pose, np.float64)

    def viewproj(self) -> np.ndarray:
        return viewproj(self.pose, self.yfov_deg, self.width / self.height)

    def render(self) -> np.ndarray:
        """One frame, ``(height, width, 3)`` uint8, top row first; the overlay (labels, help) on top."""
        import moderngl

        ctx = self.ctx
        target = self.fbo_ms or self.fbo
        target.use()
        ctx.viewport = (0, 0, self.width, self.height)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)  # TIPS windings are not consistent
        target.clear(*SKY, 1.0, depth=1.0)
        vp = self.viewproj()
        vp_bytes = np.ascontiguousarray(vp.T, np.float32).tobytes()  # column-major for GLSL
        # front to back, so the depth test rejects hidden fragments before they are shaded: the soldiers,
        # the terrain tiles nearest first, then the shadows blended over the ground
        _uniform(self.soldier_prog, "viewproj").write(vp_bytes)
        self.soldier_prog["mats"] = 0
        self.triangles_drawn = sum(batch.draw() for batch in self.soldiers.values())
        self.triangles_drawn += self._draw_terrain(vp, vp_bytes)
        self._draw_shadows(vp_bytes)
        if self.fbo_ms is not None:
            ctx.copy_framebuffer(self.fbo, self.fbo_ms)
        data = self.fbo.read(components=3, alignment=1)
        frame = np.frombuffer(data, np.uint8).reshape(self.height, self.width, 3)[::-1].copy()
        if self.overlay is not None:
            frame = self.overlay.draw(frame, vp)
        return frame

    def _draw_terrain(self, vp: np.ndarray, vp_bytes: bytes) -> int:
        import moderngl

        mesh, vao = self.terrain, self.terrain_vao
        if mesh is None or vao is None:
            return 0
        _uniform(self.terrain_prog, "viewproj").write(vp_bytes)
        drawn = 0
        tiles = np.flatnonzero(boxes_visible(mesh.lo, mesh.hi, vp))
        eye = self.pose[:3, 3]
        nearest = np.linalg.norm(np.clip(eye, mesh.lo[tiles], mesh.hi[tiles]) - eye, axis=1)
        for k in tiles[np.argsort(nearest, kind="stable")].tolist():
            vao.render(moderngl.TRIANGLES, vertices=int(mesh.count[k]), first=int(mesh.first[k]))
            drawn += int(mesh.count[k]) // 3
        return drawn

    def _draw_shadows(self, vp_bytes: bytes) -> None:
        """Every soldier's blob shadow, blended over the terrain (after it and the soldiers)."""
        import moderngl

        quads = [b.shadows for b in self.soldiers.values() if b.count]
        if not quads or not self.shadows:
            return
        q = np.concatenate(quads)
        tris = q[:, [0, 1, 2, 2, 1, 3]].reshape(-1, 5)
        ctx = self.ctx
        vbo = ctx.buffer(np.ascontiguousarray(tris, np.float32).tobytes())
        vao = ctx.vertex_array(self.shadow_prog, [(vbo, "3f 2f", "in_pos", "in_uv")])
        _uniform(self.shadow_prog, "viewproj").write(vp_bytes)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        vao.render(moderngl.TRIANGLES)  # drawn last: the depth it writes hides nothing
        ctx.disable(moderngl.BLEND)
        vao.release()
        vbo.release()

    def close(self) -> None:
        ctx, self.ctx = self.ctx, None  # type: ignore[assignment]
        if ctx is not None:
            ctx.release()


BACKENDS = ("gl", "pyrender")


def offscreen_renderer(width: int, height: int, backend: str = "gl") -> GLStubRenderer | StubRenderer:
    """The headless renderer: ``gl`` (moderngl, fast) or ``pyrender`` (the window's look, MSAA, slow)."""
    if backend == "gl":
        return GLStubRenderer(width, height)
    if backend == "pyrender":
        return StubRenderer(width, height, offscreen=True)
    raise ValueError(f"renderer must be one of {', '.join(BACKENDS)}, not {backend!r}")
