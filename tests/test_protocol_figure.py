"""FIGURE (issue 18): a client that knows only the wire (UPDATE_TABLE, FIGURE, JOINT_UPDATES; no .fig file)
places every site of the soldier and his rifle where Peabody's FK does, to 1 mm; the decoder takes any
bytes."""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_messages import deliver, open_pair

from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from peabody.model import Figure
from protocol import coords
from protocol.errors import ErrorCode, WireError
from protocol.events import FigureMsg, JointUpdates, ProtocolError, RequestFigure, Subscribe, UpdateTableMsg
from protocol.figure import figure_from_wire, figure_to_wire
from protocol.framing import encode_frame
from protocol.messages import MessageType, pack_body
from protocol.update_table import FigureEntry, JointEntry, UpdateTable, table_to_wire
from server.config import DEFAULT_DATA_DIR
from server.soldier.wire import update_table_for

FIGURES = DEFAULT_DATA_DIR / "figures"


@cache
def soldier() -> tuple[UpdateTable, tuple[Figure, ...], dict]:
    """The server's table for DI.fig + AK-47 (``update_table_for``) and the FIGURE body the server sends."""
    figures = (read_figure(FIGURES / "DI.fig"), read_figure(FIGURES / "AK_47.fig"))
    library = SimpleNamespace(
        sets=[SimpleNamespace(prototypes=list(figures))], set_keys=[("DI.fig", "AK_47.fig")]
    )
    table = update_table_for(library, 1)  # type: ignore[arg-type]
    names = [e.name for e in table.entries if isinstance(e, FigureEntry)]
    return table, figures, figure_to_wire(table, figures, names, meshes=True)


def _wire_client(poses: np.ndarray, placements: np.ndarray) -> tuple[FigureMsg, JointUpdates]:
    """Server → client over two Connections: the table, the FIGURE, one batch of soldiers."""
    table, _, body = soldier()
    client, server = open_pair()
    deliver(client, server.send(UpdateTableMsg(table)))
    (fig,) = deliver(client, server.send(FigureMsg(1, (), body)))
    n = len(poses)
    deliver(server, client.send(Subscribe(tuple(range(n)))))
    pos, quat = coords.transform_to_pose7(placements)
    sent = JointUpdates(1, np.arange(n), poses, pos, quat)
    (got,) = deliver(client, server.send(sent))
    assert isinstance(fig, FigureMsg) and isinstance(got, JointUpdates)
    return fig, got


def _peabody_sites(figure: Figure, dofs: np.ndarray, placement: np.ndarray) -> dict[str, np.ndarray]:
    """Reference: Peabody FK in Jack units on the same decoded values, sites converted to the wire's axes."""
    kin = FigureKinematics(figure)
    q = dofs.copy()
    q[~kin.rotational] *= coords.CM_PER_M
    root = coords.transforms_performer_to_jack(placement)
    p = coords.points_jack_to_performer(kin.site_globals(q, root)[:, :3, 3])
    return dict(zip(kin.site_names, p, strict=True))


unit = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=25, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.lists(st.tuples(unit, unit, unit, unit), min_size=2, max_size=2),
    st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6),
)
def test_a_client_with_only_figure_places_every_site_like_peabody(
    seed: int, quats: list[tuple[float, ...]], offsets: list[float]
) -> None:
    table, figures, _ = soldier()
    rng = np.random.default_rng(seed)
    layout = table.layout
    lo, step = layout.lo[layout.dof_fields], layout.step[layout.dof_fields]
    codes = rng.integers(0, 1 << layout.width[layout.dof_fields])
    poses = (lo + codes * step)[None, :]
    q = np.array([v if np.linalg.norm(v) > 0.1 else (1.0, 0, 0, 0) for v in quats], np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    placements = coords.pose7_to_transform(np.reshape(offsets, (2, 3)), q)[None]
    fig, got = _wire_client(poses, placements)
    # the client: placement from the decoded figure entries, angles from the decoded joint entries
    decoded = coords.pose7_to_transform(got.positions[0], got.orientations[0])
    start = 0
    for k, (wire_fig, figure) in enumerate(zip(fig.figures, figures, strict=True)):
        sites = wire_fig.site_globals(table, got.dofs[0], decoded[k])[:, :3, 3]
        ndof = FigureKinematics(figure).ndof
        ref = _peabody_sites(figure, got.dofs[0, start : start + ndof], decoded[k])
        start += ndof
        assert list(ref) == list(wire_fig.site_names)
        err = np.abs(sites - np.array(list(ref.values()))).max()
        assert err < 1e-3, (wire_fig.name, err)


def test_figure_names_the_sites_a_client_needs_and_the_neutral_facing() -> None:
    table, _, body = soldier()
    tid, (di, ak) = figure_from_wire(msgpack.unpackb(msgpack.packb(body, use_single_float=True)))
    assert tid == 1 and (di.name, di.file, ak.name) == ("soldier", "DI.fig", "rifle")
    for site in (
        "left_palm.grip",
        "right_palm.grip",
        "bottom_head.sight",
        "left_foot.heel",
        "right_foot.toe",
    ):
        assert site in di.site_names
    assert {"rifle.grip", "rifle.sight", "rifle.muzzle", "rifle.butt"} <= set(ak.site_names)
    assert body["figures"][0]["facing"] == [0.0, 1.0, 0.0] and body["figures"][0]["up"] == [0.0, 0.0, 1.0]
    # every joint entry of the table is placed by exactly one segment of one figure
    joints = {i for i, e in enumerate(table.entries) if isinstance(e, JointEntry)}
    placed = [int(e) for f in (di, ak) for e in f.entry if e >= 0]
    assert sorted(placed) == sorted(joints)
    assert set(di.meshes) and all(len(t) for _, t in di.meshes.values())


def test_figure_frame_fits_the_least_max_frame_a_client_may_announce() -> None:
    from protocol.framing import MIN_CLIENT_MAX_FRAME

    table, figures, _ = soldier()
    names = [e.name for e in table.entries if isinstance(e, FigureEntry)]
    plain = msgpack.packb(figure_to_wire(table, figures, names), use_single_float=True)
    assert len(plain) + 1 <= MIN_CLIENT_MAX_FRAME
    assert len(pack_body(table_to_wire(table))) + 1 <= MIN_CLIENT_MAX_FRAME  # UPDATE_TABLE: 1,706 bytes


def test_figure_for_a_table_never_sent_is_unknown_table() -> None:
    _, _, body = soldier()
    client, _ = open_pair()
    frame = encode_frame(MessageType.FIGURE, msgpack.packb(body, use_single_float=True))
    (err,) = deliver(client, frame)
    assert isinstance(err, ProtocolError) and err.code == ErrorCode.UNKNOWN_TABLE


# -- the decoder takes any bytes: WireError (SCHEMA / BAD_VALUE) or a figure ---------------------------------

junk = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**40), 2**40) | st.floats() | st.text(max_size=8),
    lambda kids: st.lists(kids, max_size=6) | st.dictionaries(st.text(max_size=8), kids, max_size=6),
    max_leaves=30,
)


def _paths(node: object, at: tuple = ()) -> list[tuple]:
    out = [at]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*at, k))
    elif isinstance(node, list):
        for i, v in enumerate(node[:8]):
            out += _paths(v, (*at, i))
    return out


def _replace(node: object, path: tuple, value: object) -> object:
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(node, dict):
        return {**node, head: _replace(node[head], rest, value)}
    assert isinstance(node, list)
    return [*node[:head], _replace(node[head], rest, value), *node[head + 1 :]]


def _small_body() -> dict:
    body = soldier()[2]
    small = {**body["figures"][1], "meshes": body["figures"][1].get("meshes", [])[:1]}
    return {"table": 1, "figures": [small]}


@settings(max_examples=300, deadline=None)
@given(junk)
def test_figure_decoder_raises_only_wire_errors_on_junk(raw: object) -> None:
    with pytest.raises(WireError) as exc:
        figure_from_wire(raw)
    assert exc.value.code in (ErrorCode.SCHEMA, ErrorCode.BAD_VALUE)


@settings(max_examples=300, deadline=None)
@given(st.data(), junk)
def test_figure_decoder_on_mutated_bodies(data: st.DataObject, value: object) -> None:
    body = _small_body()
    path = data.draw(st.sampled_from(_paths(body)))
    mutated = _replace(body, path, value)
    try:
        figure_from_wire(msgpack.unpackb(msgpack.packb(mutated)))
    except WireError as exc:
        assert exc.code in (ErrorCode.SCHEMA, ErrorCode.BAD_VALUE)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_figure_frames_of_random_bytes_are_protocol_errors(payload: bytes) -> None:
    client, server = open_pair()
    deliver(client, server.send(UpdateTableMsg(soldier()[0])))
    (ev,) = deliver(client, encode_frame(MessageType.FIGURE, payload))
    assert isinstance(ev, ProtocolError) and ev.code in (ErrorCode.SCHEMA, ErrorCode.BAD_VALUE)


def test_request_figure_round_trips_and_checks_its_fields() -> None:
    client, server = open_pair()
    for ev in (RequestFigure(7, 1), RequestFigure(8, 2, meshes=True)):
        assert deliver(server, client.send(ev)) == [ev]
    bad = encode_frame(MessageType.REQUEST_FIGURE, msgpack.packb({"id": 1, "table": 1, "meshes": 1}))
    (err,) = deliver(server, bad)
    assert isinstance(err, ProtocolError) and err.code == ErrorCode.SCHEMA
