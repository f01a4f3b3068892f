"""Posture nodes of the motion library for the quality check: arcs that arrive and leave must agree
(continuity, a clip's own ``end_offset`` taken out) and resting postures must rest on the ground.

A dead body also lies slack (DEAD only): ``rest_head_cm``, the head's lowest node (a head held up on a hand
18 cm over the ground is a live prone soldier's; a dead one lies on its cheek, or on an arm), and
``rest_arm_cm``, the highest of the arms' parts (upper arm, forearm, hand; each by its lowest node: a slack
arm lies on the ground or on the body, at most a supine chest's height, one raised over the head is posed).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from operator import itemgetter
from typing import Any

import numpy as np

from authoring.quality_frames import ClipFrames, FigureSet
from server.motion.posture_change import LoadedPostureGraph
from server.motion.posture_graph import posture_of

POSTURE_LIMITS: dict[str, float] = {
    "continuity_deg": 0.5,
    "continuity_root_cm": 1.0,
    "continuity_root_deg": 0.5,
    "continuity_rifle_cm": 1.0,
    "rest_contact_cm": 2.0,
    "rest_foot_cm": 15.0,
    "rest_head_cm": 10.0,
    "rest_arm_cm": 25.0,
}
ARM_PARTS = tuple(f"{side}_{p}" for side in ("left", "right") for p in ("upper_arm", "forearm", "hand"))
# weight-bearing parts of resting postures ("chest|belly": either of them)
REST_PARTS: dict[str, tuple[str, ...]] = {
    "PRONE": ("chest|belly", "left_forearm", "right_forearm"),
    "KNEEL": ("right_kneecap",),
    "CRAWL": ("left_kneecap", "right_kneecap", "left_forearm", "right_forearm"),
    "DEAD": ("lowest", "pelvis", "chest|belly"),
}


# the resting rows' metrics and the key naming where each was measured
REST_KEYS = (("rest_contact", "rest_part"), ("rest_foot", "rest_foot"), ("rest_head", "rest_head"),
             ("rest_arm", "rest_arm"))  # fmt: skip


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
    base = posture_of(node)
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
    """The weight-bearing parts of a resting posture at one endpoint: their heights and the worst (parts the
    figure lacks are listed under ``missing_parts`` and not judged)."""
    lows = {p: v for p, v in part_lows(cf, frame, figures).items() if np.isfinite(v)}
    parts = {p: round(lows[p], 3) for p in REST_PARTS[kind] if p in lows}
    worst = max(parts, key=lambda p: parts[p]) if parts else None
    row: dict[str, Any] = {
        "clip": cf.channelset.name,
        "frame": frame,
        "parts_cm": parts,
        "rest_contact_cm": None if worst is None else parts[worst],
        "rest_part": worst,
        "missing_parts": [p for p in REST_PARTS[kind] if p not in lows],
    }
    if kind == "DEAD":
        feet = {
            side: max(lows[k] for k in (f"{side}_foot", f"{side}_heel") if k in lows)
            for side in ("left", "right")
            if f"{side}_foot" in lows or f"{side}_heel" in lows
        }
        side = max(feet, key=lambda s: feet[s]) if feet else None
        row["rest_foot_cm"] = None if side is None else round(feet[side], 3)
        row["rest_foot"] = None if side is None else f"{side}_foot"
        row.update(_slack(lows))
    return row


def _slack(lows: Mapping[str, float]) -> dict[str, Any]:
    """A dead body's head and arms lie down (the module docstring): their heights, None if it lacks them."""
    arms = [p for p in ARM_PARTS if p in lows]
    arm = max(arms, key=lambda p: lows[p]) if arms else None
    return {
        "rest_head_cm": round(lows["head"], 3) if "head" in lows else None,
        "rest_head": "head",
        "rest_arm_cm": None if arm is None else round(lows[arm], 3),
        "rest_arm": arm,
    }


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
            "clips": sorted({e["clip"] for e in ends}),
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
            row.update(rest=rest, rest_kind=kind)
            for key, part in REST_KEYS:
                judged = [r for r in rest if r.get(f"{key}_cm") is not None]
                if judged:
                    w = max(judged, key=itemgetter(f"{key}_cm"))
                    row[f"{key}_cm"] = w[f"{key}_cm"]
                    row[f"{key}_where"] = f"{w['clip']}[{w['frame']}] {w[part]}"
        out.append(row)
    for row in out:
        fails = [k for k in POSTURE_LIMITS if row.get(k) is not None and row[k] > POSTURE_LIMITS[k]]
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
