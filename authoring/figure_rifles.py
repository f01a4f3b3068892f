"""``AK_47.fig`` and ``M16.fig``: one rigid segment each, built from box and cylinder primitives.

Why primitives: the rifles only need a silhouette that reads as the weapon at simulation distances
(seed 002 pairs every soldier with a gun figure, ``create_soldier_state("s0","Di2_0","AK_47_0")``) and
sites the soldier's hands and shoulder attach to. Frame: origin at the trigger, barrel along -Z, +Y up;
lengths in cm. Sites (all parallel to the rifle frame):

* ``grip``      pistol grip, right side surface: where ``right_palm.palmcenter`` goes;
* ``handguard`` under the handguard: where ``left_palm.palmcenter`` goes;
* ``butt``      centre of the butt plate (against the shoulder);
* ``muzzle``    end of the barrel;
* ``sight``     the rear sight, on the line of sight;
* ``proximal``  the root site (the origin).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

from peabody.model import Figure, Psurf, Segment, Site

MATERIALS = {
    "wood": (0.45, 0.25, 0.12),
    "steel": (0.16, 0.16, 0.17),
    "polymer": (0.07, 0.07, 0.07),
}


@dataclass
class _Parts:
    """Accumulates primitives with a material each."""

    vertices: list[np.ndarray]
    faces: list[np.ndarray]
    materials: list[np.ndarray]
    names: tuple[str, ...]

    def add(self, mesh: trimesh.Trimesh, material: str) -> None:
        offset = sum(len(v) for v in self.vertices)
        self.vertices.append(np.asarray(mesh.vertices, dtype=np.float64))
        self.faces.append(np.asarray(mesh.faces, dtype=np.int64) + offset)
        self.materials.append(np.full(len(mesh.faces), self.names.index(material), dtype=np.int64))


def _parts(*materials: str) -> _Parts:
    return _Parts([], [], [], materials)


def block(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> trimesh.Trimesh:
    """Axis-aligned box between two corners."""
    lo_a, hi_a = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    t = np.eye(4)
    t[:3, 3] = 0.5 * (lo_a + hi_a)
    return trimesh.creation.box(extents=hi_a - lo_a, transform=t)


def warped_block(corner: Callable[[float, float, float], np.ndarray]) -> trimesh.Trimesh:
    """A hexahedron with the unit box's topology whose corner (sx, sy, sz) in {-1, 1}^3 is ``corner(...)``."""
    unit = trimesh.creation.box()
    signs = np.sign(np.asarray(unit.vertices))
    verts = np.array([corner(*s) for s in signs], dtype=np.float64)
    return trimesh.Trimesh(verts, np.asarray(unit.faces), process=False)


def slanted(
    top: tuple[float, float], bottom: tuple[float, float], half: tuple[float, float, float]
) -> trimesh.Trimesh:
    """A bar in the YZ plane from ``top`` (y, z) to ``bottom`` (y, z); half = (x, z at top, z at bottom)."""
    hx, dz_top, dz_bottom = half

    def corner(sx: float, sy: float, sz: float) -> np.ndarray:
        y, z = top if sy > 0 else bottom
        dz = dz_top if sy > 0 else dz_bottom
        return np.array([sx * hx, y, z + sz * dz])

    return warped_block(corner)


def tapered(
    z: tuple[float, float], y: tuple[tuple[float, float], tuple[float, float]], half_x: tuple[float, float]
) -> trimesh.Trimesh:
    """A hexahedron between two sections along Z, each given by (y low, y high) and a half-width."""

    def corner(sx: float, sy: float, sz: float) -> np.ndarray:
        i = 0 if sz < 0 else 1
        return np.array([sx * half_x[i], y[i][1] if sy > 0 else y[i][0], z[i]])

    return warped_block(corner)


def tube(radius: float, z0: float, z1: float, y: float, sections: int = 8) -> trimesh.Trimesh:
    """A cylinder along Z from ``z0`` to ``z1`` whose axis is at height ``y``."""
    t = np.eye(4)
    t[:3, 3] = (0.0, y, 0.5 * (z0 + z1))
    return trimesh.creation.cylinder(radius=radius, height=abs(z1 - z0), sections=sections, transform=t)


def curved_magazine(
    top_z: tuple[float, float],
    top_y: float,
    length: float,
    bend_deg: float,
    half_x: float,
    depth: float,
    pieces: int = 4,
) -> list[trimesh.Trimesh]:
    """A banana magazine: ``pieces`` hexahedra along an arc curving forward (-Z) as it goes down."""
    z_front, z_back = top_z
    radius = length / np.radians(bend_deg)
    centre = np.array([top_y, z_front - radius])  # (y, z) of the arc centre, ahead of the magazine
    out = []
    angles = np.linspace(0.0, np.radians(bend_deg), pieces + 1)

    def at(a: float, back: float) -> tuple[float, float]:
        r = radius + back
        return float(centre[0] - r * np.sin(a)), float(centre[1] + r * np.cos(a))

    width = (z_back - z_front) if depth <= 0 else depth
    for a0, a1 in itertools.pairwise(angles):

        def corner(sx: float, sy: float, sz: float, a0: float = a0, a1: float = a1) -> np.ndarray:
            a = a0 if sy > 0 else a1
            y, z = at(a, 0.0 if sz < 0 else width)
            return np.array([sx * half_x, y, z])

        out.append(warped_block(corner))
    return out


def ak47() -> tuple[_Parts, dict[str, np.ndarray]]:
    """AK-47 with fixed wooden stock: 88 cm overall, curved 30-round magazine."""
    p = _parts("steel", "wood")
    butt_z, muzzle_z = 36.0, -52.0
    p.add(block((-2.0, -1.0, -18.0), (2.0, 4.5, 12.0)), "steel")  # receiver
    p.add(tube(2.0, -17.0, 10.0, 4.5, sections=6), "steel")  # rounded dust cover
    p.add(tapered((12.0, butt_z), ((-1.0, 4.0), (-10.0, 1.5)), (1.8, 2.0)), "wood")  # stock drops to the butt
    p.add(slanted((-0.5, 4.0), (-11.0, 8.5), (1.6, 2.0, 1.6)), "wood")  # pistol grip
    p.add(block((-0.4, -4.0, -3.0), (0.4, -1.0, 3.5)), "steel")  # trigger guard
    for piece in curved_magazine((-10.0, -3.0), -1.0, 25.0, 35.0, 1.4, 0.0):
        p.add(piece, "steel")
    p.add(block((-2.6, -2.0, -40.0), (2.6, 2.8, -18.0)), "wood")  # lower handguard
    p.add(tube(1.4, -38.0, -18.0, 4.0, sections=6), "wood")  # upper handguard over the gas tube
    p.add(tube(0.9, -52.0, -38.0, 1.5, sections=6), "steel")  # barrel
    p.add(tube(0.7, -47.0, -38.0, 4.0, sections=6), "steel")  # gas tube
    p.add(block((-0.4, 1.5, -47.5), (0.4, 6.0, -46.0)), "steel")  # front sight post
    p.add(block((-1.0, 4.5, -18.5), (1.0, 6.3, -15.5)), "steel")  # rear sight block
    sites = {
        "grip": np.array([1.6, -5.5, 6.0]),
        "handguard": np.array([0.0, -2.0, -29.0]),
        "butt": np.array([0.0, -4.2, butt_z]),
        "muzzle": np.array([0.0, 1.5, muzzle_z]),
        "sight": np.array([0.0, 6.3, -17.0]),
    }
    return p, sites


def m16() -> tuple[_Parts, dict[str, np.ndarray]]:
    """M16A1: 99 cm overall, carry handle, straight 20-round magazine, round handguard."""
    p = _parts("polymer", "steel")
    butt_z, muzzle_z = 38.0, -61.0
    p.add(block((-2.2, -1.5, -14.0), (2.2, 4.5, 14.0)), "steel")  # upper + lower receiver
    p.add(tapered((14.0, butt_z), ((-1.5, 4.0), (-6.0, 4.0)), (2.0, 2.0)), "polymer")  # straight-line stock
    p.add(block((-1.0, 6.5, -8.0), (1.0, 8.0, 8.0)), "steel")  # carry handle
    p.add(block((-1.0, 4.5, -8.0), (1.0, 6.5, -6.0)), "steel")  # handle front post
    p.add(block((-1.0, 4.5, 5.0), (1.0, 6.5, 8.0)), "steel")  # handle rear post
    p.add(block((-0.6, 8.0, 5.5), (0.6, 9.2, 7.5)), "steel")  # rear sight
    p.add(slanted((-1.5, 3.5), (-12.0, 7.5), (1.5, 1.8, 1.5)), "polymer")  # pistol grip
    p.add(block((-0.4, -4.0, -3.0), (0.4, -1.5, 3.0)), "steel")  # trigger guard
    p.add(slanted((-1.5, -6.0), (-19.0, -7.0), (1.3, 3.0, 3.0)), "steel")  # straight magazine
    p.add(tube(2.6, -42.0, -14.0, 1.5, sections=10), "polymer")  # round handguard
    p.add(tube(0.8, -61.0, -42.0, 1.5, sections=6), "steel")  # barrel
    p.add(tube(1.1, -61.0, -57.0, 1.5, sections=6), "steel")  # flash hider
    p.add(slanted((8.0, -46.0), (1.0, -46.0), (0.6, 0.6, 1.4)), "steel")  # front sight base
    sites = {
        "grip": np.array([1.5, -6.0, 5.5]),
        "handguard": np.array([0.0, -1.1, -28.0]),
        "butt": np.array([0.0, -1.0, butt_z]),
        "muzzle": np.array([0.0, 1.5, muzzle_z]),
        "sight": np.array([0.0, 9.2, 6.5]),
    }
    return p, sites


def _translation(p: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = p
    return t


def rifle_figure(
    name: str, build: Callable[[], tuple[_Parts, dict[str, np.ndarray]]], psurf_file: str
) -> Figure:
    parts, sites = build()
    nodes = np.round(np.concatenate(parts.vertices), 4) + 0.0
    faces = np.concatenate(parts.faces)
    psurf = Psurf(
        nodes=nodes,
        faces=list(faces),
        face_attributes=np.concatenate(parts.materials),
        attributes=[{"name": m, "diffuse": MATERIALS[m], "ambient": MATERIALS[m]} for m in parts.names],
        filename=psurf_file,
    )
    fig = Figure(name)
    seg = fig.add_segment(Segment("rifle", psurf=psurf, psurf_file=psurf_file))
    seg.add_site(Site("proximal"))
    for site_name, p in sites.items():
        seg.add_site(Site(site_name, _translation(p)))
    fig.root = seg.sites["proximal"]
    return fig


def rifle_figures() -> dict[str, Figure]:
    return {
        "AK_47": rifle_figure("AK_47", ak47, "AK_47.pss"),
        "M16": rifle_figure("M16", m16, "M16.pss"),
    }
