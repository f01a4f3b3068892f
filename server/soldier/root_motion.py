"""Root motion: how far a locomotion clip carries the soldier, measured from its planted feet (issue 16).

The library plays locomotion clips in place (``library._strip_travel``); the entity moves by its own dead
reckoned velocity. For the planted foot to stay still *in the world*, the figure must be placed relative to
the entity by a *root offset* = (the clip's own travel so far) − (the entity's travel so far). The clip's own
travel is measured once per clip here: frame after frame, the horizontal move of the foot in stance (the
lower one) taken backwards — the treadmill the in-place clip walks on. :class:`TravelTable` holds these
curves for all clips (zero for static clips and reactions), flat and interpolated like the sampler.

Axes: Jack, in the soldier's (entity's) frame: the clips walk forwards along -Z and step left along -X; only
X and Z (horizontal, centimetres) are kept.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from peabody.fk import FigureKinematics
from peabody.model import Figure
from peabody.quaternion import to_transform
from protocol.bitpack import set_rows

if TYPE_CHECKING:
    from server.soldier.library import MotionLibrary
    from server.soldier.table import SoldierTable

TURN_RATE = 90.0  # degrees/s a figure without sole sites turns towards its heading
CRAWL_TURN_RATE = 3.0  # ... a crawling one, about the root (toe tips <= 2.3 cm a stance; more: he stops)
# a walking or running figure turns at each footfall instead: only while at most one sole point is down (the
# ball at push-off, or none in a run's flight), about that point, so no planted point slides (issue 16)
STEP_TURN_DEG = 45.0  # at most this much per such window (one a step): 90° over 2-3 steps, 110° over three
FRAME_TURN_DEG = 5.0  # ... and per recorded 60 Hz frame (a walk's window is 7-8 frames: 35-40°)
STEP_TURN_RATE = 240.0  # degrees/s at most, however fast the clip plays (a snap is 6° in a 60 Hz frame)
# ... and, being slower than the entity's turn, it overshoots the corner: it heads back to its entity's path
STEER_S = 1.0  # over about this time (the lateral gap it steers by is looked ahead this many seconds' walk)
STEER_FREE_CM = 10.0  # ... once more than this beside it, until it is within and faces the heading again
STEER_MAX_DEG = 45.0
LIFT_CM = 1.5  # a sole point this far above the clip's lowest at a frame is up (a foot is down within 1 cm)
STEPPING = (2, 3)  # state.Mode.LOCO, Mode.CRAWL (plain ints: this module does not import the manager's enums)
# a side-step's feet shuffle flat, never on one sole point alone: it turns while one foot alone is down, about
# that foot's centre, which twists its heel and ball ~0.17 cm a degree (issue 16)
SIDE_TURN_DEG = 10.0  # at most this much per single-support stance (1.7 cm at heel and ball)
SHARE_FLOOR = 0.05  # a pivot's extra turn in double support, relative to single (no spurt of yaw between)
FLIGHT_CM = 3.0  # a foot whose lowest sole point is this far above the clip's lowest carries no weight
FLAT_CM = 1.0  # a carrying foot's sole points this near its lowest are all down: it turns about their middle
# per foot, the sole points whose lower one carries the weight (heel strike, then the ball at push-off)
COLUMNS_MIN = 512  # rows from which :func:`scaled` works a column at a time
FOOT_SITES: tuple[tuple[str, ...], ...] = (
    ("left_foot.heel", "left_foot.ball"),
    ("right_foot.heel", "right_foot.ball"),
)


def feet_points(kin: FigureKinematics, joints: np.ndarray, placement: np.ndarray) -> np.ndarray:
    """``(n, 2, k, 3)`` world positions (cm) of each foot's sole points for poses ``joints`` placed by
    ``placement`` (``(n, 7)``: root site position + quaternion w, x, y, z)."""
    q = np.asarray(placement, np.float64)
    roots = np.stack([to_transform(p[:3], p[3:7]) for p in q])
    sites = kin.site_globals(np.asarray(joints, np.float64), roots)
    pts = np.array([[sites[:, kin.site_names.index(s), :3, 3] for s in foot] for foot in FOOT_SITES])
    return pts.transpose(2, 0, 1, 3)  # (feet, points, n, 3) -> (n, feet, points, 3)


def has_feet(kin: FigureKinematics) -> bool:
    """Whether the figure has the sole sites :func:`feet_points` measures."""
    return all(s in kin.site_names for foot in FOOT_SITES for s in foot)


def linear_travel(n: int, total: np.ndarray) -> np.ndarray:
    """``(n, 2)``: ``total`` (X, Z cm) spread evenly over the frames (no feet to measure, or a crawl)."""
    return np.linspace(0.0, 1.0, n)[:, None] * np.asarray(total, np.float64)[None, :2]


def contact_points(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Between frames k and k+1 the sole point that is lowest over both carries the weight: ``(n-1, 2)``
    its horizontal move (X, Z cm) and ``(n-1,)`` its height above the lowest sole point of all frames."""
    n = len(points)
    flat = points.reshape(n, -1, 3)  # (n, feet * points, 3)
    pair = np.maximum(flat[:-1, :, 1], flat[1:, :, 1])
    which = np.argmin(pair, axis=1)
    k = np.arange(n - 1)
    move = flat[k + 1, which][:, [0, 2]] - flat[k, which][:, [0, 2]]
    return move, pair[k, which] - flat[..., 1].min()


def stance_contact(points: np.ndarray) -> np.ndarray:
    """``(n, 2)`` per frame the horizontal position (X, Z cm) the figure turns about so that the turn does not
    slide the planted foot: the sole point carrying the weight, or, while that foot is flat (its other sole
    points within FLAT_CM), the middle of its points down. A flat foot turned about its heel dragged the ball
    the heel-to-ball length times the angle (a 60° start's 15° rest: 2.2 cm); about the middle, half."""
    n = len(points)
    if n < 2:
        return np.zeros((n, 2))
    npts = points.shape[2]
    flat = points.reshape(n, -1, 3)
    pair = np.maximum(flat[:-1, :, 1], flat[1:, :, 1])
    pair = np.concatenate([pair, pair[-1:]])
    which = np.argmin(pair, axis=1)
    foot = which // npts
    k = np.arange(n)
    own = points[k, foot]  # (n, points, 3): the carrying foot's sole points
    height = pair.reshape(n, -1, npts)[k, foot]
    down = height <= pair[k, which][:, None] + FLAT_CM
    return (own[..., [0, 2]] * down[..., None]).sum(axis=1) / down.sum(axis=1)[:, None]


def single_support(points: np.ndarray) -> np.ndarray:
    """``(n,)`` whether one foot alone is down (the other's lowest sole point FLIGHT_CM up) per frame."""
    lift = points[..., 1].min(axis=2)  # (n, feet): each foot's lowest sole point
    return np.asarray(((lift - lift.min()) > FLIGHT_CM).sum(axis=1) == 1)


def stance_count(points: np.ndarray) -> int:
    """How many times one foot alone carries the figure (a pivot's extra turn is shared among them)."""
    single = single_support(points).astype(np.int8)
    return int((np.diff(np.concatenate([[0], single])) == 1).sum()) if len(points) else 0


def single_support_share(points: np.ndarray) -> np.ndarray:
    """``(n,)`` per frame the fraction of a pivot's extra turn done by then: mostly over the frames where one
    foot alone is down, SHARE_FLOOR of that rate elsewhere."""
    if len(points) < 2:
        return np.zeros(len(points))
    single = single_support(points)
    weight = (single[:-1] & single[1:]) + SHARE_FLOOR
    return np.concatenate([[0.0], np.cumsum(weight) / weight.sum()])


def step_turns(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(n,)`` cumulative degrees a stepping figure may turn by each frame, and ``(n, 2)`` the point (X, Z
    cm) it turns about. Between frames k and k+1 it may turn only if at most one sole point is down (within
    LIFT_CM of the clip's lowest) at either: STEP_TURN_DEG spread over each such window (FRAME_TURN_DEG a
    frame at most), about that point, which stays put; the point is kept while it stays down. Turned through
    a flat stance about the middle of the foot, heel and ball slid 4.4 cm at 30°, 6-9 cm at 90-110°."""
    n = len(points)
    flat = points.reshape(n, -1, 3)
    down = flat[..., 1] <= flat[..., 1].min() + LIFT_CM  # (n, feet * points)
    either = down[:-1] | down[1:]
    free = either.sum(axis=1) <= 1
    turn = window_turns(free, STEP_TURN_DEG)
    contact = stance_contact(points)
    pivot = np.where(either.any(axis=1), either.argmax(axis=1), flat[:-1, :, 1].argmin(axis=1))
    for k in np.flatnonzero(free).tolist():  # the pivot, over the whole time it is down
        p = int(pivot[k])
        lo, hi = k, k + 1
        while lo > 0 and down[lo - 1, p]:
            lo -= 1
        while hi < n - 1 and down[hi + 1, p]:
            hi += 1
        contact[lo : hi + 1] = flat[lo : hi + 1, p][:, [0, 2]]
    return turn, contact


def window_turns(free: np.ndarray, degrees: float) -> np.ndarray:
    """``(n,)`` cumulative degrees by each frame: ``degrees`` spread over each window of consecutive ``free``
    frame intervals (``(n-1,)``), FRAME_TURN_DEG an interval at most."""
    weight = np.zeros(len(free))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], free.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # each window [a, b) of free intervals
        weight[a:b] = min(degrees / (b - a), FRAME_TURN_DEG)
    return np.concatenate([[0.0], np.cumsum(weight)])


def side_turns(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(n,)`` cumulative degrees a side-stepping figure may turn by each frame, and ``(n, 2)`` the point
    (X, Z cm) it turns about: SIDE_TURN_DEG spread over each stance where one foot alone is down
    (:func:`single_support`), about the middle of that foot's sole points (:func:`stance_contact`). Turned at
    TURN_RATE about the root through the shuffle, its feet twisted 9-13 cm at a 30° heading change."""
    single = single_support(points)
    return window_turns(single[:-1] & single[1:], SIDE_TURN_DEG), stance_contact(points)


def stance_travel(points: np.ndarray, stride: float | None = None) -> np.ndarray:
    """``(n, 2)`` cumulative horizontal travel (X, Z cm) that keeps the point carrying the weight still
    (:func:`contact_points` of :func:`feet_points`): the body travels by minus its move. Frames with both feet
    off the ground (a run's flight) share what the stance frames leave of ``stride`` (cm, the clip's recorded
    travel), evenly."""
    n = len(points)
    out = np.zeros((n, 2))
    if n < 2:
        return out
    move, height = contact_points(points)
    step = -move
    flight = height > FLIGHT_CM
    step[flight] = 0.0
    measured = step.sum(axis=0)
    length = float(np.hypot(*measured))
    if stride and flight.any() and length > 1e-6 and stride > length:
        step[flight] = measured / length * (stride - length) / int(flight.sum())
    out[1:] = np.cumsum(step, axis=0)
    return out


class TravelTable:
    """Per clip its stance travel curve, flat like ``ClipLibrary`` data; interpolated at fractional frames."""

    def __init__(
        self,
        curves: Sequence[np.ndarray],
        contacts: Sequence[np.ndarray] | None = None,
        shares: Sequence[np.ndarray] | None = None,
        stances: Sequence[int] | None = None,
        turns: Sequence[np.ndarray | None] | None = None,
    ) -> None:
        sizes = np.array([len(c) for c in curves], np.int64)
        self.start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        self.nframes = sizes
        self.last = np.maximum(sizes - 1, 0)  # per clip its last frame's number (the lerps clamp to it)
        self.data = (
            np.concatenate([np.asarray(c, np.float64).reshape(-1, 2) for c in curves])
            if len(curves)
            else np.zeros((0, 2))
        )
        self.contact = (
            np.concatenate([np.asarray(c, np.float64).reshape(-1, 2) for c in contacts])
            if contacts is not None and len(contacts)
            else np.zeros_like(self.data)
        )
        # per clip how many single-support stances it has (turns in place; 1 elsewhere)
        self.stances = np.maximum(np.asarray(stances if stances is not None else [1] * len(curves)), 1)
        lines = [np.linspace(0.0, 1.0, len(c)) if len(c) > 1 else np.zeros(len(c)) for c in curves]
        self.share = np.concatenate(list(shares if shares is not None else lines) or [np.zeros(0)])
        # per stepping clip the degrees it may have turned by each frame (:func:`step_turns`); None: TURN_RATE
        turns = list(turns) if turns is not None else [None] * len(curves)
        self.paced = np.array([c is not None for c in turns], bool)
        self.turn = np.concatenate(
            [np.zeros(len(c)) if t is None else t for c, t in zip(curves, turns, strict=True)]
            or [np.zeros(0)]
        )
        self.total = np.array([c[-1] - c[0] if len(c) else (0.0, 0.0) for c in curves], np.float64).reshape(
            -1, 2
        )
        self.ahead = self.paced & (self.total[:, 1] < -np.abs(self.total[:, 0]))
        # a side-step turns in its single-support stances (:func:`side_turns`); an end step has no window: a
        # forwards one does not turn (a turn in place follows if it must)
        self.paced &= self.ahead | np.array([t is not None and len(t) > 0 and t[-1] > 0 for t in turns], bool)

    def at(self, clip: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """``(n, 2)`` travel of ``clip`` at fractional ``frame`` (clamped to the clip)."""
        return self._lerp(self.data, clip, frame)

    def _lerp(self, values: np.ndarray, clip: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Per-frame ``values`` (flat over clips) of ``clip`` at fractional ``frame`` (clamped), blended."""
        clip = np.asarray(clip, np.int64)
        last = self.last[clip]
        f = np.minimum(np.maximum(np.asarray(frame, np.float64), 0.0), last)  # np.clip's values, cheaper
        f0 = np.floor(f).astype(np.int64)
        f1 = np.minimum(f0 + 1, last)
        w = f - f0
        base = self.start[clip]
        v0, v1 = np.take(values, base + f0, axis=0), np.take(values, base + f1, axis=0)
        if values.ndim == 1:
            return v0 * (1.0 - w) + v1 * w
        return scaled(v0, 1.0 - w) + scaled(v1, w)

    def at_exact(self, clip: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """:meth:`at1` over arrays, bit for bit (``v0 + (v1 - v0) w``, not :meth:`at`'s blend): the grouped
        event paths store what the per-soldier one stored."""
        clip = np.asarray(clip, np.int64)
        last = self.last[clip]
        f = np.minimum(np.maximum(np.asarray(frame, np.float64), 0.0), last)
        f0 = np.floor(f).astype(np.int64)
        base = self.start[clip]
        v0 = np.take(self.data, base + f0, axis=0)
        return v0 + scaled(np.take(self.data, base + np.minimum(f0 + 1, last), axis=0) - v0, f - f0)

    def at1(self, clip: int, frame: float) -> tuple[float, float]:
        """:meth:`at` for one clip and frame in scalar Python (the per-event paths)."""
        last = max(int(self.nframes[clip]) - 1, 0)
        f = min(max(frame, 0.0), float(last))
        f0 = int(f)
        w = f - f0
        base = int(self.start[clip])
        x0, z0 = self.data[base + f0].tolist()
        if w == 0.0 or f0 >= last:
            return x0, z0
        x1, z1 = self.data[base + f0 + 1].tolist()
        return x0 + (x1 - x0) * w, z0 + (z1 - z0) * w

    def share_at(self, clip: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """``(n,)`` :func:`single_support_share` of ``clip`` at fractional ``frame`` (clamped to the clip)."""
        return self._lerp(self.share, clip, frame)

    def turn_at(self, clip: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """``(n,)`` the degrees :func:`step_turns` lets ``clip`` turn by fractional ``frame`` (clamped)."""
        return self._lerp(self.turn, clip, frame)

    def contact_at(self, clip: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """``(n, 2)`` the weight-bearing sole point of ``clip`` at the frame nearest ``frame``."""
        clip = np.asarray(clip, np.int64)
        last = self.last[clip]
        f = np.minimum(np.maximum(np.floor(np.asarray(frame, np.float64) + 0.5).astype(np.int64), 0), last)
        return np.take(self.contact, self.start[clip] + f, axis=0)


def measure(figure: Figure, joints: np.ndarray, placements: np.ndarray) -> np.ndarray:
    """The stance travel curve of one clip's frames (soldier pose vectors and root placements)."""
    kin = FigureKinematics(figure)
    return stance_travel(feet_points(kin, joints, placements))


# -- the per-soldier root offset over a SoldierTable (vectorised; the manager calls these) -----------------
def scaled(rows: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``rows * v[:, None]`` of (n, k) ``rows`` and (n,) ``v``, a column at a time: numpy broadcasts an
    (n, 1) over a short last axis with an inner loop per row, 4-8 times dearer at k = 2 and 4,000-10,000
    rows; below COLUMNS_MIN rows the broadcast's one call is the cheaper."""
    v = np.asarray(v)
    if len(rows) < COLUMNS_MIN:
        return rows * v[:, None]
    out = np.empty(rows.shape, np.result_type(rows, v))
    for k in range(rows.shape[1]):
        np.multiply(rows[:, k], v, out=out[:, k])
    return out


def frame_at(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """The fractional frame each soldier's clip shows at ``t`` (as ``ClipLibrary.sample`` computes it)."""
    clip = tb.clip[idx]
    u = np.minimum(np.maximum((t - tb.start[idx]) / np.maximum(tb.dur[idx], 1e-9), 0.0), 1.0)  # np.clip's
    u = np.where(tb.direc[idx] > 0, u, 1.0 - u)
    return u * lib.clip_last[clip]


def offset_at(
    tb: SoldierTable,
    lib: MotionLibrary,
    idx: np.ndarray,
    t: np.ndarray | float,
    frames: np.ndarray | None = None,
    travel_now: np.ndarray | None = None,
) -> np.ndarray:
    """``(n, 2)`` root offsets at ``t``: the offset at ``root_t`` plus the clip's own travel since (times the
    stride scale) minus the entity's dead-reckoned travel since (``travel_now``: the clips' travel at
    ``frames``, if the caller has it)."""
    if frames is None:
        frames = frame_at(tb, lib, idx, t)
    if travel_now is None:
        travel_now = lib.travel.at(tb.clip[idx], frames)
    travel = scaled(travel_now - np.take(tb.root_ref, idx, axis=0), tb.stride[idx])
    dt = np.asarray(t, np.float64) - tb.root_t[idx]
    off = np.take(tb.root_off, idx, axis=0)
    return off + yawed(travel, tb.root_yaw[idx]) - scaled(np.take(tb.vlocal, idx, axis=0), dt)


def yawed(xz: np.ndarray, compass_deg: np.ndarray) -> np.ndarray:
    """``(n, 2)`` horizontal vectors of the soldier frame turned by compass degrees (as blend.yaw_rotate)."""
    compass_deg = np.asarray(compass_deg, np.float64)
    turned = np.flatnonzero(compass_deg != 0.0)
    if len(turned) < len(compass_deg):  # unturned rows as they are (a walking crowd: most, or all, of them)
        out = np.array(xz, np.float64)
        if len(turned):
            set_rows(out, turned, yawed(np.take(out, turned, axis=0), compass_deg[turned]))
        return out
    a = -np.radians(compass_deg)
    c, s = np.cos(a), np.sin(a)
    x, z = xz[:, 0], xz[:, 1]
    out = np.empty((len(a), 2))  # (np.stack's values, without its overhead: called on every answer)
    out[:, 0] = c * x + s * z
    out[:, 1] = c * z - s * x
    return out


def fold(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, t: np.ndarray | float) -> None:
    """Bring the offsets up to ``t``: before a clip, the velocity or the stride scale changes, and while a
    stepping figure turns towards the heading (:func:`steer`), about the sole point carrying its weight: a
    walking or running one by what :func:`step_turns` allows between the frames shown then and now (at most
    STEP_TURN_RATE), a crawling one at TURN_RATE. A pivot's extra turn (:func:`pivot`) comes first: a request
    mid-pivot folds to its time, and the share turned since the last update was lost (issue 16: asked to
    kneel mid-pivot at 10 Hz he knelt 5.6° off his heading, then snapped to it)."""
    if len(idx) == 0:
        return
    p = np.flatnonzero(tb.pivot_rest[idx] != 0.0)
    if len(p):
        pivot(tb, lib, idx[p], np.broadcast_to(np.asarray(t, np.float64), idx.shape)[p])
    frames = frame_at(tb, lib, idx, t)
    travel_now = lib.travel.at(tb.clip[idx], frames)
    off = offset_at(tb, lib, idx, t, frames, travel_now)
    yaw = tb.root_yaw[idx]
    mode = tb.mode[idx]
    turning = (yaw != 0.0) & ((mode == STEPPING[0]) | (mode == STEPPING[1]))
    turning &= ~tb.reversing[idx]  # a reversing figure stops facing the old way, then pivots
    j = np.flatnonzero(turning)
    if len(j):  # the turning rows alone (a walking crowd: few of them)
        ti, fj, yj, oj = idx[j], frames[j], yaw[j], np.take(off, j, axis=0)
        dt = np.maximum(np.broadcast_to(np.asarray(t, np.float64), idx.shape)[j] - tb.root_t[ti], 0.0)
        rate = TURN_RATE * np.maximum(1.0, np.abs(yj) / 90.0)  # a reversal turns faster (it walks away)
        rate = np.where(tb.mode[ti] == STEPPING[1], CRAWL_TURN_RATE, rate)
        clip = tb.clip[ti]
        was = lib.travel.turn_at(clip, frame_at(tb, lib, ti, tb.root_t[ti]))
        free = np.minimum(np.abs(lib.travel.turn_at(clip, fj) - was), STEP_TURN_RATE * dt)
        step = np.where(lib.travel.paced[clip], free, rate * dt)
        new = yj - np.minimum(np.maximum(yj - steer(tb, lib, ti, oj), -step), step)
        contact = lib.travel.contact_at(clip, fj)
        # about the sole point carrying the weight
        set_rows(off, j, oj + yawed(contact, yj) - yawed(contact, new))
        tb.root_yaw[ti] = new
    set_rows(tb.root_off, idx, off)
    tb.root_t[idx] = t
    set_rows(tb.root_ref, idx, travel_now)


def steer(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, off: np.ndarray) -> np.ndarray:
    """``(n,)`` compass degrees from the heading that soldiers ``idx`` (root offsets ``off``) turn towards:
    the heading, or for a figure walking or running forwards along a velocity along its heading, towards its
    entity's path, STEER_S ahead, when it is more than STEER_FREE_CM beside it. Turned 90° at each footfall
    without it, a walker at 1.4 m/s ended 1.1 m beside the path (110°: 1.9 m); with it 0.1 m (0.4 m)."""
    v = np.take(tb.vlocal, idx, axis=0)
    speed = np.hypot(v[:, 0], v[:, 1])
    ahead = lib.travel.ahead[tb.clip[idx]] & (tb.direc[idx] > 0) & (np.abs(v[:, 0]) <= 0.01 * speed)
    side = np.sign(off[:, 0]) * np.maximum(np.abs(off[:, 0]) - STEER_FREE_CM, 0.0)
    aim = -np.degrees(np.arctan2(side, np.maximum(speed * STEER_S, 100.0)))
    aim = np.minimum(np.maximum(aim, -STEER_MAX_DEG), STEER_MAX_DEG)
    return np.where(ahead & (v[:, 1] < 0.0), aim, 0.0)


def pivot(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, t: np.ndarray | float) -> None:
    """A pivot (a turn in place) also turns the figure by what the turn clip lacks (``pivot_rest``
    degrees), about the sole point carrying its weight (as :func:`fold` turns a stepping figure), while one
    foot alone carries it (``TravelTable.share``): turned in double support it dragged the other foot."""
    if len(idx) == 0:
        return
    t = np.minimum(np.asarray(t, np.float64), tb.end[idx])
    frames = frame_at(tb, lib, idx, t)
    clip = tb.clip[idx]
    travel_now = lib.travel.at(clip, frames)
    off = offset_at(tb, lib, idx, t, frames, travel_now)
    yaw = tb.root_yaw[idx]
    was = lib.travel.share_at(clip, frame_at(tb, lib, idx, tb.root_t[idx]))
    new = yaw + tb.pivot_rest[idx] * (lib.travel.share_at(clip, frames) - was)
    contact = lib.travel.contact_at(clip, frames)
    set_rows(tb.root_off, idx, off + yawed(contact, yaw) - yawed(contact, new))
    tb.root_yaw[idx] = new
    tb.root_t[idx] = t
    set_rows(tb.root_ref, idx, travel_now)


def frame_at1(tb: SoldierTable, lib: MotionLibrary, i: int, t: float) -> float:
    """:func:`frame_at` for one soldier in scalar Python."""
    u = min(max((t - float(tb.start[i])) / max(float(tb.dur[i]), 1e-9), 0.0), 1.0)
    if tb.direc[i] <= 0:
        u = 1.0 - u
    return u * max(int(lib.clip_nframes[tb.clip[i]]) - 1, 0)


def fold1(tb: SoldierTable, lib: MotionLibrary, i: int, t: float) -> None:
    """:func:`fold` for one soldier in scalar Python (a request or a clip change of one soldier)."""
    yaw = float(tb.root_yaw[i])
    if yaw != 0.0 or tb.pivot_rest[i] != 0.0:  # turning about a contact point: the vectorised path
        fold(tb, lib, np.array([i], np.int64), t)
        return
    tx, tz = lib.travel.at1(int(tb.clip[i]), frame_at1(tb, lib, i, t))
    rx, rz = tb.root_ref[i].tolist()
    vx, vz = tb.vlocal[i].tolist()
    ox, oz = tb.root_off[i].tolist()
    s = float(tb.stride[i])
    dt = t - float(tb.root_t[i])
    tb.root_off[i] = (ox + (tx - rx) * s - vx * dt, oz + (tz - rz) * s - vz * dt)
    tb.root_t[i] = t
    tb.root_ref[i] = (tx, tz)


def fold_exact(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, t: np.ndarray) -> None:
    """:func:`fold1` of soldiers ``idx`` at once, bit for bit: a turned figure's rows through :func:`fold`,
    the rest through :func:`fold_unturned`."""
    turned = (tb.root_yaw[idx] != 0.0) | (tb.pivot_rest[idx] != 0.0)
    if turned.any():
        fold(tb, lib, idx[turned], t[turned])
        idx, t = idx[~turned], t[~turned]
    if len(idx):
        fold_unturned(tb, lib, idx, t)


def fold_unturned(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray, t: np.ndarray) -> None:
    """:func:`fold1` of soldiers whose figure faces its heading (``root_yaw`` 0) at once, bit for bit."""
    travel = lib.travel.at_exact(tb.clip[idx], frame_at(tb, lib, idx, t))
    dt = t - tb.root_t[idx]
    off = np.take(tb.root_off, idx, axis=0)
    off = off + scaled(travel - np.take(tb.root_ref, idx, axis=0), tb.stride[idx])
    set_rows(tb.root_off, idx, off - scaled(np.take(tb.vlocal, idx, axis=0), dt))
    tb.root_t[idx] = t
    set_rows(tb.root_ref, idx, travel)


def rebase_exact(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray) -> None:
    """:func:`rebase1` of soldiers ``idx`` at once, bit for bit."""
    set_rows(tb.root_ref, idx, lib.travel.at_exact(tb.clip[idx], frame_at(tb, lib, idx, tb.root_t[idx])))


def rebase1(tb: SoldierTable, lib: MotionLibrary, i: int) -> None:
    """:func:`rebase` for one soldier in scalar Python."""
    tb.root_ref[i] = lib.travel.at1(int(tb.clip[i]), frame_at1(tb, lib, i, float(tb.root_t[i])))


def rebase(tb: SoldierTable, lib: MotionLibrary, idx: np.ndarray) -> None:
    """After a new clip starts (at ``root_t``): its travel counts from the frame it shows then."""
    if len(idx):
        set_rows(tb.root_ref, idx, lib.travel.at(tb.clip[idx], frame_at(tb, lib, idx, tb.root_t[idx])))


def turn_offsets(tb: SoldierTable, idx: np.ndarray, compass_change: np.ndarray) -> None:
    """The entity turned by ``compass_change`` degrees (clockwise): a world-fixed offset turns the other way
    in the soldier's frame."""
    a = np.radians(compass_change)
    c, s = np.cos(a), np.sin(a)
    x, z = tb.root_off[idx, 0].copy(), tb.root_off[idx, 1].copy()
    tb.root_off[idx, 0] = x * c + z * s
    tb.root_off[idx, 1] = -x * s + z * c
