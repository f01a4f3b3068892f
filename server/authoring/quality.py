"""Quality checks of the motion library: does it look like soldiers moving? (``ttes author check``).

Per clip (a channelset bound to its soldier figure and rifle; every frame, vectorised):

* ``foot_skate_cm`` — feet must not slide while they carry weight. Contact points (heel, ball, toe tip) are
  taken in the *world* frame: locomotion clips are recorded in place, so the entity's ground motion at the
  recorded ``ground_speed`` is added back (along -Z, the facing direction; +Z for backward clips). A point is
  in stance while it is on the ground (below ``CONTACT_HEIGHT_CM``) and slow (under ``CONTACT_SPEED``) or
  flat on it (below ``FLAT_HEIGHT_CM``); the skate of one stance is the largest horizontal distance between
  two of its frames.
* ``ground_penetration_cm`` — how far any body mesh node (every psurf: feet, knees, hands, the body when
  prone) goes below the ground plane y = 0.
* ``palm_rifle_cm`` — right palm centre to the rifle's ``grip``, left palm centre to its ``handguard``
  (``rifle_below_ground_cm`` is reported too, without a threshold).
* ``joint_limit_violations`` — recorded DOF values outside their joint limits (float32 slack allowed).
* ``max_frame_jump_deg`` — the largest joint-angle change between two consecutive frames (pops, IK flips).
* locomotion clips: ``stride_length`` (cm), ``ground_speed`` (cm/s) and the cadence they imply must be
  recorded (``locomotion_recorded``).

Across clips, along every posture graph: at each posture node the poses where arcs arrive (forward: last
frame, backward: first frame) and leave (forward: first, backward: last) must agree — ``continuity_deg``
(joint angles), ``continuity_root_cm`` / ``continuity_root_deg`` (the soldier's figure channel) and
``continuity_rifle_cm``, so a chain of posture changes never pops.

:func:`check_library` returns one object per clip, one per posture node and a ``summary`` with, per threshold,
the limit, the worst value, where it happened and pass/fail.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset
from server.motion.posture_change import LoadedPostureGraph, load_posture_graph
from server.peabody.fk import FigureKinematics
from server.peabody.model import Figure

THRESHOLDS: dict[str, float] = {
    "foot_skate_cm": 2.0,
    "ground_penetration_cm": 1.0,
    "palm_rifle_cm": 1.0,
    "joint_limit_violations": 0.0,
    "max_frame_jump_deg": 20.0,
    "continuity_deg": 0.5,
    "continuity_root_cm": 1.0,
    "continuity_root_deg": 0.5,
    "continuity_rifle_cm": 1.0,
}
CONTACT_HEIGHT_CM = 2.5
FLAT_HEIGHT_CM = 0.5
CONTACT_SPEED = 40.0  # cm/s, world frame
LIMIT_SLACK = 1e-4  # rad / cm: float32 rounding of recorded angles
CONTACT_SITES = ("{s}_foot.heel", "{s}_foot.ball", "{s}_toes.distal")
PALM_PAIRS = (("right_palm.palmcenter", "grip"), ("left_palm.palmcenter", "handguard"))
LOCOMOTION_GRAPH_WORDS = ("loco", "crawl")
BACKWARD_WORDS = ("bwalk", "backward", "back_walk", "walkback")


class QualityError(Exception):
    """A library that cannot be checked (missing figure, unbindable channelset); carries the file."""

    def __init__(self, message: str, source: str | None = None) -> None:
        super().__init__(f"{source}: {message}" if source else message)
        self.source = source


@dataclass
class FigureSet:
    """Figures (by file type, e.g. ``"DI.fig"``) with cached kinematics and mesh nodes."""

    figures: dict[str, Figure]

    def __post_init__(self) -> None:
        self.kin = {t: FigureKinematics(f) for t, f in self.figures.items()}
        self._nodes: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    @classmethod
    def from_dir(cls, folder: Path, types: Sequence[str]) -> FigureSet:
        from server.peabody.loader import read_figure

        figs = {}
        for t in types:
            path = Path(folder) / t
            if not path.is_file():
                raise QualityError(f"figure file {t!r} not found in {folder}")
            figs[t] = read_figure(path)
        return cls(figs)

    def nodes(self, ptype: str) -> tuple[np.ndarray, np.ndarray]:
        """Mesh nodes ``(k, 4)`` (homogeneous, segment frames) and their segments; sites if no psurfs."""
        hit = self._nodes.get(ptype)
        if hit is not None:
            return hit
        fig = self.figures[ptype]
        kin = self.kin[ptype]
        pts, segs = [], []
        for i, name in enumerate(kin.segment_names):
            seg = fig.segments[name]
            if seg.psurf is None or not len(seg.psurf.nodes):
                continue
            nodes = np.c_[
                np.asarray(seg.psurf.nodes, np.float64).reshape(-1, 3), np.ones(len(seg.psurf.nodes))
            ]
            if seg.psurf_transform is not None:
                nodes = nodes @ np.asarray(seg.psurf_transform).T
            pts.append(nodes)
            segs.append(np.full(len(nodes), i))
        if not pts:  # no geometry loaded: use the sites
            for s in fig.sites():
                if s.segment is None:
                    continue
                pts.append(np.asarray(s.location)[None, :, 3])
                segs.append(np.array([kin.segment_names.index(s.segment.name)]))
        out = (np.concatenate(pts), np.concatenate(segs))
        self._nodes[ptype] = out
        return out


@dataclass
class ClipFrames:
    """A channelset played on its figures: per figure file type, poses ``(n, ndof)`` and root globals."""

    channelset: Channelset
    poses: dict[str, np.ndarray]
    locations: dict[str, np.ndarray]


def play(channelset: Channelset, figures: FigureSet) -> ClipFrames:
    """Every frame of ``channelset`` as pose vectors and root-site globals for each figure type it drives."""
    types = sorted({c.protofiletype for c in channelset.channels})
    missing = [t for t in types if t not in figures.figures]
    if missing:
        raise QualityError(f"no figure of type {missing[0]!r} to play {channelset.name}", channelset.source)
    figs = [figures.figures[t] for t in types]
    bound = bind_channelset(channelset, figs)
    n = channelset.nframes
    poses, locs = {}, {}
    for bf in bound.figures:
        ptype = bf.protofiletype
        fig = figures.figures[ptype]
        kin = figures.kin[ptype]
        q = np.tile(bf.neutral.astype(np.float64), (n, 1))
        q[:, bf.dst] = channelset.joint_data[:, bf.src]
        if bf.figure_channel < 0:
            loc = np.broadcast_to(fig.location, (n, 4, 4)).copy()
        else:
            chan = next(c for c in channelset.figure_channels() if c.column == bf.figure_channel)
            loc = channelset.transforms(chan)
            roots = channelset.roots(chan)
            root = kin.root_name
            if any(r != root for r in roots):
                g = kin.site_globals(q, np.broadcast_to(np.eye(4), (n, 4, 4)))
                idx = np.array([kin.site_names.index(r) for r in roots])
                loc = loc @ np.linalg.inv(g[np.arange(n), idx]) @ g[:, kin.site_names.index(root)]
        poses[ptype] = q
        locs[ptype] = loc
    return ClipFrames(channelset, poses, locs)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of the runs of True."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def foot_skate(points: np.ndarray, fps: float) -> tuple[float, int]:
    """Largest horizontal slide (cm) of contact points ``(n, k, 3)`` (world) during stance, and the number
    of stance phases found."""
    n = points.shape[0]
    if n < 2:
        return 0.0, 0
    vel = np.gradient(points, axis=0) * fps
    speed = np.linalg.norm(vel[..., [0, 2]], axis=-1)
    y = points[..., 1]
    contact = ((y <= CONTACT_HEIGHT_CM) & (speed <= CONTACT_SPEED)) | (y <= FLAT_HEIGHT_CM)
    worst = 0.0
    count = 0
    for k in range(points.shape[1]):
        for a, b in _runs(contact[:, k]):
            if b - a < 3:
                continue
            count += 1
            xz = points[a:b, k][:, [0, 2]]
            d = np.sqrt(((xz[:, None, :] - xz[None, :, :]) ** 2).sum(-1)).max()
            worst = max(worst, float(d))
    return worst, count


def check_clip(
    clip: ClipFrames | Channelset,
    figures: FigureSet,
    *,
    locomotion: bool = False,
    direction: float | None = None,
    file: str | None = None,
) -> dict[str, Any]:
    """All per-clip metrics of one channelset (see the module docstring) and its pass/fail."""
    frames = clip if isinstance(clip, ClipFrames) else play(clip, figures)
    cs = frames.channelset
    n = cs.nframes
    t = np.arange(n) / cs.fps
    name = cs.name
    if direction is None:
        direction = 1.0 if any(w in name.lower() for w in BACKWARD_WORDS) else -1.0
    body_type = max(frames.poses, key=lambda k: figures.kin[k].ndof)
    rifle_type = next((k for k in frames.poses if k != body_type), None)
    kin = figures.kin[body_type]
    q, loc = frames.poses[body_type], frames.locations[body_type]
    out: dict[str, Any] = {
        "name": name,
        "file": file or cs.source,
        "figure": body_type,
        "rifle": rifle_type,
        "frames": n,
        "fps": cs.fps,
        "duration_s": round(cs.duration, 4),
        "locomotion": locomotion,
    }
    sites = kin.site_globals(q, loc)
    # ground motion added back for in-place locomotion
    speed = cs.ground_speed
    stride = cs.stride_length
    shift = np.zeros((n, 3))
    if locomotion and speed is not None:
        shift[:, 2] = direction * speed * t
    contact_names = [c.format(s=side) for side in ("left", "right") for c in CONTACT_SITES]
    contact_idx = [kin.site_names.index(s) for s in contact_names if s in kin.site_names]
    pts = sites[:, contact_idx][..., :3, 3] + shift[:, None, :]
    skate, stances = foot_skate(pts, cs.fps)
    out["foot_skate_cm"] = round(skate, 3)
    out["stance_phases"] = stances
    # ground penetration over the whole body mesh
    nodes, segs = figures.nodes(body_type)
    segg = kin.segment_globals(q, loc)  # (n, nseg, 4, 4)
    ys = np.einsum("fkj,kj->fk", segg[:, segs, 1, :], nodes)
    low = np.unravel_index(int(np.argmin(ys)), ys.shape)
    out["ground_penetration_cm"] = round(max(0.0, -float(ys[low])), 3)
    out["lowest_segment"] = kin.segment_names[int(segs[low[1]])]
    # palms on the rifle
    if rifle_type is not None:
        rk = figures.kin[rifle_type]
        rs = rk.site_globals(frames.poses[rifle_type], frames.locations[rifle_type])
        rnames = {s.split(".", 1)[1]: i for i, s in enumerate(rk.site_names)}
        worst = 0.0
        for palm, rsite in PALM_PAIRS:
            if palm in kin.site_names and rsite in rnames:
                d = np.linalg.norm(
                    sites[:, kin.site_names.index(palm), :3, 3] - rs[:, rnames[rsite], :3, 3], axis=-1
                )
                out[f"{palm.split('.')[0]}_rifle_cm"] = round(float(d.max()), 3)
                worst = max(worst, float(d.max()))
        out["palm_rifle_cm"] = round(worst, 3)
        rnodes, rsegs = figures.nodes(rifle_type)  # information only: a muzzle in the dirt is worth seeing
        rg = rk.segment_globals(frames.poses[rifle_type], frames.locations[rifle_type])
        ry = np.einsum("fkj,kj->fk", rg[:, rsegs, 1, :], rnodes)
        out["rifle_below_ground_cm"] = round(max(0.0, -float(ry.min(initial=np.inf))), 3)
    # joint limits and pops
    viol = (q < kin.lower - LIMIT_SLACK) | (q > kin.upper + LIMIT_SLACK)
    out["joint_limit_violations"] = int(viol.sum())
    if viol.any():
        bad = np.flatnonzero(viol.any(axis=0))
        names = [j for j, sl in kin.dof_slices.items() if np.any((bad >= sl.start) & (bad < sl.stop))]
        out["violating_joints"] = names
    rot = np.array([d.kind == "R" for j in figures.figures[body_type].joints.values() for d in j.dofs])
    jump = np.abs(np.diff(q[:, rot], axis=0)).max(initial=0.0)
    out["max_frame_jump_deg"] = round(float(np.degrees(jump)), 3)
    if locomotion:
        out["stride_length"] = stride
        out["ground_speed"] = speed
        out["cadence"] = round(speed / stride, 4) if speed and stride else None
        out["locomotion_recorded"] = speed is not None and stride is not None
    failures = [k for k, lim in THRESHOLDS.items() if k in out and out[k] is not None and out[k] > lim]
    if locomotion and not out["locomotion_recorded"]:
        failures.append("locomotion_recorded")
    out["failures"] = failures
    out["pass"] = not failures
    return out


def _endpoint(clips: Mapping[int, ClipFrames], token: int, forward: bool, arrive: bool) -> dict[str, Any]:
    cf = clips[token]
    last = cf.channelset.nframes - 1
    frame = (last if forward else 0) if arrive else (0 if forward else last)
    return {"clip": cf.channelset.name, "frame": frame, "cf": cf}


def check_continuity(
    loaded: LoadedPostureGraph, clips: Mapping[int, ClipFrames], figures: FigureSet
) -> list[dict]:
    """Per posture node, the largest disagreement between the poses of arcs arriving and leaving there."""
    by_node: dict[str, list[dict[str, Any]]] = {}
    for arc in loaded.graph.arcs:
        fwd = arc.forward
        by_node.setdefault(arc.end, []).append(_endpoint(clips, arc.channelset, fwd, True))
        by_node.setdefault(arc.start, []).append(_endpoint(clips, arc.channelset, fwd, False))
    out = []
    for node, ends in by_node.items():
        worst = {"deg": 0.0, "root_cm": 0.0, "root_deg": 0.0, "rifle_cm": 0.0}
        pair: dict[str, list[str]] = {k: [] for k in worst}
        for i in range(len(ends)):
            for j in range(i + 1, len(ends)):
                a, b = ends[i], ends[j]
                d = _difference(a["cf"], a["frame"], b["cf"], b["frame"], figures)
                for k, v in d.items():
                    if v > worst[k]:
                        worst[k] = v
                        pair[k] = [f"{a['clip']}[{a['frame']}]", f"{b['clip']}[{b['frame']}]"]
        out.append(
            {
                "graph": loaded.name,
                "posture": node,
                "endpoints": len(ends),
                "continuity_deg": round(worst["deg"], 4),
                "continuity_root_cm": round(worst["root_cm"], 4),
                "continuity_root_deg": round(worst["root_deg"], 4),
                "continuity_rifle_cm": round(worst["rifle_cm"], 4),
                "worst_pair": pair["deg"] or pair["root_cm"] or pair["rifle_cm"],
            }
        )
    for row in out:
        fails = [
            k
            for k in ("continuity_deg", "continuity_root_cm", "continuity_root_deg", "continuity_rifle_cm")
            if row[k] > THRESHOLDS[k]
        ]
        row["failures"] = fails
        row["pass"] = not fails
    return out


def _difference(a: ClipFrames, fa: int, b: ClipFrames, fb: int, figures: FigureSet) -> dict[str, float]:
    out = {"deg": 0.0, "root_cm": 0.0, "root_deg": 0.0, "rifle_cm": 0.0}
    for ptype in set(a.poses) & set(b.poses):
        kin = figures.kin[ptype]
        if kin.ndof:
            rot = np.array([d.kind == "R" for j in figures.figures[ptype].joints.values() for d in j.dofs])
            dq = np.abs(a.poses[ptype][fa] - b.poses[ptype][fb])
            out["deg"] = max(out["deg"], float(np.degrees(dq[rot].max(initial=0.0))))
        la, lb = a.locations[ptype][fa], b.locations[ptype][fb]
        dp = float(np.linalg.norm(la[:3, 3] - lb[:3, 3]))
        cos = np.clip((np.trace(la[:3, :3].T @ lb[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
        if kin.ndof:
            out["root_cm"] = max(out["root_cm"], dp)
            out["root_deg"] = max(out["root_deg"], float(np.degrees(np.arccos(cos))))
        else:
            out["rifle_cm"] = max(out["rifle_cm"], dp)
    return out


def _is_locomotion(graph_path: Path) -> bool:
    stem = graph_path.stem.lower()
    return any(w in stem for w in LOCOMOTION_GRAPH_WORDS)


def check_library(
    graphs: Sequence[str | Path],
    figures_dir: str | Path,
    *,
    clips: Sequence[str | Path] = (),
    figures: FigureSet | None = None,
) -> dict[str, Any]:
    """Check every clip of the posture graphs (and any extra channelset files) and every graph's continuity.

    Figures are read from ``figures_dir`` by the channelsets' protofiletypes. Returns ``{"clips": [...],
    "continuity": [...], "summary": {...}}``; ``summary["pass"]`` is False when any threshold fails.
    """
    from server.motion.cache import load_channelset

    figset = figures or FigureSet({})
    seen: dict[str, dict[str, Any]] = {}
    continuity: list[dict] = []

    def figures_for(cs: Channelset) -> None:
        need = sorted({c.protofiletype for c in cs.channels} - set(figset.figures))
        if need:
            extra = FigureSet.from_dir(Path(figures_dir), need)
            figset.figures.update(extra.figures)
            figset.kin.update(extra.kin)

    for gpath in map(Path, graphs):
        loaded = load_posture_graph(gpath)
        loco = _is_locomotion(gpath)
        played: dict[int, ClipFrames] = {}
        for token, (cs, fname) in enumerate(zip(loaded.channelsets, loaded.graph.files, strict=True)):
            figures_for(cs)
            cf = play(cs, figset)
            played[token] = cf
            key = str((gpath.parent / fname).resolve())
            if key not in seen:
                seen[key] = check_clip(cf, figset, locomotion=loco, file=str(gpath.parent / fname))
                seen[key]["graphs"] = [gpath.name]
            elif gpath.name not in seen[key]["graphs"]:
                seen[key]["graphs"].append(gpath.name)
        continuity.extend(check_continuity(loaded, played, figset))
    for path in map(Path, clips):
        key = str(path.resolve())
        if key in seen:
            continue
        cs = load_channelset(path)
        figures_for(cs)
        seen[key] = check_clip(play(cs, figset), figset, file=str(path))
        seen[key]["graphs"] = []
    clip_rows = list(seen.values())
    return {"clips": clip_rows, "continuity": continuity, "summary": summarise(clip_rows, continuity)}


def summarise(clips: Sequence[Mapping[str, Any]], continuity: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per threshold: limit, worst value, where, pass; plus counts and the overall verdict."""
    rows: dict[str, Any] = {}
    for key, limit in THRESHOLDS.items():
        source = continuity if key.startswith("continuity") else clips
        vals = [(r[key], r) for r in source if r.get(key) is not None]
        if not vals:
            rows[key] = {"limit": limit, "worst": None, "where": None, "failing": 0, "pass": True}
            continue
        worst, row = max(vals, key=lambda x: x[0])
        where = row.get("name") or f"{row.get('graph')}:{row.get('posture')}"
        failing = sum(1 for v, _ in vals if v > limit)
        rows[key] = {"limit": limit, "worst": worst, "where": where, "failing": failing, "pass": failing == 0}
    loco = [c for c in clips if c.get("locomotion")]
    missing = [c["name"] for c in loco if not c.get("locomotion_recorded")]
    rows["locomotion_recorded"] = {
        "limit": "stride_length and ground_speed on every locomotion clip",
        "worst": None if not missing else f"{len(missing)} missing",
        "where": missing[0] if missing else None,
        "failing": len(missing),
        "pass": not missing,
    }
    ok = all(r["pass"] for r in rows.values())
    return {
        "clips": len(clips),
        "clips_failing": sum(1 for c in clips if not c.get("pass", True)),
        "postures_checked": len(continuity),
        "thresholds": rows,
        "pass": ok,
    }
