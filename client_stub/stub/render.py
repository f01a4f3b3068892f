"""Drawing the scene with pyrender: the terrain, and the soldiers as instanced body parts.

Performer drew each soldier's joint DCS tree; here every body part (segment) of a kind of soldier is one
pyrender mesh drawn once per visible soldier with per-instance poses (``Primitive.poses``, a GL instance
buffer), so the draw calls do not grow with the number of soldiers. The poses come from the scene graph's
world matrices (:class:`~client_stub.stub.scene_graph.Crowd`) every frame and are uploaded into the instance
buffers just before drawing (pyrender uploads them only once by itself).

Friendly and opposing forces differ by uniform colour: the figure's dominant surface colour (its uniform) is
replaced by the force's colour; skin, boots and rifles keep theirs.

Offscreen rendering needs ``PYOPENGL_PLATFORM=egl`` in the environment before OpenGL is first imported
(``ttes stub --headless`` sets it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyrender
import trimesh

from client_stub.stub.camera import viewproj
from client_stub.stub.overlay import Overlay
from client_stub.stub.scene_graph import EntityLayout, SegmentGeometry
from client_stub.stub.shadow import shadow_disc, shadow_matrices
from client_stub.stub.simsoldier import Force

FORCE_UNIFORMS: dict[int, tuple[float, float, float] | None] = {
    Force.FRIENDLY: None,  # the figure's own olive drab
    Force.OPPOSING: (0.50, 0.10, 0.14),  # maroon: far from olive, skin and the sky
}
SKY = (0.62, 0.74, 0.88)
AMBIENT = (0.35, 0.35, 0.38)
SUN = ((1.0, 0.97, 0.9), 3.2)  # colour, intensity; from compass 35°, 55° up
FILL = ((0.8, 0.85, 1.0), 1.0)  # from compass -150°, 35° up
FILL_AT = (-150.0, 35.0)
HIDDEN = np.zeros((1, 4, 4), np.float32)  # an instance pose that draws nothing (all vertices at one point)


def uniform_colour(layout: EntityLayout) -> np.ndarray | None:
    """The body's uniform: the diffuse colour covering the most triangles of the first figure."""
    counts: dict[tuple[float, ...], int] = {}
    for geom, _ in layout.geometry:
        if geom.figure != layout.figures[0].name or not len(geom.diffuse):
            continue
        attr, n = np.unique(geom.triangle_attribute, return_counts=True)
        for a, c in zip(attr, n, strict=True):
            key = tuple(np.round(geom.diffuse[a], 6))
            counts[key] = counts.get(key, 0) + int(c)
    if not counts:
        return None
    return np.array(max(counts, key=lambda k: counts[k]))


def _material(rgb: np.ndarray) -> pyrender.MetallicRoughnessMaterial:
    return pyrender.MetallicRoughnessMaterial(
        baseColorFactor=(*np.clip(rgb, 0, 1), 1.0), metallicFactor=0.0, roughnessFactor=0.9, doubleSided=True
    )


def segment_arrays(
    geom: SegmentGeometry, uniform: np.ndarray | None, force_colour: tuple[float, float, float] | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """A segment's indexed mesh as every back end draws it: positions, normals (smooth within each
    attribute), RGB colours (attribute colours, the uniform recoloured for the force) and triangle indices;
    None for a segment without triangles."""
    if not len(geom.triangles):
        return None
    diffuse = geom.diffuse if len(geom.diffuse) else np.full((1, 3), 0.7)
    if force_colour is not None and uniform is not None:
        diffuse = np.where(
            np.all(np.isclose(diffuse, uniform, atol=1e-4), axis=1)[:, None], force_colour, diffuse
        )
    positions, normals, colours, indices = [], [], [], []
    base = 0
    for a in np.unique(geom.triangle_attribute):
        tris = geom.triangles[geom.triangle_attribute == a]
        used, inverse = np.unique(tris, return_inverse=True)
        part = trimesh.Trimesh(geom.vertices[used], inverse.reshape(-1, 3), process=False)
        n = geom.vertex_normals[used] if geom.vertex_normals is not None else part.vertex_normals
        rgb = diffuse[min(int(a), len(diffuse) - 1)]
        c = (
            geom.vertex_colors[used, :3]
            if geom.vertex_colors is not None
            else np.broadcast_to(rgb, (len(used), 3))
        )
        positions.append(geom.vertices[used])
        normals.append(n)
        colours.append(c)
        indices.append(inverse.reshape(-1, 3) + base)
        base += len(used)
    return (
        np.concatenate(positions).astype(np.float32),
        np.concatenate(normals).astype(np.float32),
        np.concatenate(colours).astype(np.float32),
        np.concatenate(indices).astype(np.uint32),
    )


def segment_primitives(
    geom: SegmentGeometry, uniform: np.ndarray | None, force_colour: tuple[float, float, float] | None
) -> list[pyrender.Primitive]:
    """One primitive per segment (one draw call per body part) of :func:`segment_arrays`."""
    arrays = segment_arrays(geom, uniform, force_colour)
    if arrays is None:
        return []
    positions, normals, colours, indices = arrays
    return [
        pyrender.Primitive(
            positions=positions,
            normals=normals,
            color_0=np.column_stack([colours, np.ones(len(colours), np.float32)]),
            indices=indices,
            material=_material(np.ones(3)),
            poses=HIDDEN,
        )
    ]


@dataclass
class _Part:
    node: int  # scene-graph node the segment hangs under
    primitives: list[pyrender.Primitive]


class SoldierMeshes:
    """The instanced meshes of one kind of soldier in one force's colours."""

    def __init__(self, scene: pyrender.Scene, layout: EntityLayout, force: int) -> None:
        self.layout = layout
        self.force = force
        uniform = uniform_colour(layout)
        colour = FORCE_UNIFORMS.get(force)
        self.parts: list[_Part] = []
        self.nodes: list[pyrender.Node] = []
        for geom, node in layout.geometry:
            prims = segment_primitives(geom, uniform, colour)
            if not prims:
                continue
            mesh = pyrender.Mesh(prims, name=f"{geom.figure}.{geom.segment}")
            self.nodes.append(scene.add(mesh, name=f"{geom.figure}.{geom.segment}/{force}"))
            self.parts.append(_Part(node, prims))
        positions, colours, indices = shadow_disc()
        blend = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=(1.0, 1.0, 1.0, 1.0), alphaMode="BLEND", doubleSided=True
        )
        self.shadow = pyrender.Primitive(
            positions=positions, color_0=colours, indices=indices, material=blend, poses=HIDDEN
        )
        self.nodes.append(scene.add(pyrender.Mesh([self.shadow], name="shadow"), name=f"shadow/{force}"))
        self.count = 0

    def update(self, world: np.ndarray) -> None:
        """Instance poses from the world matrices ``(n, nodes, 4, 4)`` of the soldiers to draw."""
        self.count = len(world)
        for part in self.parts:
            poses = world[:, part.node].astype(np.float32) if len(world) else HIDDEN
            for prim in part.primitives:
                prim.poses = poses
        self.shadow.poses = shadow_matrices(world).astype(np.float32) if len(world) else HIDDEN

    @staticmethod
    def upload(primitives: list[pyrender.Primitive]) -> None:
        """Copy changed instance poses into the GL buffers (the GL context must be current)."""
        from OpenGL.GL import GL_ARRAY_BUFFER, GL_DYNAMIC_DRAW, glBindBuffer, glBufferData

        for prim in primitives:
            if prim._vaid is None or len(prim._buffers) < 2 or prim.poses is None:
                continue  # not drawn yet: pyrender uploads the current poses itself
            data = np.ascontiguousarray(np.transpose(prim.poses, (0, 2, 1)), dtype=np.float32)
            glBindBuffer(GL_ARRAY_BUFFER, prim._buffers[1])
            glBufferData(GL_ARRAY_BUFFER, data.nbytes, data, GL_DYNAMIC_DRAW)

    def primitives(self) -> list[pyrender.Primitive]:
        return [p for part in self.parts for p in part.primitives] + [self.shadow]


def terrain_nodes(scene: pyrender.Scene, meshes: dict[str, trimesh.Trimesh]) -> list[pyrender.Node]:
    """Add the terrain meshes (vertex-coloured layers smooth, face-coloured ones flat)."""
    nodes = []
    for name, mesh in meshes.items():
        smooth = getattr(mesh.visual, "kind", None) == "vertex" and name in ("ground",)
        pm = pyrender.Mesh.from_trimesh(mesh, smooth=smooth)
        for prim in pm.primitives:
            prim.material.metallicFactor = 0.0
            prim.material.roughnessFactor = 1.0
        nodes.append(scene.add(pm, name=f"terrain/{name}"))
    return nodes


class StubRenderer:
    """The pyrender scene: terrain, sun, camera and the soldiers' instanced meshes (a
    :class:`client_stub.renderer.Renderer`)."""

    def __init__(
        self, width: int = 640, height: int = 480, offscreen: bool = True, yfov_deg: float = 50.0
    ) -> None:
        self.width, self.height, self.yfov_deg = width, height, yfov_deg
        self.overlay: Overlay | None = None
        self.shadows = True  # blob shadows under the soldiers
        self.scene = pyrender.Scene(bg_color=(*SKY, 1.0), ambient_light=AMBIENT)
        self.camera = pyrender.PerspectiveCamera(
            yfov=np.radians(yfov_deg), znear=0.2, zfar=2000.0, aspectRatio=width / height
        )
        self.camera_node = self.scene.add(self.camera, pose=np.eye(4), name="camera")
        sun = pyrender.DirectionalLight(color=SUN[0], intensity=SUN[1])
        self.scene.add(sun, pose=sun_pose(), name="sun")
        fill = pyrender.DirectionalLight(color=FILL[0], intensity=FILL[1])
        self.scene.add(fill, pose=sun_pose(*FILL_AT), name="fill")
        self.soldiers: dict[tuple[int, int], SoldierMeshes] = {}
        self._offscreen = pyrender.OffscreenRenderer(width, height) if offscreen else None

    def set_terrain(self, meshes: dict[str, trimesh.Trimesh]) -> None:
        terrain_nodes(self.scene, meshes)

    def soldier_meshes(self, kind: int, layout: EntityLayout, force: int) -> SoldierMeshes:
        key = (kind, int(force))
        if key not in self.soldiers:
            self.soldiers[key] = SoldierMeshes(self.scene, layout, int(force))
        return self.soldiers[key]

    def set_camera(self, pose: np.ndarray) -> None:
        self.scene.set_pose(self.camera_node, pose)

    def upload(self) -> None:
        """Instance poses into GL (context current)."""
        for meshes in self.soldiers.values():
            if not self.shadows:
                meshes.shadow.poses = HIDDEN
            SoldierMeshes.upload(meshes.primitives())

    def render(self) -> np.ndarray:
        """One offscreen frame, ``(height, width, 3)`` uint8."""
        if self._offscreen is None:
            raise RuntimeError("renderer was made for a window")
        self._offscreen._platform.make_current()
        self.upload()
        colour, _ = self._offscreen.render(self.scene)
        frame = np.asarray(colour)
        if self.overlay is not None:
            pose = self.scene.get_pose(self.camera_node)
            frame = self.overlay.draw(frame, viewproj(pose, self.yfov_deg, self.width / self.height))
        return frame

    def close(self) -> None:
        """Free the GL objects and our context. With EGL the display is left alone: pyrender's own
        ``delete`` terminates the process-wide default display, which kills every other renderer's context."""
        r, self._offscreen = self._offscreen, None
        if r is None:
            return
        platform = r._platform
        display = getattr(platform, "_egl_display", None)
        context = getattr(platform, "_egl_context", None)
        if display is None or context is None:
            r.delete()
            return
        from OpenGL import EGL

        platform.make_current()
        r._renderer.delete()
        EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
        EGL.eglDestroyContext(display, context)
        platform._egl_context = None
        platform._egl_display = None  # so pyrender's __del__ -> delete() cannot terminate the shared display


def sun_pose(azimuth: float = 35.0, elevation: float = 55.0) -> np.ndarray:
    """A directional light shining down from compass ``azimuth`` at ``elevation`` degrees."""
    az, el = np.radians(azimuth), np.radians(elevation)
    towards_sun = np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    z = towards_sun  # the light shines along its -Z
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = x, np.cross(z, x), z
    return pose
