"""Resting parts do not rise after rest (issue 14): once a dead body's pelvis, chest and head are down, no
foot, heel, knee or arm lifts off where it lay.

A settle that lifted each leg 4-8 deg of hip extension to turn it out (heels 19-22 -> 14-16 cm) raised the
lower legs ~15 cm a second after the body had landed (ststow2dead, 2.28-2.60 s): a dead man kicking. This
measures, from the first frame where the pelvis, the chest (or belly) and the head are down (each within
:data:`NEAR_CM` of its height at the last frame, :func:`down_frame`: not "staying so", which a slave's pelvis
settled late pushed to the clip's end; nor while the pelvis is still turned more than :data:`ROLL_DEG` from
how it lies: a body rolling over onto his back carries his bent knee up), how far each leg point rises above
the lowest it has been since (``rest_rise_cm``; the heel and knee sites, the lowest nodes of the foot, the
kneecap, the upper arm, forearm and hand). ``ttes author check`` holds every clip that ends in DEAD to it
(:data:`RISE_LIMIT_CM`); the leg settle (:mod:`authoring.dead_legs`) searches within it. kfire2dead's right
hand, laid over the head by the arm fall, rose 18.6 cm after he lay still: the contact sheet showed it, the
check did not see it while it measured the legs alone. The head counts for rest: a prone death's arms are laid
anew while the chest and head come down.

A limb may also stay up long after the body and come down late without ever rising: kfire2dead's top arm was
held raised 1.5 s after the trunk lay still, then lowered (a dead man holding up his arm). ``limb_rest_lag_s``
is the time from the body being down and still (pelvis, chest or belly, head: :func:`rest_frame`, and their
centroids at rest as a limb's, :func:`trunk_rest`; a prone body's chest and head come down in its settle) to
the last limb part (upper arm, forearm, hand,
thigh, shin, foot) coming to rest; a part is at rest from the first frame after which its centroid stays
within :data:`NEAR_CM` of its final height and slower than :data:`STILL_M_S` (:func:`limb_rest_lag`,
:data:`LAG_LIMIT_S`: a limb falls with the body).

Nor should the trunk stay up long after he is down: prstow2dead and prfire2dead lay propped on their
elbows, the head 30 cm up, from the hit until 3.4 s and 1.7 s (the physics leaves him so and the settle
lowered the chest after it), and every other limit passed: to a trainee he looks alive. ``propped_s`` is the
time from the pelvis first coming near the ground (its lowest node within :data:`PELVIS_NEAR_CM` of where it
finally lies) to the head's lowest node and the chest's centroid coming within :data:`PROPPED_CM` of where
they finally lie and staying so (:func:`propped_lag`, :data:`PROPPED_LIMIT_S`): a man who falls lands on his
chest as his pelvis comes down (the standing and kneeling deaths: 0.0-0.25 s), a man shot lying drops his
head at once. Counted from the pelvis *lying* (within :data:`NEAR_CM`, staying so) a slave whose pelvis was
laid only at the end read 0 (the DI prone deaths of branch proppedmerge-s16, 1.0 s from the pelvis near); a
crawler's head resting on his forearms 10 cm up read 1.4-1.6 s against 5 cm.

Nor should a dead trunk rise: a DI slave's pelvis, down on the ground, rose 3-5 cm 1.2 s into a prone death
(proppedmerge-s16, frames 72-84) and 5 cm as a knelt one's chest landed (kfire2dead_low, frames 76-108), a
man lifting his hips, and ``rest_rise_cm`` judges only the limbs. ``trunk_rise_cm`` is, for the pelvis and
the chest (lowest nodes), from the first frame each is down (within :data:`TRUNK_DOWN_CM` of where it finally
lies), the most it rises above its lowest since (:func:`trunk_rise`, :data:`TRUNK_RISE_LIMIT_CM`).

Nor should a dead limb be flung once the body is down: kfire2dead's top arm, laid anew across his chest after
he was down, swung its hand round at 8.96 m/s, kstow2dead's left at 7.92 (a limp hand dropped 45 cm lands at
about 3 m/s; every other death's limbs 0.2-3.1 m/s). ``dead_limb_speed_m_s`` is the fastest any limb part's
centroid moves from the frame the body is down (:func:`rest_frame`, within :data:`NEAR_CM`;
:func:`limb_whip`, :data:`WHIP_M_S`).

Nor should a dead man's legs rise once his pelvis has reached the ground: kstow2dead, his pelvis down at
1.07 s, swung his left foot 10 -> 41 cm at 1.27 s and rolled onto his back, legs in the air; kfire2dead's
right knee rose 20 -> 32 cm, the boot standing up, at 1.38-1.93 s. ``rest_rise_cm`` opens its window only
once the head is down and he has stopped rolling, and ``feet_up_cm`` judges only while the chest faces down:
neither saw it. ``legs_rise_cm`` is, from the first frame the pelvis' lowest node comes within
:data:`PELVIS_NEAR_CM` of where it finally lies, the most any leg point (the feet's, shins' and kneecaps'
lowest nodes, the heel and knee sites) rises above its lowest since (:func:`legs_rise`,
:data:`LEGS_RISE_LIMIT_CM`): every other death's legs, rolled out as he lies, rise 0.4-6.0 cm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from authoring.quality_frames import ClipFrames, FigureSet

DOWN_CM = 1.0  # cm: pelvis, chest and head are down once within this of where they finally lie
RISE_LIMIT_CM = 3.0  # cm: the most a resting leg or arm point may rise above its lowest since rest
LEG_SITES = ("foot.heel", "lower_leg.knee")
LEG_PARTS = ("foot", "knee", "kneecap")
ARM_PARTS = ("upper_arm", "forearm", "hand")
TORSO_PARTS = ("pelvis", "chest", "belly", "head")
LAG_LIMIT_S = 0.5  # s: the most a limb part may come to rest after the trunk
NEAR_CM = 3.0  # cm: a part is at rest within this of its final height ...
STILL_M_S = 0.1  # m/s: ... and slower than this (its centroid)
WHIP_M_S = 4.5  # m/s: the fastest a limb part's centroid may move once the body is down (a whip, not a fall)
# degrees: a pelvis turned more than this from how it finally lies is still rolling over, not down
# (rest_rise): kstow2dead's, 60 degrees off as his trunk came within 3 cm of its last height, rolled onto
# his back 0.3 s more, its pelvis moving 11.6 cm, and his bent left knee rose 6.7 cm with it; every other
# death's (and slave's) pelvis is within 22 degrees by then
ROLL_DEG = 30.0
PELVIS_NEAR_CM = 10.0  # cm: the pelvis is near the ground within this of where it finally lies
# cm: the head (lowest node) and chest (centroid) are down within this of where they lie: a head held up a
# hand's breadth; a dead crawler's rests on his forearms 10 cm up
PROPPED_CM = 12.0
# s: the most they may stay up after the pelvis is near the ground (quality.THRESHOLDS): main's prstow2dead
# (soldier / DI / M16) 3.33 / 3.37 / 3.37 and prfire2dead 1.62 / 1.67 / 1.67 fail it (branch
# proppedmerge-s16: 0.92-1.00)
PROPPED_LIMIT_S = 1.0
TRUNK_DOWN_CM = 5.0  # cm: the pelvis or chest is down within this of where it finally lies
TRUNK_RISE_PARTS = ("pelvis", "chest")
# cm: the most the pelvis or chest may rise above its lowest once down (proposed, not yet in THRESHOLDS): the
# DI/M16 slaves of the prone deaths fail it (4.2-5.3 at frames 75-76; kfire2dead's 5.3 -> 1.2:
# DeathSpec.slave_settle_down)
TRUNK_RISE_LIMIT_CM = 2.0
# cm: the most a foot, shin or knee may rise above its lowest once the pelvis is near the ground (legs_rise):
# the other deaths' legs rolled out 0.4-6.0 cm (crawl2dead's right knee 6.0), kstow2dead's swung up 28-30 cm
# and kfire2dead's 19-22 (soldier, DI, M16)
LEGS_RISE_LIMIT_CM = 8.0
LIMBS = ("upper_arm", "forearm", "hand", "thigh", "knee", "foot")  # knee: the shin (authoring.body_parts)


def _heights(cf: ClipFrames, figures: FigureSet) -> dict[str, np.ndarray]:
    """Per frame, the heights (cm) of the torso's and head's lowest nodes and the legs' and arms' points."""
    body = max(cf.poses, key=lambda k: figures.kin[k].ndof)
    kin = figures.kin[body]
    nodes, segs = figures.nodes(body)
    parts = figures.node_parts(body)
    q, loc = cf.poses[body], cf.locations[body]
    y = np.einsum("nkj,kj->nk", kin.segment_globals(q, loc)[:, segs, 1, :], nodes)
    sites = kin.site_globals(q, loc)[:, :, 1, 3]
    out: dict[str, np.ndarray] = {}
    for name in TORSO_PARTS:
        if (parts == name).any():
            out[name] = y[:, parts == name].min(axis=1)
    for side in ("left", "right"):
        for p in LEG_PARTS + ARM_PARTS:
            if (parts == f"{side}_{p}").any():
                out[f"{side}_{p}"] = y[:, parts == f"{side}_{p}"].min(axis=1)
        for s in LEG_SITES:
            if f"{side}_{s}" in kin.site_names:
                out[f"{side}_{s}"] = sites[:, kin.site_names.index(f"{side}_{s}")]
    return out


def rest_frame(h: dict[str, np.ndarray], near: float = DOWN_CM) -> int | None:
    """The first frame from which the pelvis, chest (or belly) and head stay down, within ``near`` (cm) of
    where they finally lie (None: the body lacks the pelvis or chest)."""
    torso = [h["pelvis"]] if "pelvis" in h else []
    chest = [h[p] for p in ("chest", "belly") if p in h]
    if not torso or not chest:
        return None
    down = [torso[0], np.minimum.reduce(chest)] + ([h["head"]] if "head" in h else [])
    up = np.logical_or.reduce([y > y[-1] + near for y in down])
    late = np.flatnonzero(up)
    return 0 if len(late) == 0 else int(late[-1]) + 1


def down_frame(
    h: dict[str, np.ndarray], near: float = NEAR_CM, turned: np.ndarray | None = None
) -> int | None:
    """The first frame at which the pelvis, chest (or belly) and head are all down, within ``near`` (cm) of
    where they finally lie, whatever they do after (None: the body lacks the pelvis or chest). A slave's
    pelvis settling its last 2 cm late moved :func:`rest_frame` of kfire2dead_low from 94 to 165 (of 184)
    and hid a forearm's 2.96 cm rise at frame 100 (rest_rise 0.82). ``turned``: per frame, how far (deg)
    the pelvis is turned from how it finally lies (:func:`pelvis_turn`); one turned more than
    :data:`ROLL_DEG` is still rolling over, not down."""
    if "pelvis" not in h or not any(p in h for p in ("chest", "belly")):
        return None
    chest = np.minimum.reduce([h[p] for p in ("chest", "belly") if p in h])
    down = [h["pelvis"], chest] + ([h["head"]] if "head" in h else [])
    near_all = np.logical_and.reduce([y <= y[-1] + near for y in down])
    if turned is not None:
        near_all &= turned <= ROLL_DEG
    return int(np.argmax(near_all))


def pelvis_turn(cf: ClipFrames, figures: FigureSet) -> np.ndarray | None:
    """Per frame, the angle (deg) between the pelvis' orientation and its orientation at the last frame
    (None: the body has no ``lower_torso``)."""
    body = max(cf.poses, key=lambda k: figures.kin[k].ndof)
    return pelvis_turns(figures.kin[body], cf.poses[body], cf.locations[body])


def pelvis_turns(kin: Any, q: np.ndarray, loc: np.ndarray) -> np.ndarray | None:
    """:func:`pelvis_turn` of poses ``q`` ``(n, ndof)`` at root globals ``loc`` of a figure's kinematics."""
    if "lower_torso" not in kin.segment_names:
        return None
    g = kin.segment_globals(q, loc)[:, kin.segment_names.index("lower_torso")]
    r = g[:, :3, :3]
    cos = (np.einsum("nij,ij->n", r, r[-1]) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def rise_after(h: dict[str, np.ndarray], start: int) -> tuple[float, str | None, int | None]:
    """From frame ``start`` on: the most (cm) any leg or arm point of ``h`` rises above its lowest since
    then, which point and at which frame (0.0, None, None if none rises)."""
    best: tuple[float, str | None, int | None] = (0.0, None, None)
    for name, y in h.items():
        if name in TORSO_PARTS:
            continue
        tail = y[start:]
        rise = tail - np.minimum.accumulate(tail)
        k = int(np.argmax(rise))
        if rise[k] > best[0]:
            best = (float(rise[k]), name, start + k)
    return best


def rest_rise(cf: ClipFrames, figures: FigureSet) -> dict[str, Any]:
    """From the frame the body is first down (:func:`down_frame`, reported as ``rest_frame``), the most (cm)
    any leg or arm point rises above its lowest since then (``rest_rise_cm``), which point and at which
    frame: a trunk that settles its last cm late does not shorten the window."""
    h = _heights(cf, figures)
    start = down_frame(h, turned=pelvis_turn(cf, figures))
    row: dict[str, Any] = {"rest_frame": start, "rest_rise_cm": None, "rest_rise_part": None}
    row["rest_rise_frame"] = None
    if start is None:
        return row
    rise, part, frame = rise_after(h, start)
    row.update(rest_rise_cm=round(rise, 3), rest_rise_part=part, rest_rise_frame=frame)
    return row


def _centroids(
    cf: ClipFrames, figures: FigureSet, names: tuple[str, ...] | None = None
) -> dict[str, np.ndarray]:
    """Per frame, the centroid (cm, world) of each limb part's nodes ``(n, 3)`` (or of parts ``names``)."""
    body = max(cf.poses, key=lambda k: figures.kin[k].ndof)
    kin = figures.kin[body]
    nodes, segs = figures.nodes(body)
    parts = figures.node_parts(body)
    g = kin.segment_globals(cf.poses[body], cf.locations[body])
    out: dict[str, np.ndarray] = {}
    limbs = tuple(f"{side}_{p}" for side in ("left", "right") for p in LIMBS)
    for name in names if names is not None else limbs:
        m = parts == name
        if m.any():
            out[name] = np.einsum("nkij,kj->ni", g[:, segs[m], :3, :], nodes[m]) / int(m.sum())
    return out


def settled_from(pos: np.ndarray, fps: float) -> int:
    """The first frame from which a part at ``pos`` ``(n, 3)`` (cm) stays within :data:`NEAR_CM` of its
    final height and slower than :data:`STILL_M_S`."""
    speed = np.linalg.norm(np.gradient(pos, axis=0), axis=1) * fps / 100.0 if len(pos) > 1 else np.zeros(1)
    moving = (np.abs(pos[:, 1] - pos[-1, 1]) > NEAR_CM) | (speed > STILL_M_S)
    late = np.flatnonzero(moving)
    return 0 if len(late) == 0 else int(late[-1]) + 1


def limb_rest_lag(limbs: dict[str, np.ndarray], trunk: int | None, fps: float) -> dict[str, Any]:
    """How long (s) after frame ``trunk`` (the trunk is down) the last limb part at ``limbs`` (name:
    centroids ``(n, 3)``) comes to rest (:func:`settled_from`; 0 if none rests after it), which part and
    at which frame."""
    row: dict[str, Any] = {"limb_rest_lag_s": None, "limb_rest_lag_part": None, "limb_rest_lag_where": None}
    if trunk is None or not limbs:
        return row
    part, frame = max(((k, settled_from(v, fps)) for k, v in limbs.items()), key=lambda kv: kv[1])
    lag = max(0.0, (frame - trunk) / fps)
    row.update(limb_rest_lag_s=round(lag, 3), limb_rest_lag_part=part if lag > 0 else None)
    row["limb_rest_lag_where"] = f"{part} at rest frame {frame}, trunk {trunk}" if lag > 0 else None
    return row


def limb_whip(limbs: dict[str, np.ndarray], down: int | None, fps: float) -> dict[str, Any]:
    """The fastest (m/s) any limb part at ``limbs`` (name: centroids ``(n, 3)``, cm) moves from frame
    ``down`` (the body is down) on, which part and at which frame."""
    row: dict[str, Any] = {"dead_limb_speed_m_s": None, "dead_limb_speed_where": None}
    if down is None or not limbs:
        return row
    speeds = {
        k: np.linalg.norm(np.gradient(v, axis=0), axis=1)[down:] * fps / 100.0 for k, v in limbs.items()
    }
    part = max(speeds, key=lambda k: float(speeds[k].max(initial=0.0)))
    frame = down + int(np.argmax(speeds[part]))
    row.update(dead_limb_speed_m_s=round(float(speeds[part].max(initial=0.0)), 3))
    row["dead_limb_speed_where"] = f"{part} at frame {frame}"
    return row


def rest_lag(cf: ClipFrames, figures: FigureSet) -> dict[str, Any]:
    """:func:`limb_rest_lag` of a played clip, from the frame its body is down (:func:`rest_frame`, within
    :data:`NEAR_CM`: as near as a limb at rest; a slave's body lowered the last 2 cm at the end hid its arm
    held up)."""
    fps = cf.channelset.fps
    down = rest_frame(_heights(cf, figures), NEAR_CM)
    trunk = trunk_rest(down, _centroids(cf, figures, TORSO_PARTS), fps)
    limbs = _centroids(cf, figures)
    return limb_rest_lag(limbs, trunk, fps) | limb_whip(limbs, down, fps)


def trunk_rest(down: int | None, torso: dict[str, np.ndarray], fps: float) -> int | None:
    """The frame from which the trunk rests: down (``down``, :func:`rest_frame`) and its parts at rest as a
    limb is (:func:`settled_from` of the centroids ``torso``). A body rolling over onto its back keeps its
    lowest points on the ground while it rolls and carries its limbs along: kstow2dead's right foot came to
    rest 0.53 s after he was down, 4 frames after he stopped rolling (frames 82-110: 55 degrees, 9 cm)."""
    if down is None or not torso:
        return down
    return max(down, *(settled_from(c, fps) for c in torso.values()))


def down_from(y: np.ndarray, near: float) -> int:
    """The first frame from which heights ``y`` stay within ``near`` (cm) of the last one (0: always)."""
    up = np.flatnonzero(y > y[-1] + near)
    return 0 if len(up) == 0 else int(up[-1]) + 1


def near_from(y: np.ndarray, near: float) -> int:
    """The first frame at which heights ``y`` come within ``near`` (cm) of the last one (whatever after)."""
    return int(np.argmax(y <= y[-1] + near))


def propped_lag(pelvis: np.ndarray, upper: dict[str, np.ndarray], fps: float) -> dict[str, Any]:
    """How long (s) after the ``pelvis`` (its lowest node's heights) first comes within
    :data:`PELVIS_NEAR_CM` of where it finally lies the last of ``upper`` (name: heights, the head's lowest
    node, the chest's centroid) comes down within :data:`PROPPED_CM` (0 if none is up after the pelvis is
    near), which part and from which frame."""
    near = near_from(pelvis, PELVIS_NEAR_CM)
    part, frame = max(((k, down_from(y, PROPPED_CM)) for k, y in upper.items()), key=lambda kv: kv[1])
    lag = max(0.0, (frame - near) / fps)
    where = f"{part} down from frame {frame}, pelvis near the ground from {near}" if lag > 0 else None
    return {"propped_s": round(lag, 3), "propped_part": part if lag > 0 else None, "propped_where": where}


def trunk_rise(parts: dict[str, np.ndarray]) -> dict[str, Any]:
    """For each of ``parts`` (name: its lowest node's heights), from the first frame it is down (within
    :data:`TRUNK_DOWN_CM` of where it finally lies) the most (cm) it rises above its lowest since: the worst
    part, at which frame (None: no such part)."""
    if not parts:
        return {"trunk_rise_cm": None, "trunk_rise_part": None, "trunk_rise_where": None}
    best: tuple[float, str | None, int, int] = (0.0, None, 0, 0)
    for name, y in parts.items():
        down = near_from(y, TRUNK_DOWN_CM)
        tail = y[down:]
        rise = tail - np.minimum.accumulate(tail)
        k = int(np.argmax(rise))
        if rise[k] > best[0]:
            best = (float(rise[k]), name, down + k, down)
    rise_cm, part, frame, down = best
    where = f"{part} at frame {frame}, down from {down}" if part is not None else None
    return {"trunk_rise_cm": round(rise_cm, 3), "trunk_rise_part": part, "trunk_rise_where": where}


def dead_trunk(cf: ClipFrames, figures: FigureSet) -> dict[str, Any]:
    """:func:`propped_lag` (its head's lowest node, its chest's centroid) and :func:`trunk_rise` (its pelvis'
    and chest's lowest nodes) of a played clip."""
    h = _heights(cf, figures)
    row = trunk_rise({k: h[k] for k in TRUNK_RISE_PARTS if k in h})
    if "pelvis" not in h or "head" not in h:
        return {**row, "propped_s": None, "propped_part": None, "propped_where": None}
    upper = {"head": h["head"]}
    upper.update({k: c[:, 1] for k, c in _centroids(cf, figures, ("chest",)).items()})
    return {**row, **propped_lag(h["pelvis"], upper, cf.channelset.fps)}


def legs_rise(h: dict[str, np.ndarray]) -> dict[str, Any]:
    """From the first frame the pelvis of ``h`` (name: heights, :func:`_heights`) comes within
    :data:`PELVIS_NEAR_CM` of where it finally lies, the most (cm) any leg point rises above its lowest since,
    which point and at which frame (None: no pelvis)."""
    row: dict[str, Any] = {"legs_rise_cm": None, "legs_rise_part": None, "legs_rise_where": None}
    if "pelvis" not in h:
        return row
    start = near_from(h["pelvis"], PELVIS_NEAR_CM)
    legs = {k: y for k, y in h.items() if k.split("_", 1)[-1] in LEG_PARTS + LEG_SITES}
    rise, part, frame = rise_after(legs, start)
    where = f"{part} at frame {frame}, pelvis down from {start}" if part is not None else None
    row.update(legs_rise_cm=round(rise, 3), legs_rise_part=part, legs_rise_where=where)
    return row


def dead_legs(cf: ClipFrames, figures: FigureSet) -> dict[str, Any]:
    """:func:`legs_rise` of a played clip."""
    return legs_rise(_heights(cf, figures))
