"""glTF 2.0 out (issue 20): a soldier, its rifle and their channelsets as animations, for any image generator.

The file is the FIGURE message (docs/PROTOCOL.md §7.2, ``protocol.figure``) written as a node tree, so a
glTF client and a wire client see the same skeleton with the same names:

    jack_to_gltf               rotation only: Performer axes (+Z up, facing +Y) to glTF's (+Y up, facing +Z)
      soldier / rifle          the figure entry F (the table's entry name); animated: translation, rotation
        <root>.segment         pre of row 0, the segment's mesh (node mesh, rigidly bound)
          <joint>              pre · D(q), the update table's joint name; animated: rotation (+ translation
            <segment>.segment  for T DOFs); then post, the segment's mesh
              <segment>.<site> an empty at each site's location

Segments are ``NAME.segment`` because a joint may share its segment's name (DI's ``neck``); the rifle's
nodes are ``AK_47.…`` as its joints are in the table. Metres everywhere. The local transforms come from
the wire client's segment globals (``WireFigure.segment_globals``), so no second FK lives here:
joint = inv(G(parent)) · G(segment) · inv(post).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any

import numpy as np
import pygltflib as gl
import trimesh

from peabody import quaternion
from peabody.fk import FigureKinematics, rigid_inverse
from peabody.loader import read_figure
from peabody.model import Figure
from protocol import coords
from protocol.figure import WireFigure, dof_starts, figure_from_wire, figure_to_wire
from protocol.update_table import FigureEntry, JointEntry, UpdateTable
from server.motion.binding import FigurePlacement, bind_channelset
from server.motion.cache import load_channelset
from server.motion.channelset import Channelset
from server.soldier.wire import table_entries

# Performer (x, y, z) -> glTF (-x, z, y): a half turn about (0, 1, 1)/sqrt2, as an (x, y, z, w) quaternion
PERFORMER_TO_GLTF = (0.0, float(np.sqrt(0.5)), float(np.sqrt(0.5)), 0.0)
ROOT_NODE = "jack_to_gltf"
_COLOURS = ((0.33, 0.36, 0.22, 1.0), (0.15, 0.15, 0.15, 1.0))  # olive drab soldier, dark rifle


@dataclass(frozen=True)
class Rig:
    """The figures of one update table as a client holds them (the FIGURE message decoded)."""

    table: UpdateTable
    figures: tuple[Figure, ...]
    wire: tuple[WireFigure, ...]
    entry_names: tuple[str, ...]  # the figure entries: "soldier", "rifle"
    joint_names: tuple[tuple[str, ...], ...]  # per figure, per segment row > 0: the node name of its joint

    @property
    def translational(self) -> np.ndarray:
        return np.array(
            [d.kind == "T" for e in self.table.entries if isinstance(e, JointEntry) for d in e.dofs]
        )

    def table_dofs(self, poses: Sequence[np.ndarray]) -> np.ndarray:
        """Per-figure Peabody pose vectors (radians, cm) -> one table-order DOF vector (radians, metres)."""
        dofs = np.concatenate([np.asarray(p, np.float64) for p in poses])
        dofs[self.translational] /= coords.CM_PER_M
        return dofs


def rig_for(figures: Sequence[Figure]) -> Rig:
    """The rig of a soldier (first) and its weapon, named as the server's update table names them."""
    files = [PurePath(f.filename or f.name).name for f in figures]
    table = UpdateTable(0, files[0], files[1] if len(files) > 1 else "", table_entries(figures))
    names = tuple(e.name for e in table.entries if isinstance(e, FigureEntry))
    _, wire = figure_from_wire(figure_to_wire(table, figures, names, meshes=True))
    joints = []
    for k, fig in enumerate(figures):
        prefix = "" if k == 0 else f"{fig.name}."
        joints.append(tuple(prefix + step[0] for step in FigureKinematics(fig).tree_steps()))
    return Rig(table, tuple(figures), wire, names, tuple(joints))


def local_transforms(rig: Rig, dofs: np.ndarray, placements: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Per figure ``(S, 4, 4)``: each joint node's local transform (row 0: the root segment's ``pre``) at one
    pose; ``placements`` are the figure entries F (Performer, metres)."""
    out = []
    for wf, f in zip(rig.wire, placements, strict=True):
        g = wf.segment_globals(rig.table, dofs, f)
        local = np.empty_like(g)
        local[0] = wf.pre[0]
        parents = g[wf.parent[1:]]
        local[1:] = rigid_inverse(parents) @ g[1:] @ rigid_inverse(wf.post[1:])
        out.append(local)
    return out


def _trs(m: np.ndarray) -> tuple[list[float], list[float]]:
    """A rigid 4x4 as glTF translation and (x, y, z, w) rotation."""
    w, x, y, z = quaternion.from_matrix(m[:3, :3])
    return [float(v) for v in m[:3, 3]], [float(x), float(y), float(z), float(w)]


def vertex_normals(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Unit vertex normals (trimesh's, area-weighted) so viewers shade a segment smooth, not flat.

    glTF requires every NORMAL to be unit length: a vertex no triangle uses gets +Z."""
    mesh = trimesh.Trimesh(vertices=verts, faces=tris, process=False)
    n = np.array(mesh.vertex_normals, dtype=np.float64)
    length = np.linalg.norm(n, axis=1)
    n[length < 0.5] = (0.0, 0.0, 1.0)
    n /= np.linalg.norm(n, axis=1)[:, None]
    return n.astype(np.float32)


class _Writer:
    """Accumulates one .glb: nodes, meshes, accessors over a single binary buffer."""

    def __init__(self) -> None:
        self.gltf = gl.GLTF2(asset=gl.Asset(generator="jack-ttes authoring.gltf_export", version="2.0"))
        self.blob = bytearray()

    def accessor(self, data: np.ndarray, kind: str, target: int | None = None, bounds: bool = False) -> int:
        data = np.ascontiguousarray(data)
        while len(self.blob) % 4:
            self.blob.append(0)
        view = gl.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=data.nbytes, target=target)
        self.blob.extend(data.tobytes())
        self.gltf.bufferViews.append(view)
        ctype = {np.dtype(np.float32): gl.FLOAT, np.dtype(np.uint32): gl.UNSIGNED_INT}[data.dtype]
        acc = gl.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1, componentType=ctype, count=len(data), type=kind
        )
        if bounds:
            flat = data.reshape(len(data), -1)
            acc.min = [float(v) for v in flat.min(axis=0)]
            acc.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def node(self, name: str, m: np.ndarray | None = None, mesh: int | None = None) -> int:
        node = gl.Node(name=name, mesh=mesh)
        if m is not None:
            node.translation, node.rotation = _trs(m)
        self.gltf.nodes.append(node)
        return len(self.gltf.nodes) - 1

    def child(self, parent: int, name: str, m: np.ndarray | None = None, mesh: int | None = None) -> int:
        k = self.node(name, m, mesh)
        self.gltf.nodes[parent].children.append(k)
        return k

    def material(self, name: str, rgba: tuple[float, ...]) -> int:
        pbr = gl.PbrMetallicRoughness(baseColorFactor=list(rgba), metallicFactor=0.0, roughnessFactor=0.8)
        self.gltf.materials.append(gl.Material(name=name, pbrMetallicRoughness=pbr, doubleSided=True))
        return len(self.gltf.materials) - 1

    def mesh(self, name: str, verts: np.ndarray, tris: np.ndarray, material: int) -> int:
        pos = self.accessor(verts.astype(np.float32), gl.VEC3, gl.ARRAY_BUFFER, bounds=True)
        nrm = self.accessor(vertex_normals(verts, tris), gl.VEC3, gl.ARRAY_BUFFER)
        idx = self.accessor(tris.astype(np.uint32).ravel(), gl.SCALAR, gl.ELEMENT_ARRAY_BUFFER)
        attributes = gl.Attributes(POSITION=pos, NORMAL=nrm)
        prim = gl.Primitive(attributes=attributes, indices=idx, material=material)
        self.gltf.meshes.append(gl.Mesh(name=name, primitives=[prim]))
        return len(self.gltf.meshes) - 1

    def write(self, out: Path) -> None:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.gltf.buffers = [gl.Buffer(byteLength=len(self.blob))]
        self.gltf.set_binary_blob(bytes(self.blob))
        out.parent.mkdir(parents=True, exist_ok=True)
        self.gltf.save_binary(str(out))


@dataclass(frozen=True)
class _Nodes:
    """Node indices of the written rig: per figure its entry node and joint nodes (row 0: root segment)."""

    entries: tuple[int, ...]
    joints: tuple[tuple[int, ...], ...]


def segment_node_name(prefix: str, segment: str) -> str:
    """A segment's node: ``lower_torso.segment`` (``AK_47.gun.segment`` for the weapon's)."""
    return f"{prefix}{segment}.segment"


def _write_figure(
    w: _Writer, parent: int, rig: Rig, k: int, local: np.ndarray, f: np.ndarray
) -> tuple[int, ...]:
    wf = rig.wire[k]
    prefix = "" if k == 0 else f"{rig.figures[k].name}."
    material = w.material(rig.entry_names[k], _COLOURS[min(k, len(_COLOURS) - 1)])
    meshes = {
        row: w.mesh(prefix + wf.segment_names[row], verts, tris, material)
        for row, (verts, tris) in wf.meshes.items()
    }
    entry = w.child(parent, rig.entry_names[k], f)
    joint_nodes = [w.child(entry, segment_node_name(prefix, wf.segment_names[0]), local[0], meshes.get(0))]
    segment_nodes = [joint_nodes[0]]
    for row in range(1, len(wf.segment_names)):
        up = segment_nodes[wf.parent[row]]
        jn = w.child(up, rig.joint_names[k][row - 1], local[row])
        joint_nodes.append(jn)
        name = segment_node_name(prefix, wf.segment_names[row])
        segment_nodes.append(w.child(jn, name, wf.post[row], meshes.get(row)))
    for name, seg, loc in zip(wf.site_names, wf.site_segment, wf.site_location, strict=True):
        w.child(segment_nodes[seg], prefix + name, loc)
    return tuple([entry, *joint_nodes])


def _write_rig(w: _Writer, rig: Rig, dofs: np.ndarray, placements: Sequence[np.ndarray]) -> _Nodes:
    root = w.node(ROOT_NODE)
    w.gltf.nodes[root].rotation = list(PERFORMER_TO_GLTF)
    w.gltf.scenes = [gl.Scene(name=rig.table.figure, nodes=[root])]
    w.gltf.scene = 0
    locals_ = local_transforms(rig, dofs, placements)
    written = [_write_figure(w, root, rig, k, locals_[k], placements[k]) for k in range(len(rig.wire))]
    return _Nodes(tuple(n[0] for n in written), tuple(n[1:] for n in written))


def neutral_placements(rig: Rig) -> list[np.ndarray]:
    """Each figure's own ``location`` (Performer): where a figure stands in its file."""
    return [coords.transforms_jack_to_performer(f.location) for f in rig.figures]


def export_figures(figures: Sequence[Figure], out: Path) -> Rig:
    """Write ``figures`` (a soldier, then its weapon) in their neutral pose as a .glb."""
    rig = rig_for(figures)
    w = _Writer()
    poses = [FigureKinematics(f).neutral_pose() for f in figures]
    _write_rig(w, rig, rig.table_dofs(poses), neutral_placements(rig))
    w.write(out)
    return rig


# -- motion -----------------------------------------------------------------------------------------------


def _channel(w: _Writer, anim: gl.Animation, times: int, node: int, path: str, values: np.ndarray) -> None:
    kind = gl.VEC4 if path == "rotation" else gl.VEC3
    out = w.accessor(values.astype(np.float32), kind)
    anim.samplers.append(gl.AnimationSampler(input=times, output=out, interpolation="LINEAR"))
    anim.channels.append(
        gl.AnimationChannel(
            sampler=len(anim.samplers) - 1, target=gl.AnimationChannelTarget(node=node, path=path)
        )
    )


def _track(w: _Writer, anim: gl.Animation, times: int, node: int, mats: np.ndarray, moves: bool) -> None:
    trs = [_trs(m) for m in mats]
    rot = quaternion.make_continuous(np.array([r for _, r in trs]))
    _channel(w, anim, times, node, "rotation", rot)
    if moves:
        _channel(w, anim, times, node, "translation", np.array([t for t, _ in trs]))


@dataclass(frozen=True)
class Clip:
    """One animation: ``dofs`` ``(N, ndof)`` (table order, radians/metres) and per figure its placement
    ``(N, 4, 4)`` (Performer), sampled at ``fps``; ``extras`` go into the glTF animation as they are."""

    name: str
    fps: float
    dofs: np.ndarray
    placements: list[np.ndarray]
    extras: dict[str, Any] | None = None


def _animation(w: _Writer, rig: Rig, nodes: _Nodes, clip: Clip) -> gl.Animation:
    n = len(clip.dofs)
    frames = [local_transforms(rig, clip.dofs[i], [p[i] for p in clip.placements]) for i in range(n)]
    times = w.accessor((np.arange(n) / clip.fps).astype(np.float32), gl.SCALAR, bounds=True)
    anim = gl.Animation(name=clip.name, extras=clip.extras or {})
    translational = rig.translational
    starts = dof_starts(rig.table)
    for k, wf in enumerate(rig.wire):
        _track(w, anim, times, nodes.entries[k], clip.placements[k], moves=True)
        for row in range(1, len(wf.segment_names)):
            e = int(wf.entry[row])
            if e < 0:
                continue
            moves = bool(translational[starts[e] : starts[e] + len(wf.joints[e][1])].any())
            _track(w, anim, times, nodes.joints[k][row], np.array([f[k][row] for f in frames]), moves)
    return anim


def write_animations(rig: Rig, clips: Sequence[Clip], out: Path) -> None:
    """Write the rig, posed at the first clip's first frame, with one glTF animation per clip."""
    w = _Writer()
    first = clips[0]
    nodes = _write_rig(w, rig, first.dofs[0], [p[0] for p in first.placements])
    w.gltf.animations = [_animation(w, rig, nodes, clip) for clip in clips]
    w.write(out)


def _figure_files(cs: Channelset) -> list[str]:
    """The .fig files a channelset drives, in the order its channels first name them (the soldier first)."""
    return list(dict.fromkeys(c.protofiletype for c in cs.channels))


def _location(kin: FigureKinematics, placement: FigurePlacement | None, pose: np.ndarray) -> np.ndarray:
    """The figure's ``location`` (Jack) that puts the placement's root site where the channelset says."""
    if placement is None:
        return np.asarray(kin.figure.location, np.float64)
    m = placement.matrix()
    if placement.root == kin.root_name:
        return m
    return kin.location_for_site_global(placement.root, m, pose.astype(np.float64))


def channelset_motion(cs: Channelset, rig: Rig) -> tuple[np.ndarray, list[np.ndarray]]:
    """Per stored frame (not resampled): table-order DOFs ``(N, ndof)`` and per figure its placement
    ``(N, 4, 4)`` (Performer). A figure of the rig the channelset does not drive keeps its file's pose."""
    bound = bind_channelset(cs, rig.figures)
    kins = [FigureKinematics(f) for f in rig.figures]
    rests = [k.neutral_pose() for k in kins]  # a figure the clip does not drive stays as its file has it
    dofs, places = [], []
    for i in range(cs.nframes):
        s = bound.sample(float(i), interpolate=False)
        poses = [s.poses.get(f.name, neutral) for f, neutral in zip(rig.figures, rests, strict=True)]
        dofs.append(rig.table_dofs(poses))
        places.append(
            [_location(kin, s.placements.get(kin.figure.name), p) for kin, p in zip(kins, poses, strict=True)]
        )
    per_figure = [np.array([p[k] for p in places]) for k in range(len(rig.figures))]
    return np.array(dofs), [coords.transforms_jack_to_performer(p) for p in per_figure]


def export_channelset(
    path: Path, figures_dir: Path, *, gltf: Path | None = None, bvh: Path | None = None
) -> tuple[Rig, int]:
    """Write the channelset at ``path`` on its figures (from ``figures_dir``): a .glb with one animation,
    and/or a BVH of the soldier (``authoring.bvh_io``)."""
    cs = load_channelset(path)
    figures = [read_figure(figures_dir / name) for name in _figure_files(cs)]
    rig = rig_for(figures)
    dofs, placements = channelset_motion(cs, rig)
    if gltf is not None:
        write_animations(rig, [Clip(cs.name, cs.fps, dofs, placements)], gltf)
    if bvh is not None:
        from authoring.bvh_io import export_bvh

        export_bvh(rig, cs.fps, dofs, placements, bvh)
    return rig, cs.nframes


def export_posture_graph(path: Path, figures_dir: Path, out: Path) -> tuple[Rig, int]:
    """Write every channelset of a posture graph as one glTF animation each, on one rig (the figures they
    drive, the soldier first); each animation's ``extras.arcs`` lists the graph's arcs that play it as
    ``[from, to, "forward"|"backward"]``."""
    from server.motion.posture_change import load_posture_graph

    loaded = load_posture_graph(path)
    files = list(dict.fromkeys(name for cs in loaded.channelsets for name in _figure_files(cs)))
    rig = rig_for([read_figure(figures_dir / name) for name in files])
    clips = []
    for token, cs in enumerate(loaded.channelsets):
        arcs = [[a.start, a.end, a.direction] for a in loaded.graph.arcs if a.channelset == token]
        dofs, placements = channelset_motion(cs, rig)
        clips.append(Clip(cs.name, cs.fps, dofs, placements, {"arcs": arcs}))
    write_animations(rig, clips, out)
    return rig, len(clips)
