"""The renderer interface every image-generator back end implements: the pyrender stub
(:class:`client_stub.stub.render.StubRenderer`) and the moderngl crowd
(:class:`client_stub.crowd.app.CrowdRenderer`). A new back end implements these four calls; what it draws
(instanced soldier meshes, a crowd state) it takes in its own terms."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import trimesh


@runtime_checkable
class Renderer(Protocol):
    width: int
    height: int

    def set_terrain(self, meshes: dict[str, trimesh.Trimesh]) -> None:
        """The terrain's meshes (Performer axes: metres, +Z up), once."""
        ...

    def set_camera(self, pose: np.ndarray) -> None:
        """4×4 camera-to-world pose, OpenGL style (the camera looks down its -Z, +Y up)."""
        ...

    def render(self) -> np.ndarray:
        """One frame, ``(height, width, 3)`` uint8."""
        ...

    def close(self) -> None:
        """Free the GL objects."""
        ...
