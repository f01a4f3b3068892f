"""The renderer interface every image-generator back end implements: the pyrender stub
(:class:`client_stub.stub.render.StubRenderer`) and the moderngl crowd
(:class:`client_stub.crowd.app.CrowdRenderer`). A new back end implements these four calls; what it draws
(instanced soldier meshes, a crowd state) it takes in its own terms. A back end of the stub app is a
:class:`StubBackend`: the pyrender stub, or the moderngl one that headless runs use
(:class:`client_stub.stub.gl_render.GLStubRenderer`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
import trimesh

if TYPE_CHECKING:
    from client_stub.stub.overlay import Overlay
    from client_stub.stub.scene_graph import EntityLayout


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


class InstancedSoldiers(Protocol):
    """The soldiers of one kind and look as a back end draws them (one instanced draw per part or kind)."""

    def update(self, world: np.ndarray) -> None:
        """World matrices ``(n, nodes, 4, 4)`` of the soldiers to draw this frame (n may be 0)."""
        ...


@runtime_checkable
class StubBackend(Renderer, Protocol):
    """What :class:`client_stub.stub.app.StubApp` draws through: the pyrender stub or the moderngl one
    (:class:`client_stub.stub.gl_render.GLStubRenderer`). ``overlay`` is written over each frame."""

    yfov_deg: float
    overlay: Overlay | None

    @property
    def soldiers(self) -> Mapping[tuple[int, int], InstancedSoldiers]:
        """(kind, look) -> the meshes made so far."""
        ...

    def soldier_meshes(self, kind: int, layout: EntityLayout, force: int) -> InstancedSoldiers:
        """The meshes of soldiers of ``kind`` in look ``force`` (a force or a DIS look; made once)."""
        ...
