"""A new user's audit of the motion library (issue 14), written without authoring/quality*.py.

Plays every channelset on its figures with the shared kinematics (``peabody.fk``, ``server.motion.binding``),
puts every mesh node of body and rifle in the world and measures what a viewer sees, each clip on the three
sets (soldier.fig + AK-47, DI.fig + AK-47 ``*_low``, DI.fig + M16 ``*_m16_low``):

* contacts by height alone (``--contact-cm``, default 1.25): per body part the widest horizontal extent a mesh
  node covers while it stays that low (in-place locomotion clips get the entity's motion at ``ground_speed``
  added back, along -Z, +Z for the backward walk);
* penetration of body and rifle into the ground, rifle nodes inside a body segment's convex hull (hands
  excepted) while held, and the rifle slipping in the hands (grip in the right palm's frame, handguard in the
  left palm's, against frame 0);
* at every static end (from the posture graphs) the fastest mesh node over the first/last three frames;
* per-frame joint jumps and one-frame flicks (rotational DOFs), and world-space pops: a body node whose
  velocity changes for one frame and back (``pop_m_s``), which a pose spread over many joints hides;
* ``unsupported_s``: the longest time nothing of the body is within 2 cm of the ground (a run's flight is
  ~0.13 s; lying down from the crawl must not float);
* at every resting end (KNEEL, PRONE, CRAWL, DEAD) the lowest point of each weight-bearing part;
* per posture node the largest mesh-node jump between any arriving and any leaving clip (``end_offset`` taken
  back), and for cycles speed, steps per second and the speed the planted limbs show.

``--check FILE`` (``ttes author check --json``) adds the disagreements: a limit of the check that this audit
says fails where the check passes.

    python bench/motion_audit.py [--only PATTERN] [--figures soldier,DI,M16] [--check check.json] > audit.json
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from peabody import quaternion
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from server.motion.binding import BoundFigure, bind_channelset
from server.motion.channelset import Channelset
from server.motion.channelset_file import read_channelset

ROOT = Path(__file__).resolve().parents[1]
SETS = {
    "soldier": ("soldier.fig", "AK_47.fig", "{}.chset.env"),
    "DI": ("DI.fig", "AK_47.fig", "{}_low.chset.env"),
    "M16": ("DI.fig", "M16.fig", "{}_m16_low.chset.env"),
}
SUFFIX = {"soldier": ".chset", "DI": "_low.chset", "M16": "_m16_low.chset"}  # the check's clip names
STATIC = re.compile(r"^(STAND|KNEEL|PRONE|CRAWL$|DEAD)")
SUPPORT_CM = 2.0  # something this low holds the body up
END_FRAMES = 3
Arc = tuple[str, str, str]  # start posture, end posture, direction


def part(seg: str) -> str:
    """Body part of a segment name (soldier.fig and DI.fig)."""
    side = "l_" if seg.startswith("left") else "r_" if seg.startswith("right") else ""
    s = seg.removeprefix("left_").removeprefix("right_")
    named = {
        "foot": "foot",
        "toes": "foot",
        "lower_leg": "shin",
        "upper_leg": "thigh",
        "lower_arm": "forearm",
    }
    if s in named:
        return side + named[s]
    if s == "upper_arm":
        return side + "upperarm"
    if s == "palm" or re.match(r"(thumb|index|middle|ring|pinky)\d", s):
        return side + "hand"
    if s == "lower_torso":
        return "pelvis"
    if s in ("lumbar", "middle_torso") or re.match(r"l\d$", s):
        return "belly"
    if s in ("clavicle", "thoracic", "upper_torso") or re.match(r"t\d+$", s):
        return "chest"
    return "head"


class Fig:
    """A figure with its kinematics, mesh nodes (segment frames), their parts and segment hulls."""

    def __init__(self, path: Path) -> None:
        self.fig = read_figure(path)
        self.kin = FigureKinematics(self.fig)
        pts, segs = [], []
        for i, name in enumerate(self.kin.segment_names):
            sg = self.fig.segments[name]
            if sg.psurf is None or not len(sg.psurf.nodes):
                continue
            p = np.c_[np.asarray(sg.psurf.nodes, float).reshape(-1, 3), np.ones(len(sg.psurf.nodes))]
            if sg.psurf_transform is not None:
                p = p @ np.asarray(sg.psurf_transform).T
            pts.append(p)
            segs += [i] * len(p)
        self.nodes = np.concatenate(pts)
        self.seg = np.array(segs)
        self.parts = np.array([part(self.kin.segment_names[s]) for s in self.seg])
        self.hull: dict[int, np.ndarray] = {}
        for s in np.unique(self.seg):
            p = self.nodes[self.seg == s, :3]
            if not part(self.kin.segment_names[s]).endswith("hand") and len(p) >= 5:
                self.hull[int(s)] = ConvexHull(p).equations

    def globals(self, cs: Channelset, bf: BoundFigure) -> tuple[np.ndarray, np.ndarray]:
        """Every frame's segment globals ``(n, nseg, 4, 4)`` and poses ``(n, ndof)``."""
        n = cs.nframes
        q = np.tile(bf.neutral.astype(float), (n, 1))
        q[:, bf.dst] = cs.joint_data[:, bf.src]
        eye = np.broadcast_to(np.eye(4), (n, 4, 4))
        if bf.figure_channel < 0:
            root = np.broadcast_to(self.fig.location, (n, 4, 4))
        else:
            k = bf.figure_channel
            m = np.stack(
                [quaternion.to_transform(cs.fig_pos[i, k].astype(float), cs.fig_quat[i, k]) for i in range(n)]
            )
            sites = np.array([self.kin.site_names.index(cs.root_names[r]) for r in cs.fig_root[:, k]])
            root = m @ np.linalg.inv(self.kin.site_globals(q, eye)[np.arange(n), sites])
        return np.ascontiguousarray(self.kin.segment_globals(q, root)), q

    def world(self, g: np.ndarray) -> np.ndarray:
        """``(n, k, 3)`` world mesh nodes."""
        return np.einsum("nkij,kj->nki", g[:, self.seg], self.nodes)[..., :3]

    def dof_name(self, dof: int) -> str:
        for name, sl in self.kin.dof_slices.items():
            if sl.start <= dof < sl.stop:
                return f"{name}[{dof - sl.start}]"
        return "?"


def graph_arcs() -> dict[str, list[Arc]]:
    """Clip base name -> its arcs, from the DI graphs (the other sets' graphs have the same arcs)."""
    out: dict[str, list[Arc]] = {}
    for g in sorted((ROOT / "posture_graphs").glob("soldier_*.graph")):
        if g.name.endswith(("_hi.graph", "_m16.graph")):
            continue
        text = g.read_text().splitlines()
        files = {}
        for line in text:
            m = re.match(r"^(\d+) \.\./channelsets/(\S+)_low\.chset\.env", line)
            if m:
                files[m.group(1)] = m.group(2)
        for line in text:
            m = re.match(r"^([A-Z_@a-z]+)\s+([A-Z_@a-z]+)\s+(\d+)\s+(forward|backward)", line)
            if m and m.group(3) in files:
                out.setdefault(files[m.group(3)], []).append((m.group(1), m.group(2), m.group(4)))
    return out


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the True runs of a 1-D mask."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def slides(p: np.ndarray, parts: np.ndarray, contact_cm: float) -> dict[str, list[float]]:
    """Per part ``[cm, first, stop]``: the widest horizontal extent of a node while at most contact_cm up."""
    low = p[..., 1] <= contact_cm
    out: dict[str, list[float]] = {}
    for k in np.flatnonzero(low.any(axis=0)):
        for a, b in runs(low[:, k]):
            if b - a < 2:
                continue
            xz = p[a:b, k][:, [0, 2]][np.linspace(0, b - a - 1, min(b - a, 80)).astype(int)]
            ext = float(np.linalg.norm(xz[:, None] - xz[None], axis=-1).max())
            if ext > out.get(parts[k], [0.0])[0]:
                out[parts[k]] = [round(ext, 2), a, b]
    return dict(sorted(out.items(), key=lambda kv: -kv[1][0]))


def rifle_in_body(fig: Fig, g: np.ndarray, rifle: np.ndarray, frames: np.ndarray) -> list[Any]:
    """Deepest rifle node inside a body segment's hull (hands excepted): ``[cm, frame, segment]``."""
    best: list[Any] = [0.0, -1, ""]
    if not len(frames):
        return best
    pw = np.concatenate([rifle[frames], np.ones((len(frames), rifle.shape[1], 1))], axis=-1)
    for s, eq in fig.hull.items():
        local = np.einsum("nij,nkj->nki", np.linalg.inv(g[frames, s]), pw)[..., :3]
        depth = -(local @ eq[:, :3].T + eq[:, 3]).max(axis=-1)  # > 0 inside
        i = np.unravel_index(np.argmax(depth), depth.shape)
        if depth[i] > best[0]:
            best = [round(float(depth[i]), 2), int(frames[i[0]]), fig.kin.segment_names[s]]
    return best


def lowest(p: np.ndarray, parts: np.ndarray, pattern: str) -> float:
    sel = np.array([re.fullmatch(pattern, x) is not None for x in parts])
    return round(float(p[sel, 1].min()), 2)


REST_PARTS = {
    "pelvis": "pelvis",
    "trunk": "belly|chest",
    "head": "head",
    "l_forearm": "l_forearm",
    "r_forearm": "r_forearm",
    "l_thigh": "l_thigh",
    "r_thigh": "r_thigh",
    "l_shin": "l_shin",
    "r_shin": "r_shin",
    "l_foot": "l_foot",
    "r_foot": "r_foot",
}


def audit_clip(
    name: str, figset: str, body: Fig, rifle: Fig, arcs: list[Arc], contact_cm: float
) -> dict[str, Any]:
    """Every measure of one clip on one set (``_first``/``_last``: the end poses, for continuity)."""
    btype, rtype, fmt = SETS[figset]
    cs = read_channelset(ROOT / "channelsets" / fmt.format(name))
    bfs = {bf.protofiletype: bf for bf in bind_channelset(cs, [body.fig, rifle.fig]).figures}
    gb, qb = body.globals(cs, bfs[btype])
    gr, _ = rifle.globals(cs, bfs[rtype])
    n, fps = cs.nframes, cs.fps
    pb, pr = body.world(gb), rifle.world(gr)
    inplace = cs.ground_speed is not None and cs.end_offset is None
    shift = np.zeros((n, 1, 3))
    if inplace:
        shift[:, 0, 2] = (
            (1.0 if name.startswith("bwalk") else -1.0) * float(cs.ground_speed or 0) * np.arange(n) / fps
        )
    pbw, prw = pb + shift, pr + shift
    r: dict[str, Any] = {"clip": name, "set": figset, "frames": n, "seconds": round(cs.size / fps, 3)}
    sl = slides(pbw, body.parts, contact_cm)
    r["slides"] = sl
    r["foot_slide"] = max([v[0] for k, v in sl.items() if k.endswith("foot")], default=0.0)
    r["other_slide"] = max([[v[0], k] for k, v in sl.items() if not k.endswith("foot")], default=[0.0, ""])
    r["body_pen"] = round(-float(pb[..., 1].min()), 2)
    r["rifle_pen"] = round(-float(pr[..., 1].min()), 2)
    held = np.arange(cs.release_frame if cs.release_frame is not None else n)
    r["rifle_in_body"] = rifle_in_body(body, gb, pr, held)
    slip = {}
    for site, seg in (("grip", "right_palm"), ("handguard", "left_palm")):
        w = (gr[:, 0] @ rifle.fig.site(f"rifle.{site}").location)[:, :, 3]
        local = np.einsum("nij,nj->ni", np.linalg.inv(gb[:, body.kin.segment_names.index(seg)]), w)[:, :3]
        slip[site] = round(float(np.linalg.norm(local[held] - local[0], axis=1).max(initial=0.0)), 2)
    r["grip_slip"] = slip
    v = np.linalg.norm(np.diff(np.concatenate([pbw, prw], axis=1), axis=0), axis=-1) * fps / 100.0
    ends = [(a if d == "forward" else b, "start") for a, b, d in arcs] + [
        (b if d == "forward" else a, "end") for a, b, d in arcs
    ]
    for post, end in ends:
        if STATIC.match(post):
            r[f"{end}_speed"] = round(float((v[:END_FRAMES] if end == "start" else v[-END_FRAMES:]).max()), 2)
    rot = np.flatnonzero(body.kin.rotational)
    dq = np.degrees(np.diff(qb[:, rot], axis=0))
    i, k = np.unravel_index(np.argmax(np.abs(dq)), dq.shape)
    r["joint_jump"] = [round(float(abs(dq[i, k])), 1), int(i), body.dof_name(int(rot[k]))]
    if len(dq) >= 3:
        fl = np.minimum(np.abs(dq[1:-1] - dq[:-2]), np.abs(dq[1:-1] - dq[2:]))
        i, k = np.unravel_index(np.argmax(fl), fl.shape)
        r["flick"] = [round(float(fl[i, k]), 1), int(i + 1), body.dof_name(int(rot[k]))]
    vb = np.diff(pb, axis=0) * fps / 100.0
    if len(vb) >= 3:
        dv = np.linalg.norm(np.diff(vb, axis=0), axis=-1)
        pop = np.minimum(dv[:-1], dv[1:])
        i, k = np.unravel_index(np.argmax(pop), pop.shape)
        r["pop_m_s"] = [round(float(pop[i, k]), 2), int(i + 1), str(body.parts[k])]
    free = runs(pb[..., 1].min(axis=1) > SUPPORT_CM)
    a, b = max(free, key=lambda ab: ab[1] - ab[0], default=(0, 0))
    r["unsupported_s"] = [
        round((b - a) / fps, 3),
        a,
        b,
        round(float(pb[a:b, :, 1].min(axis=1).max(initial=0.0)), 1),
    ]
    rest = {}
    for post, fr in [(b, n - 1) for _, b, d in arcs if d == "forward"] + [
        (b, 0) for _, b, d in arcs if d == "backward"
    ]:
        if STATIC.match(post) and not post.startswith("STAND"):
            row = {key: lowest(pb[fr], body.parts, pat) for key, pat in REST_PARTS.items()}
            rest[post] = {
                "lowest": round(float(pb[fr, :, 1].min()), 2),
                **row,
                "rifle_low": round(float(pr[fr, :, 1].min()), 2),
            }
    r["rest"] = rest
    if cs.end_offset is not None:
        r["end_offset"] = list(cs.end_offset)
        r["end_travel_cm"] = round(math.hypot(cs.end_offset[0], cs.end_offset[1]), 1)
    if "_cycle" in name and cs.ground_speed:
        steps = 2 if name.startswith("crawl") else 1
        planted = (pb[1:, :, 1] <= contact_cm) & (pb[:-1, :, 1] <= contact_cm)
        vz = np.abs(np.diff(pb[..., 2], axis=0)) * fps / 100.0
        r["gait"] = {
            "speed_m_s": round(cs.ground_speed / 100, 3),
            "steps_per_s": round(steps * fps / cs.size, 2),
            "planted_speed_m_s": round(float(np.median(vz[planted])), 3) if planted.any() else None,
        }
    r["_first"] = np.concatenate([pb[0], pr[0]])
    last = np.concatenate([pb[-1], pr[-1]])
    if cs.end_offset is not None:
        x, z, yaw = cs.end_offset
        c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        last = (last - [x, 0.0, z]) @ np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    r["_last"] = last
    return r


def continuity(rows: list[dict[str, Any]], arcs: dict[str, list[Arc]]) -> list[dict[str, Any]]:
    """Per set and posture node the largest mesh-node distance between an arriving and a leaving pose."""
    out = []
    for figset in SETS:
        poses = {r["clip"]: r for r in rows if r["set"] == figset and "_first" in r}
        arrive: dict[str, list[tuple[str, np.ndarray]]] = {}
        leave: dict[str, list[tuple[str, np.ndarray]]] = {}
        for name, al in arcs.items():
            if name not in poses:
                continue
            first, last = poses[name]["_first"], poses[name]["_last"]
            for a, b, d in al:
                fwd = d == "forward"
                arrive.setdefault(b, []).append((name, last if fwd else first))
                leave.setdefault(a, []).append((name, first if fwd else last))
        for node in sorted(set(arrive) & set(leave)):
            worst = max(
                (
                    (float(np.linalg.norm(pa - pl, axis=1).max()), na, nl)
                    for na, pa in arrive[node]
                    for nl, pl in leave[node]
                ),
                default=(0.0, "", ""),
            )
            out.append(
                {"set": figset, "node": node, "node_jump_cm": round(worst[0], 2), "between": worst[1:]}
            )
    return out


def disagreements(rows: list[dict[str, Any]], check: dict[str, Any]) -> list[list[Any]]:
    """Limits of the check this audit says fail on a clip where the check passes it."""
    byname = {c["name"]: c for c in check["clips"]}
    out: list[list[Any]] = []
    for r in rows:
        c = byname.get(r["clip"] + SUFFIX[r["set"]], {})
        speeds = c.get("end_speeds_m_s") or {}
        pairs = [
            ("foot_skate_cm", r["foot_slide"], c.get("foot_skate_cm"), 2.0),
            ("contact_slide_cm", r["other_slide"][0], c.get("contact_slide_cm"), 3.0),
            ("ground_penetration_cm", r["body_pen"], c.get("ground_penetration_cm"), 1.0),
            ("rifle_penetration_cm", r["rifle_pen"], c.get("rifle_penetration_cm"), 1.0),
            ("rifle_in_body_cm", r["rifle_in_body"][0], c.get("rifle_in_body_cm"), 1.0),
            ("end_speed_m_s (first)", r.get("start_speed"), speeds.get("first"), 0.5),
            ("end_speed_m_s (last)", r.get("end_speed"), speeds.get("last"), 0.5),
            ("max_frame_jump_deg", r["joint_jump"][0], c.get("max_frame_jump_deg"), 20.0),
            ("max_frame_flick_deg", r.get("flick", [0])[0], c.get("max_frame_flick_deg"), 15.0),
        ]
        for what, mine, theirs, limit in pairs:
            if mine is not None and mine > limit and (theirs is None or theirs <= limit):
                out.append([r["set"], r["clip"], what, mine, theirs, limit])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default="*", help="clip base names (shell pattern)")
    ap.add_argument("--figures", default="soldier,DI,M16", help="sets to audit")
    ap.add_argument("--contact-cm", type=float, default=1.25, help="a node this low is on the ground")
    ap.add_argument("--check", type=Path, help="ttes author check --json output, for the disagreements")
    args = ap.parse_args()
    arcs = graph_arcs()
    figs: dict[str, Fig] = {}
    names = sorted(
        p.name.removesuffix(".chset.env")
        for p in (ROOT / "channelsets").glob("*.chset.env")
        if not p.name.endswith("_low.chset.env")
        and fnmatch.fnmatch(p.name.removesuffix(".chset.env"), args.only)
    )
    rows = []
    for figset in args.figures.split(","):
        btype, rtype, _ = SETS[figset]
        body = figs.setdefault(btype, Fig(ROOT / "figures" / btype))
        rifle = figs.setdefault(rtype, Fig(ROOT / "figures" / rtype))
        for name in names:
            rows.append(audit_clip(name, figset, body, rifle, arcs.get(name, []), args.contact_cm))
            print(f"{figset} {name}", file=sys.stderr)
    out: dict[str, Any] = {"contact_cm": args.contact_cm, "continuity": continuity(rows, arcs)}
    out["clips"] = [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]
    if args.check:
        out["disagreements"] = disagreements(rows, json.loads(args.check.read_text()))
    json.dump(out, sys.stdout, indent=None, default=float)
    print()


if __name__ == "__main__":
    main()
