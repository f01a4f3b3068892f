"""The crowd's OpenGL side (moderngl): terrain, and one instanced draw call per level of detail.

Every level's mesh carries a *part* number per vertex; per-instance part matrices (3×4, the top rows of
each rigid transform, world space) live in a float texture, one row per drawn soldier and three texels per
part, which the vertex shader reads with ``texelFetch``. The far level is a silhouette on one quad per
soldier. So a frame is: upload three small textures, draw three levels (three draw calls whatever the number
of soldiers), then the terrain tiles in view.

Headless rendering uses EGL (``moderngl.create_standalone_context(backend="egl")``); Mesa's llvmpipe runs
it on the CPU.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from client_stub.crowd.lod import IMPOSTOR_COLOUR, SKIN_COLOUR, Impostor, LodModel

if TYPE_CHECKING:
    import moderngl

SKY = (0.62, 0.74, 0.88)
SUN = np.array([0.45, 0.35, 0.82])  # towards the sun (Performer: +Z up)
FOG_M = (250.0, 1200.0)  # linear fog from .. to

_COMMON = """
uniform vec3 sun;
uniform vec3 eye;
uniform vec3 sky;
uniform vec2 fog;
vec3 shade(vec3 colour, vec3 n, vec3 world) {
    float diffuse = abs(dot(normalize(n), sun));  // two-sided: TIPS windings are not consistent
    vec3 lit = colour * (0.38 + 0.72 * diffuse);
    float f = clamp((distance(world, eye) - fog.x) / (fog.y - fog.x), 0.0, 1.0);
    return mix(lit, sky, f);
}
"""

_PARTS_VS_INPUTS = """
#version 330
uniform mat4 viewproj;
uniform sampler2D mats;
in vec3 in_pos;
in vec3 in_norm;
in vec3 in_col;
in float in_part;
out vec3 v_col;
"""
_PARTS_VS_TRANSFORM = """
    int x = int(in_part + 0.5) * 3;
    vec4 r0 = texelFetch(mats, ivec2(x, gl_InstanceID), 0);
    vec4 r1 = texelFetch(mats, ivec2(x + 1, gl_InstanceID), 0);
    vec4 r2 = texelFetch(mats, ivec2(x + 2, gl_InstanceID), 0);
    vec4 p = vec4(in_pos, 1.0);
    vec3 world = vec3(dot(r0, p), dot(r1, p), dot(r2, p));
    vec3 n = vec3(dot(r0.xyz, in_norm), dot(r1.xyz, in_norm), dot(r2.xyz, in_norm));
"""

_TERRAIN_VS_INPUTS = """
#version 330
uniform mat4 viewproj;
in vec3 in_pos;
in vec3 in_norm;
in vec3 in_col;
out vec3 v_col;
"""


def parts_vs(lighting: str, colour: str) -> str:
    """An instanced soldier's vertex shader: the world position and normal ``n`` of a vertex of part
    ``in_part`` from the part's 3×4 world matrix (three texels of row ``gl_InstanceID`` of ``mats``), its
    colour the GLSL expression ``colour`` of ``in_col``, ``n`` and ``world`` with the functions of
    ``lighting``. The stub's moderngl renderer (:mod:`client_stub.stub.gl_render`) lights its own way."""
    main = f"void main() {{{_PARTS_VS_TRANSFORM}    v_col = {colour};\n"
    return f"{_PARTS_VS_INPUTS}{lighting}{main}    gl_Position = viewproj * vec4(world, 1.0);\n}}\n"


def terrain_vs(lighting: str, colour: str) -> str:
    """The terrain's vertex shader: world ``in_pos``, ``in_norm``, ``in_col``, coloured by ``colour``."""
    main = f"void main() {{\n    v_col = {colour};\n    gl_Position = viewproj * vec4(in_pos, 1.0);\n}}\n"
    return _TERRAIN_VS_INPUTS + lighting + main


SOLDIER_VS = parts_vs(_COMMON, "shade(in_col, n, world)")
TERRAIN_VS = terrain_vs(_COMMON, "shade(in_col, in_norm, in_pos)")

FS = """
#version 330
in vec3 v_col;
out vec4 f_col;
void main() { f_col = vec4(v_col, 1.0); }
"""

# The far level: a soldier's silhouette on one quad (2 triangles), an axial billboard along the body's up
# axis (the root's +Z), turned to face the eye; the fragment shader cuts head, arms, torso and legs out.
IMPOSTOR_VS = """
#version 330
uniform mat4 viewproj;
uniform sampler2D mats;
uniform vec3 eye;
uniform vec2 zrange;  // feet and head along the body axis, metres from the pelvis
uniform float halfwidth;
uniform vec2 fog;
in vec2 in_uv;  // u across (-1..1), v up (0..1)
out vec2 v_xy;  // metres: across, up from the feet
out float v_fog;
void main() {
    vec4 r0 = texelFetch(mats, ivec2(0, gl_InstanceID), 0);
    vec4 r1 = texelFetch(mats, ivec2(1, gl_InstanceID), 0);
    vec4 r2 = texelFetch(mats, ivec2(2, gl_InstanceID), 0);
    vec3 origin = vec3(r0.w, r1.w, r2.w);
    vec3 axis = vec3(r0.z, r1.z, r2.z);
    float h = zrange.y - zrange.x;
    vec3 base = origin + axis * zrange.x;
    vec3 side = cross(axis, base + axis * (0.5 * h) - eye);
    float len = length(side);
    side = len > 1e-6 ? side / len : vec3(1.0, 0.0, 0.0);
    vec3 world = base + axis * (in_uv.y * h) + side * (in_uv.x * halfwidth);
    v_xy = vec2(in_uv.x * halfwidth, in_uv.y * h);
    v_fog = clamp((distance(world, eye) - fog.x) / (fog.y - fog.x), 0.0, 1.0);
    gl_Position = viewproj * vec4(world, 1.0);
}
"""

IMPOSTOR_FS = """
#version 330
uniform vec3 uniform_colour;
uniform vec3 skin;
uniform vec3 sky;
uniform vec2 zrange;
in vec2 v_xy;
in float v_fog;
out vec4 f_col;
void main() {
    float h = zrange.y - zrange.x;
    float y = v_xy.y / h;
    float x = abs(v_xy.x);
    vec3 c;
    if (length(vec2(v_xy.x, (y - 0.93) * h)) < 0.11) c = skin;  // head
    else if (x < 0.19 && y > 0.50 && y < 0.86) c = uniform_colour;  // torso
    else if (x < 0.26 && y > 0.47 && y < 0.84) c = uniform_colour * 0.9;  // arms
    else if (abs(x - 0.09) < 0.075 && y > 0.04 && y < 0.53) c = uniform_colour * 0.8;  // legs
    else if (abs(x - 0.09) < 0.08 && y <= 0.04) c = vec3(0.08);  // boots
    else discard;
    f_col = vec4(mix(c, sky, v_fog), 1.0);
}
"""


@dataclass
class TerrainMesh:
    """Flat-shaded terrain triangles sorted into square tiles, so tiles outside the view are not drawn
    (llvmpipe's front end, not its rasteriser, is the bottleneck: every triangle submitted costs)."""

    vertices: np.ndarray  # (v, 9) float32: position, normal, colour
    first: np.ndarray  # (tiles,) first vertex of each tile
    count: np.ndarray  # (tiles,) vertices of each tile
    lo: np.ndarray  # (tiles, 3) bounds
    hi: np.ndarray


def terrain_mesh(meshes: dict, tile_m: float = 40.0, smooth: tuple[str, ...] = ()) -> TerrainMesh:
    """Triangles of trimesh meshes (Performer axes) as a :class:`TerrainMesh`; the meshes named in
    ``smooth`` keep their vertex normals (a rolling ground), the others are flat-shaded."""
    parts = []
    for name, mesh in meshes.items():
        tri = np.asarray(mesh.faces, np.int64)
        p = np.asarray(mesh.vertices, np.float64)[tri]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        n = np.asarray(mesh.vertex_normals, np.float64)[tri] if name in smooth else n[:, None]
        col = None
        visual = getattr(mesh, "visual", None)
        kind = getattr(visual, "kind", None)
        if visual is not None and kind == "vertex":
            col = np.asarray(visual.vertex_colors, np.float64)[tri][..., :3] / 255.0
        elif visual is not None and kind == "face":
            col = np.repeat(np.asarray(visual.face_colors, np.float64)[:, None, :3] / 255.0, 3, axis=1)
        if col is None:
            col = np.full((len(tri), 3, 3), 0.5)
        parts.append(np.concatenate([p, np.broadcast_to(n, p.shape), col], axis=2))
    if not parts:
        z = np.zeros(0, np.int64)
        return TerrainMesh(np.zeros((0, 9), np.float32), z, z, np.zeros((0, 3)), np.zeros((0, 3)))
    tris = np.concatenate(parts)  # (t, 3, 9)
    centre = tris[:, :, :2].mean(axis=1)
    cell = np.floor((centre - centre.min(axis=0)) / tile_m).astype(np.int64)
    key = cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1]
    order = np.argsort(key, kind="stable")
    tris, key = tris[order], key[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, len(key)])
    pts = tris[:, :, :3]
    lo = np.minimum.reduceat(pts.min(axis=1), starts, axis=0)
    hi = np.maximum.reduceat(pts.max(axis=1), starts, axis=0)
    verts = np.ascontiguousarray(tris.reshape(-1, 9), np.float32)
    return TerrainMesh(verts, starts * 3, counts * 3, lo, hi)


def terrain_array(
    ctx: moderngl.Context, prog: moderngl.Program, mesh: TerrainMesh
) -> moderngl.VertexArray | None:
    """The terrain's vertex buffer bound to ``prog``'s inputs (None for an empty mesh)."""
    if not len(mesh.vertices):
        return None
    vbo = ctx.buffer(mesh.vertices.tobytes())
    return ctx.vertex_array(prog, [(vbo, "3f 3f 3f", "in_pos", "in_norm", "in_col")])


def boxes_visible(lo: np.ndarray, hi: np.ndarray, viewproj: np.ndarray) -> np.ndarray:
    """(n,) bool: may each axis-aligned box be in the view frustum? (Not all 8 corners beyond one plane.)"""
    corners = np.stack(
        [np.stack([(hi if i & 1 else lo)[:, 0], (hi if i & 2 else lo)[:, 1], (hi if i & 4 else lo)[:, 2]], 1)
         for i in range(8)], 1)  # fmt: skip
    h = np.concatenate([corners, np.ones((*corners.shape[:2], 1))], axis=2) @ np.asarray(viewproj).T
    x, y, z, w = h[..., 0], h[..., 1], h[..., 2], h[..., 3]
    outside = [(x < -w), (x > w), (y < -w), (y > w), (z < -w), (z > w)]
    return ~np.any([o.all(axis=1) for o in outside], axis=0)


def _uniform(prog: moderngl.Program, name: str) -> moderngl.Uniform:
    """A program's uniform by name, for ``write``: ``Program[name]`` may be any kind of member."""
    import moderngl

    member = prog[name]
    assert isinstance(member, moderngl.Uniform), name
    return member


class CrowdGL:
    """Offscreen EGL context, programs, the terrain, and one vertex array + matrix texture per level."""

    def __init__(
        self, width: int, height: int, models: list[LodModel], impostor: Impostor, max_instances: int
    ) -> None:
        import moderngl

        self.width, self.height = width, height
        # moderngl's stub types each **settings value as a dict; the backend name is a str at run time.
        self.ctx = moderngl.create_standalone_context(backend="egl")  # type: ignore[arg-type]
        ctx = self.ctx
        self.renderer = str(ctx.info.get("GL_RENDERER", "?"))
        self.soldier_prog = ctx.program(vertex_shader=SOLDIER_VS, fragment_shader=FS)
        self.terrain_prog = ctx.program(vertex_shader=TERRAIN_VS, fragment_shader=FS)
        for prog in (self.soldier_prog, self.terrain_prog):
            prog["sun"] = tuple((SUN / np.linalg.norm(SUN)).tolist())
            prog["sky"] = SKY
            prog["fog"] = FOG_M
        self.max_instances = int(max_instances)
        self.levels = []
        for model in models:
            vbo = ctx.buffer(model.interleaved().tobytes())
            vao = ctx.vertex_array(
                self.soldier_prog, [(vbo, "3f 3f 3f 1f", "in_pos", "in_norm", "in_col", "in_part")]
            )
            tex = ctx.texture((3 * len(model.parts), max(1, self.max_instances)), 4, dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.levels.append((model, vbo, vao, tex))
        self.impostor = impostor
        self.impostor_prog = prog = ctx.program(vertex_shader=IMPOSTOR_VS, fragment_shader=IMPOSTOR_FS)
        prog["zrange"] = (float(impostor.feet), float(impostor.head))
        prog["halfwidth"] = float(impostor.halfwidth)
        prog["fog"] = FOG_M
        prog["sky"] = SKY
        prog["skin"] = SKIN_COLOUR
        prog["uniform_colour"] = IMPOSTOR_COLOUR
        quad = np.array([[-1.0, 0.0], [1.0, 0.0], [-1.0, 1.0], [1.0, 1.0]], np.float32)
        self.impostor_vao = ctx.vertex_array(prog, [(ctx.buffer(quad.tobytes()), "2f", "in_uv")])
        self.impostor_tex = ctx.texture((3, max(1, self.max_instances)), 4, dtype="f4")
        self.impostor_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.terrain_vao: moderngl.VertexArray | None = None
        self.terrain: TerrainMesh | None = None
        colour = ctx.renderbuffer((width, height))
        depth = ctx.depth_renderbuffer((width, height))
        self.fbo = ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
        self.triangles_drawn = 0

    def set_terrain(self, mesh: TerrainMesh) -> None:
        self.terrain_vao = terrain_array(self.ctx, self.terrain_prog, mesh)
        self.terrain = mesh if self.terrain_vao is not None else None

    def draw(self, viewproj: np.ndarray, eye: np.ndarray, instances: list[np.ndarray]) -> None:
        """One frame: ``instances`` are (n, parts, 3, 4) float32 world part matrices of the near and mid
        levels, then (n, 1, 3, 4) root (figure DCS) matrices of the impostors. Soldiers are drawn before the
        terrain, so the depth test rejects the terrain behind them early."""
        import moderngl

        ctx = self.ctx
        self.fbo.use()
        ctx.viewport = (0, 0, self.width, self.height)
        ctx.enable(moderngl.DEPTH_TEST)
        self.fbo.clear(*SKY, 1.0, depth=1.0)
        vp = np.ascontiguousarray(viewproj.T, np.float32).tobytes()  # column-major for GLSL
        eye_t = tuple(float(v) for v in eye)
        self.triangles_drawn = 0
        ctx.disable(moderngl.CULL_FACE)  # TIPS windings are not consistent
        _uniform(self.soldier_prog, "viewproj").write(vp)
        self.soldier_prog["eye"] = eye_t
        self.soldier_prog["mats"] = 0
        for (model, _, vao, tex), mats in zip(self.levels, instances[: len(self.levels)], strict=True):
            n = min(len(mats), self.max_instances)
            if not n:
                continue
            tex.write(
                np.ascontiguousarray(mats[:n], np.float32).tobytes(), viewport=(0, 0, 3 * len(model.parts), n)
            )
            tex.use(0)
            vao.render(moderngl.TRIANGLES, instances=n)
            self.triangles_drawn += n * model.triangles
        far = instances[len(self.levels)] if len(instances) > len(self.levels) else np.zeros((0, 1, 3, 4))
        n = min(len(far), self.max_instances)
        if n:
            prog = self.impostor_prog
            _uniform(prog, "viewproj").write(vp)
            prog["eye"] = eye_t
            prog["mats"] = 0
            self.impostor_tex.write(
                np.ascontiguousarray(far[:n], np.float32).tobytes(), viewport=(0, 0, 3, n)
            )
            self.impostor_tex.use(0)
            self.impostor_vao.render(moderngl.TRIANGLE_STRIP, instances=n)
            self.triangles_drawn += 2 * n
        if self.terrain_vao is not None and self.terrain is not None:
            _uniform(self.terrain_prog, "viewproj").write(vp)
            self.terrain_prog["eye"] = eye_t
            mesh = self.terrain
            for k in np.flatnonzero(boxes_visible(mesh.lo, mesh.hi, viewproj)).tolist():
                self.terrain_vao.render(
                    moderngl.TRIANGLES, vertices=int(mesh.count[k]), first=int(mesh.first[k])
                )
                self.triangles_drawn += int(mesh.count[k]) // 3
        ctx.finish()

    def read(self) -> np.ndarray:
        """The last frame, (height, width, 3) uint8, top row first."""
        data = self.fbo.read(components=3, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(self.height, self.width, 3)[::-1].copy()

    def release(self) -> None:
        self.ctx.release()
