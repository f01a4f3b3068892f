"""Which optional extra of ``jack-ttes`` installs a module: the message a command prints when it lacks one.

The base install is the server's (numpy, trio, msgpack); the clients, the DIS tools and the authoring
tools are extras (``pyproject.toml``). Keep this table in step with them.
"""

from __future__ import annotations

EXTRA_OF_MODULE: dict[str, str] = {
    "dpkt": "dis",
    "tqdm": "dis",
    "trimesh": "stub",
    "pyrender": "stub",
    "OpenGL": "stub",
    "moderngl": "stub",
    "imageio": "stub",
    "imageio_ffmpeg": "stub",
    "PIL": "stub",
    "matplotlib": "stub",
    "mujoco": "authoring",
    "scipy": "authoring",
    "fast_simplification": "authoring",
    "pygltflib": "authoring",
    "bvhio": "authoring",
    "pyglm": "authoring",  # PyGLM, bvhio's vectors
    "zenoh": "fabric",  # ttes server --shard, ttes front (server.fabric)
    "cyclonedds": "fabric",
}


def missing_extra_message(command: str, exc: ModuleNotFoundError) -> str | None:
    """The line to print when ``command`` failed importing a module of an extra; ``None`` for other modules
    (a missing module of our own is a bug, not an install choice)."""
    top = (exc.name or "").partition(".")[0]
    extra = EXTRA_OF_MODULE.get(top)
    if extra is None:
        return None
    return (
        f"ttes {command}: needs {top}, which the '{extra}' extra installs: pip install 'jack-ttes[{extra}]'"
    )
