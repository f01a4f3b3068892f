"""Quality checks of the motion library: does it look like soldiers moving? (``ttes author check``).

Everything is measured on every frame, vectorised, in the *world* frame: locomotion clips are recorded in
place, so the entity's ground motion at the recorded ``ground_speed`` is added back (along -Z, the facing
direction; +Z for backward clips; the crawl too); clips with an ``end_offset`` really move and need nothing.

Per clip (a channelset bound to its soldier figure and rifle):

* contacts, by **height alone** (a fast skim just above the ground is sliding, not swinging): every mesh node
  (psurf node) below ``CONTACT_HEIGHT_CM`` is on the ground, and its slide is the horizontal extent of its
  positions over one such run of frames (:mod:`server.authoring.body_parts`). ``foot_skate_cm`` is the worst
  over the feet (heels, balls, toes), ``contact_slide_cm`` over every other part (knees, hands, forearms,
  upper arms, chest, belly, pelvis, head), ``contact_slide_part`` names it, ``contact_slides`` has each part.
* ``ground_penetration_cm`` (body mesh below y = 0), ``rifle_penetration_cm`` (rifle mesh below y = 0) and
  ``rifle_in_body_cm``: how deep rifle mesh nodes go into the body, measured against the convex hull (Qhull)
  of each body segment's mesh in the segment's frame — the hands and fingers that hold it excepted — with
  bounding spheres to pick the candidate (frame, segment, node) triples first.
* ``palm_rifle_cm`` — right palm centre to the rifle's ``grip``, left palm centre to its ``handguard``, only
  while the rifle is held (before the channelset's ``release_frame``).
* ``end_speed_m_s`` — at each end of the clip that is a static posture (both ends of a static-graph clip, the
  base-posture ends of locomotion clips), the fastest site (body and rifle) over the first/last
  ``END_FRAMES`` frames: things ease in and out, deaths end at rest.
* ``joint_limit_violations`` (float32 slack allowed) and ``max_frame_jump_deg`` (pops, IK flips).
* locomotion clips: ``stride_length`` (cm), ``ground_speed`` (cm/s) and the cadence they imply must be
  recorded (``locomotion_recorded``); cycle clips are judged for realism, ``gait_speed_m_s`` and
  ``gait_steps_per_s`` against ``GAIT_LIMITS`` (a walk or run cycle clip holds one step, cut at footfalls;
  the crawl cycle both legs' moves).

Across clips, along every posture graph, at each posture node:

* continuity: the poses where arcs arrive (forward: last frame, backward: first frame) and leave must agree —
  ``continuity_deg`` (joint angles), ``continuity_root_cm`` / ``continuity_root_deg`` (the figure channel)
  and ``continuity_rifle_cm``. A clip's last frame is taken back by its ``end_offset`` (the ground-plane
  move ``x, z, yaw about +Y``) before it is compared, so a turn arrives at its posture.
* resting postures rest (``REST_PARTS``; ``NAME@variant`` is a variant of ``NAME``): at every endpoint the
  weight-bearing parts' lowest nodes are on the ground, ``rest_contact_cm`` (prone: chest or belly and both
  forearms; kneeling: the right kneecap; crawl: both kneecaps and forearms; DEAD: the lowest point, the
  pelvis and the chest or belly) and, DEAD only, ``rest_foot_cm`` (each foot's heel and lowest node).

:func:`check_library` returns one object per clip, one per posture node and a ``summary`` with, per threshold,
the limit, the worst value, where it happened and pass/fail.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from server.authoring.body_parts import (
    FOOT_PARTS,
    HAND_PARTS,
    KNEE_RADIUS_CM,
    SegmentHulls,
    contact_slides,
    part_of,
)
from server.motion.binding import bind_channelset
from server.motion.channelset import Channelset
from server.motion.posture_change import LoadedPostureGraph, load_posture_graph
from server.peabody.fk import FigureKinematics
from server.peabody.model import Figure

THRESHOLDS: dict[str, float] = {
    "foot_skate_cm": 2.0,
    "contact_slide_cm": 3.0,
    "ground_penetration_cm": 1.0,
    "rifle_penetration_cm": 1.0,
    "rifle_in_body_cm": 1.0,
    "palm_rifle_cm": 1.0,
    "end_speed_m_s": 0.5,
    "joint_limit_violations": 0.0,
    "max_frame_jump_deg": 20.0,
    "continuity_deg": 0.5,
    "continuity_root_cm": 1.0,
    "continuity_root_deg": 0.5,
    "continuity_rifle_cm": 1.0,
    "rest_contact_cm": 2.0,
    "rest_foot_cm": 15.0,
}
POSTURE_KEYS = (
    "continuity_deg",
    "continuity_root_cm",
    "continuity_root_deg",
    "continuity_rifle_cm",
    "rest_contact_cm",
    "rest_foot_cm",
)
# (low, high) per gait family of cycle clips; None: recorded only
GAIT_LIMITS: dict[str, dict[str, tuple[float, float] | None]] = {
    "walk": {"gait_speed_m_s": (1.2, 1.6), "gait_steps_per_s": (1.7, 2.1)},
    "run": {"gait_speed_m_s": (3.0, 5.0), "gait_steps_per_s": None},
    "crawl": {"gait_speed_m_s": (0.3, 0.6), "gait_steps_per_s": None},
    "bwalk": {"gait_speed_m_s": None, "gait_steps_per_s": None},
}
STEPS_PER_CYCLE_CLIP = {"crawl": 2}  # gait.py cuts one step per cycle clip; crawl.py one full cycle
# weight-bearing parts of resting postures ("chest|belly": either of them)
REST_PARTS: dict[str, tuple[str, ...]] = {
    "PRONE": ("chest|belly", "left_forearm", "right_forearm"),
    "KNEEL": ("right_kneecap",),
    "CRAWL": ("left_kneecap", "right_kneecap", "left_forearm", "right_forearm"),
    "DEAD": ("lowest", "pelvis", "chest|belly"),
}
CONTACT_HEIGHT_CM = 2.5
END_FRAMES = 3  # frames over which an end's speed is measured
LIMIT_SLACK = 1e-4  # rad / cm: float32 rounding of recorded angles
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
        self._cache: dict[str, Any] = {}

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

    def node_parts(self, ptype: str) -> np.ndarray:
        """Per mesh node its body part (``left_foot``, ``chest``, ...; kneecap nodes are ``*_kneecap``)."""
        key = f"parts:{ptype}"
        hit = self._cache.get(key)
        if hit is None:
            nodes, segs = self.nodes(ptype)
            kin, fig = self.kin[ptype], self.figures[ptype]
            hit = np.array([part_of(kin.segment_names[s]) for s in segs], dtype=object)
            for side in ("left", "right"):
                name = f"{side}_lower_leg"
                if f"{name}.knee" not in kin.site_names:
                    continue
                knee = np.asarray(fig.site(f"{name}.knee").location)[:3, 3]
                near = np.linalg.norm(nodes[:, :3] - knee, axis=1) < KNEE_RADIUS_CM
                hit[(segs == kin.segment_names.index(name)) & near] = f"{side}_kneecap"
            self._cache[key] = hit
        return hit

    def hulls(self, ptype: str) -> SegmentHulls:
        """Convex hulls of the body segments a rifle must stay out of (all but the hands)."""
        key = f"hulls:{ptype}"
        hit = self._cache.get(key)
        if hit is None:
            nodes, segs = self.nodes(ptype)
            names = self.kin[ptype].segment_names
            keep = np.array([s for s in np.unique(segs) if part_of(names[s]) not in HAND_PARTS], dtype=int)
            hit = SegmentHulls.build(nodes, segs, keep)
            self._cache[key] = hit
        return hit


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
    """Largest horizontal slide (cm) of contact points ``(n, k, 3)`` (world) while below the contact height
    (judged by height alone), and the number of contact runs of three frames or more."""
    del fps  # contact no longer depends on speed: a fast skim at ground level is a slide
    if points.shape[0] < 2:
        return 0.0, 0
    slide, _ = contact_slides(points, CONTACT_HEIGHT_CM)
    phases = sum(1 for k in range(points.shape[1]) for a, b in _runs(points[:, k, 1] <= CONTACT_HEIGHT_CM)
                 if b - a >= 3)  # fmt: skip
    return float(slide.max(initial=0.0)), phases


def ground_shift(cs: Channelset, locomotion: bool, direction: float | None = None) -> np.ndarray:
    """``(n, 3)`` world travel to add to an in-place locomotion clip (zeros for every other clip)."""
    n = cs.nframes
    shift = np.zeros((n, 3))
    if locomotion and cs.ground_speed is not None:
        if direction is None:
            direction = 1.0 if any(w in cs.name.lower() for w in BACKWARD_WORDS) else -1.0
        shift[:, 2] = direction * cs.ground_speed * np.arange(n) / cs.fps
    return shift


def gait_family(name: str) -> str | None:
    """``walk``, ``bwalk``, ``run`` or ``crawl`` for a locomotion cycle clip's name, else None."""
    low = name.lower()
    if "cycle" not in low:
        return None
    return next((f for f in ("bwalk", "walk", "run", "crawl") if low.startswith(f)), None)


def end_speeds(pos: np.ndarray, names: Sequence[str], fps: float) -> dict[str, tuple[float, str]]:
    """Fastest site (m/s, name) of ``pos`` ``(n, k, 3)`` over the first and the last ``END_FRAMES``."""
    n = pos.shape[0]
    out: dict[str, tuple[float, str]] = {}
    if n < 2:
        return {"first": (0.0, ""), "last": (0.0, "")}
    k = min(END_FRAMES, n - 1)
    for end, part in (("first", pos[: k + 1]), ("last", pos[n - 1 - k :])):
        v = np.linalg.norm(np.diff(part, axis=0), axis=-1).max(axis=0) * fps / 100.0
        i = int(np.argmax(v))
        out[end] = (float(v[i]), names[i])
    return out


def _range_distance(value: float, limits: tuple[float, float] | None) -> float:
    """How far ``value`` lies outside ``limits`` (negative inside, ``-inf`` without limits)."""
    return -np.inf if limits is None else max(limits[0] - value, value - limits[1])


def _range_failure(value: float | None, limits: tuple[float, float] | None) -> bool:
    return value is not None and limits is not None and not (limits[0] <= value <= limits[1])


def check_clip(
    clip: ClipFrames | Channelset,
    figures: FigureSet,
    *,
    locomotion: bool = False,
    direction: float | None = None,
    file: str | None = None,
    static_ends: tuple[bool, bool] | None = None,
) -> dict[str, Any]:
    """All per-clip metrics of one channelset (see the module docstring) and its pass/fail.

    ``static_ends``: whether the first and the last frame are static postures (speeds are checked there);
    default: both for a static clip, neither for a locomotion clip."""
    frames = clip if isinstance(clip, ClipFrames) else play(clip, figures)
    cs = frames.channelset
    n = cs.nframes
    name = cs.name
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
    shift = ground_shift(cs, locomotion, direction)
    sites = kin.site_globals(q, loc)
    # every mesh node in the world: contacts and ground penetration
    nodes, segs = figures.nodes(body_type)
    parts = figures.node_parts(body_type)
    segg = kin.segment_globals(q, loc)  # (n, nseg, 4, 4)
    pts = np.einsum("fkij,kj->fki", segg[:, segs, :3, :], nodes) + shift[:, None, :]
    slide, _ = contact_slides(pts, CONTACT_HEIGHT_CM)
    feet = np.isin(parts, FOOT_PARTS)
    per_part: dict[str, float] = {}
    for p in np.unique(parts[slide > 0]):
        per_part[str(p)] = round(float(slide[parts == p].max()), 3)
    out["contact_slides"] = per_part
    for key, mask in (("foot_skate", feet), ("contact_slide", ~feet)):
        i = int(np.argmax(np.where(mask, slide, -1.0)))
        val = float(slide[i]) if mask[i] else 0.0
        out[f"{key}_cm"] = round(val, 3)
        out[f"{key}_part"] = str(parts[i]).replace("_kneecap", "_knee") if val > 0 else None
    foot_down = np.stack([(pts[:, parts == f, 1] <= CONTACT_HEIGHT_CM).any(axis=1) for f in FOOT_PARTS
                          if (parts == f).any()])  # fmt: skip
    out["stance_phases"] = sum(1 for row in foot_down for a, b in _runs(row) if b - a >= 3)
    ys = pts[..., 1]
    low = np.unravel_index(int(np.argmin(ys)), ys.shape)
    out["ground_penetration_cm"] = round(max(0.0, -float(ys[low])), 3)
    out["lowest_segment"] = kin.segment_names[int(segs[low[1]])]
    site_pos = sites[..., :3, 3] + shift[:, None, :]
    site_names = list(kin.site_names)
    if rifle_type is not None:
        rk = figures.kin[rifle_type]
        rq, rloc = frames.poses[rifle_type], frames.locations[rifle_type]
        rs = rk.site_globals(rq, rloc)
        rnames = {s.split(".", 1)[1]: i for i, s in enumerate(rk.site_names)}
        held = n if cs.release_frame is None else cs.release_frame
        out["release_frame"] = cs.release_frame
        worst = 0.0
        for palm, rsite in PALM_PAIRS:
            if palm in kin.site_names and rsite in rnames and held > 0:
                d = np.linalg.norm(
                    sites[:held, kin.site_names.index(palm), :3, 3] - rs[:held, rnames[rsite], :3, 3], axis=-1
                )
                out[f"{palm.split('.')[0]}_rifle_cm"] = round(float(d.max()), 3)
                worst = max(worst, float(d.max()))
        out["palm_rifle_cm"] = round(worst, 3)
        rnodes, rsegs = figures.nodes(rifle_type)
        rg = rk.segment_globals(rq, rloc)
        rpts = np.einsum("fkij,kj->fki", rg[:, rsegs, :3, :], rnodes)
        out["rifle_penetration_cm"] = round(max(0.0, -float(rpts[..., 1].min(initial=np.inf))), 3)
        depth, frame, seg = figures.hulls(body_type).depth(rpts, segg)
        out["rifle_in_body_cm"] = round(depth, 3)
        out["rifle_in_body_where"] = f"{kin.segment_names[seg]}[{frame}]" if seg >= 0 else None
        site_pos = np.concatenate([site_pos, rs[..., :3, 3] + shift[:, None, :]], axis=1)
        site_names += list(rk.site_names)
    # speeds at the ends that are static postures
    if static_ends is None:
        static_ends = (not locomotion, not locomotion)
    speeds = end_speeds(site_pos, site_names, cs.fps)
    checked = [(end, *speeds[end]) for end, ok in zip(("first", "last"), static_ends, strict=True) if ok]
    out["end_speeds_m_s"] = {end: round(v, 3) for end, (v, _) in speeds.items()}
    if checked:
        end, v, site = max(checked, key=lambda c: c[1])
        out["end_speed_m_s"] = round(v, 3)
        out["end_speed_where"] = f"{site} ({end} frames)"
    else:
        out["end_speed_m_s"] = None
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
    failures = [k for k, lim in THRESHOLDS.items() if k in out and out[k] is not None and out[k] > lim]
    if locomotion:
        speed, stride = cs.ground_speed, cs.stride_length
        out["stride_length"] = stride
        out["ground_speed"] = speed
        out["cadence"] = round(speed / stride, 4) if speed and stride else None
        out["locomotion_recorded"] = speed is not None and stride is not None
        if not out["locomotion_recorded"]:
            failures.append("locomotion_recorded")
        family = gait_family(name)
        if family is not None and out["locomotion_recorded"] and cs.duration > 0:
            out["gait"] = family
            out["gait_speed_m_s"] = round(float(speed) / 100.0, 4)
            out["gait_steps_per_s"] = round(STEPS_PER_CYCLE_CLIP.get(family, 1) / cs.duration, 4)
            for key, limits in GAIT_LIMITS[family].items():
                if _range_failure(out[key], limits):
                    failures.append(key)
    out["failures"] = failures
    out["pass"] = not failures
    return out


# --- posture nodes: continuity and resting postures ------------------------------------------------------


def offset_transform(offset: tuple[float, float, float] | None) -> np.ndarray:
    """The ground-plane rigid move of an ``end_offset`` (x cm, z cm, yaw degrees about +Y, + = left)."""
    m = np.eye(4)
    if offset is None:
        return m
    x, z, yaw = offset
    c, s = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
    m[:3, :3] = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
    m[0, 3], m[2, 3] = x, z
    return m


def posture_location(cf: ClipFrames, frame: int, ptype: str) -> np.ndarray:
    """A figure's root global at ``frame``, the clip's own move taken out at its last frame (``end_offset``)
    so it can be compared with the posture where other arcs arrive or leave."""
    loc = cf.locations[ptype][frame]
    if frame == cf.channelset.nframes - 1 and cf.channelset.end_offset is not None:
        loc = np.linalg.inv(offset_transform(cf.channelset.end_offset)) @ loc
    return loc


def rest_kind(node: str) -> str | None:
    """``PRONE``, ``KNEEL``, ``CRAWL`` or ``DEAD`` for a resting posture node (``NAME@variant`` too)."""
    base = node.split("@", 1)[0]
    if base in ("CRAWL", "DEAD"):
        return base
    m = re.match(r"(PRONE|KNEEL)_", base)
    return m.group(1) if m else None


def part_lows(cf: ClipFrames, frame: int, figures: FigureSet) -> dict[str, float]:
    """Height (cm) of the lowest mesh node of every body part at one frame (kneecaps as ``*_kneecap``,
    ``lowest`` the whole body, ``*_heel`` the heel sites)."""
    body = max(cf.poses, key=lambda k: figures.kin[k].ndof)
    kin = figures.kin[body]
    nodes, segs = figures.nodes(body)
    parts = figures.node_parts(body)
    g = kin.segment_globals(cf.poses[body][frame : frame + 1], cf.locations[body][frame : frame + 1])[0]
    y = np.einsum("kj,kj->k", g[segs, 1, :], nodes)
    out = {str(p): float(y[parts == p].min()) for p in np.unique(parts)}
    for side in ("left", "right"):  # a kneecap is part of the knee too
        if f"{side}_kneecap" in out and f"{side}_knee" in out:
            out[f"{side}_knee"] = min(out[f"{side}_knee"], out[f"{side}_kneecap"])
    out["lowest"] = float(y.min())
    out["chest|belly"] = min(out.get("chest", np.inf), out.get("belly", np.inf))
    sg = kin.site_globals(cf.poses[body][frame : frame + 1], cf.locations[body][frame : frame + 1])[0]
    for side in ("left", "right"):
        if f"{side}_foot.heel" in kin.site_names:
            out[f"{side}_heel"] = float(sg[kin.site_names.index(f"{side}_foot.heel"), 1, 3])
    return out


def rest_endpoint(cf: ClipFrames, frame: int, figures: FigureSet, kind: str) -> dict[str, Any]:
    """The weight-bearing parts of a resting posture at one endpoint: their heights and the worst."""
    lows = part_lows(cf, frame, figures)
    parts = {p: round(lows.get(p, np.inf), 3) for p in REST_PARTS[kind]}
    worst = max(parts, key=lambda p: parts[p])
    row: dict[str, Any] = {
        "clip": cf.channelset.name,
        "frame": frame,
        "parts_cm": parts,
        "rest_contact_cm": parts[worst],
        "rest_part": worst,
    }
    if kind == "DEAD":
        feet = {
            side: max(lows.get(f"{side}_foot", -np.inf), lows.get(f"{side}_heel", -np.inf))
            for side in ("left", "right")
        }
        side = max(feet, key=lambda s: feet[s])
        row["rest_foot_cm"] = round(feet[side], 3)
        row["rest_foot"] = f"{side}_foot"
    return row


def _endpoint(clips: Mapping[int, ClipFrames], token: int, forward: bool, arrive: bool) -> dict[str, Any]:
    cf = clips[token]
    last = cf.channelset.nframes - 1
    frame = (last if forward else 0) if arrive else (0 if forward else last)
    return {"clip": cf.channelset.name, "frame": frame, "cf": cf}


def check_continuity(
    loaded: LoadedPostureGraph, clips: Mapping[int, ClipFrames], figures: FigureSet
) -> list[dict]:
    """Per posture node, the largest disagreement between the poses of arcs arriving and leaving there, and
    for resting postures whether the weight-bearing parts are on the ground at every endpoint."""
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
        row: dict[str, Any] = {
            "graph": loaded.name,
            "posture": node,
            "endpoints": len(ends),
            "continuity_deg": round(worst["deg"], 4),
            "continuity_root_cm": round(worst["root_cm"], 4),
            "continuity_root_deg": round(worst["root_deg"], 4),
            "continuity_rifle_cm": round(worst["rifle_cm"], 4),
            "worst_pair": pair["deg"] or pair["root_cm"] or pair["rifle_cm"],
        }
        kind = rest_kind(node)
        if kind is not None:
            seen: dict[tuple[str, int], dict[str, Any]] = {}
            for e in ends:
                if (e["clip"], e["frame"]) not in seen:
                    seen[(e["clip"], e["frame"])] = rest_endpoint(e["cf"], e["frame"], figures, kind)
            rest = list(seen.values())
            w = max(rest, key=lambda r: r["rest_contact_cm"])
            row.update(rest=rest, rest_kind=kind, rest_contact_cm=w["rest_contact_cm"])
            row["rest_where"] = f"{w['clip']}[{w['frame']}] {w['rest_part']}"
            if kind == "DEAD":
                wf = max(rest, key=lambda r: r["rest_foot_cm"])
                row["rest_foot_cm"] = wf["rest_foot_cm"]
                row["rest_foot_where"] = f"{wf['clip']}[{wf['frame']}] {wf['rest_foot']}"
        out.append(row)
    for row in out:
        fails = [k for k in POSTURE_KEYS if row.get(k) is not None and row[k] > THRESHOLDS[k]]
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
        la, lb = posture_location(a, fa, ptype), posture_location(b, fb, ptype)
        dp = float(np.linalg.norm(la[:3, 3] - lb[:3, 3]))
        cos = np.clip((np.trace(la[:3, :3].T @ lb[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
        if kin.ndof:
            out["root_cm"] = max(out["root_cm"], dp)
            out["root_deg"] = max(out["root_deg"], float(np.degrees(np.arccos(cos))))
        else:
            out["rifle_cm"] = max(out["rifle_cm"], dp)
    return out


# --- the library ------------------------------------------------------------------------------------------


def _is_locomotion(graph_path: Path) -> bool:
    stem = graph_path.stem.lower()
    return any(w in stem for w in LOCOMOTION_GRAPH_WORDS)


def static_nodes(loaded: LoadedPostureGraph, locomotion: bool) -> set[str]:
    """Posture nodes where the soldier stands still: every node of a static graph; in a locomotion graph
    those no cycle clip touches (``STAND_STOWED``, ``CRAWL``; not ``WALK_L`` or ``CRAWLING``)."""
    nodes = {n for arc in loaded.graph.arcs for n in (arc.start, arc.end)}
    if not locomotion:
        return nodes
    moving = {
        n
        for arc in loaded.graph.arcs
        if "cycle" in loaded.channelsets[arc.channelset].name.lower()
        for n in (arc.start, arc.end)
    }
    return nodes - moving


def check_library(
    graphs: Sequence[str | Path],
    figures_dir: str | Path,
    *,
    clips: Sequence[str | Path] = (),
    figures: FigureSet | None = None,
) -> dict[str, Any]:
    """Check every clip of the posture graphs (and any extra channelset files) and every graph's posture
    nodes.

    Figures are read from ``figures_dir`` by the channelsets' protofiletypes. Returns ``{"clips": [...],
    "continuity": [...], "summary": {...}}``; ``summary["pass"]`` is False when any threshold fails.
    """
    from server.motion.cache import load_channelset

    figset = figures or FigureSet({})

    def figures_for(cs: Channelset) -> None:
        need = sorted({c.protofiletype for c in cs.channels} - set(figset.figures))
        if need:
            extra = FigureSet.from_dir(Path(figures_dir), need)
            figset.figures.update(extra.figures)
            figset.kin.update(extra.kin)

    # first every graph: which clips are locomotion, which of their ends are static postures
    info: dict[str, dict[str, Any]] = {}
    loaded_graphs = []
    for gpath in map(Path, graphs):
        loaded = load_posture_graph(gpath)
        loco = _is_locomotion(gpath)
        still = static_nodes(loaded, loco)
        tokens: dict[int, str] = {}
        for token, (cs, fname) in enumerate(zip(loaded.channelsets, loaded.graph.files, strict=True)):
            key = str((gpath.parent / fname).resolve())
            tokens[token] = key
            row = info.setdefault(
                key,
                {
                    "cs": cs,
                    "file": str(gpath.parent / fname),
                    "loco": loco,
                    "graphs": [],
                    "ends": [False] * 2,
                },
            )
            if gpath.name not in row["graphs"]:
                row["graphs"].append(gpath.name)
        for arc in loaded.graph.arcs:
            first, last = (arc.start, arc.end) if arc.forward else (arc.end, arc.start)
            ends = info[tokens[arc.channelset]]["ends"]
            ends[0] |= first in still
            ends[1] |= last in still
        loaded_graphs.append((loaded, tokens))
    played: dict[str, ClipFrames] = {}
    seen: dict[str, dict[str, Any]] = {}
    for key, row in info.items():
        figures_for(row["cs"])
        played[key] = play(row["cs"], figset)
        seen[key] = check_clip(
            played[key], figset, locomotion=row["loco"], file=row["file"], static_ends=tuple(row["ends"])
        )
        seen[key]["graphs"] = row["graphs"]
    continuity: list[dict] = []
    for loaded, tokens in loaded_graphs:
        continuity.extend(check_continuity(loaded, {t: played[k] for t, k in tokens.items()}, figset))
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


def _where(row: Mapping[str, Any], key: str) -> str:
    name = row.get("name") or f"{row.get('graph')}:{row.get('posture')}"
    detail = {
        "foot_skate_cm": row.get("foot_skate_part"),
        "contact_slide_cm": row.get("contact_slide_part"),
        "rifle_in_body_cm": row.get("rifle_in_body_where"),
        "end_speed_m_s": row.get("end_speed_where"),
        "ground_penetration_cm": row.get("lowest_segment"),
        "rest_contact_cm": row.get("rest_where"),
        "rest_foot_cm": row.get("rest_foot_where"),
    }.get(key)
    return f"{name} ({detail})" if detail else name


def summarise(clips: Sequence[Mapping[str, Any]], continuity: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per threshold: limit, worst value, where, pass; plus counts and the overall verdict."""
    rows: dict[str, Any] = {}
    for key, limit in THRESHOLDS.items():
        source = continuity if key in POSTURE_KEYS else clips
        vals = [(r[key], r) for r in source if r.get(key) is not None]
        if not vals:
            rows[key] = {"limit": limit, "worst": None, "where": None, "failing": 0, "pass": True}
            continue
        worst, row = max(vals, key=lambda x: x[0])
        failing = sum(1 for v, _ in vals if v > limit)
        rows[key] = {"limit": limit, "worst": worst, "where": _where(row, key), "failing": failing,
                     "pass": failing == 0}  # fmt: skip
    for key in ("gait_speed_m_s", "gait_steps_per_s"):
        judged = [(c, GAIT_LIMITS[c["gait"]][key]) for c in clips if c.get(key) is not None]
        limit = {f: v[key] for f, v in GAIT_LIMITS.items() if v[key] is not None}
        bad = [(c, lim) for c, lim in judged if _range_failure(c[key], lim)]

        # the worst: furthest outside its range, else the value closest to an edge
        pick = max(judged, key=lambda cl: _range_distance(cl[0][key], cl[1])) if judged else None
        rows[key] = {
            "limit": limit,
            "worst": None if pick is None else pick[0][key],
            "where": None if pick is None else pick[0]["name"],
            "failing": len(bad),
            "pass": not bad,
        }
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
        "postures_failing": sum(1 for r in continuity if not r.get("pass", True)),
        "thresholds": rows,
        "pass": ok,
    }
