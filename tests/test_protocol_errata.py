"""Issue 18's errata of docs/PROTOCOL.md, each held to the code: §7.1's resolution table is the real table's,
the least max_frame a client may announce is stated with the real sizes and refused below, padding bits name
their error, count-0 JOINT_UPDATES are valid and change nothing, UPDATE_TABLE and READY come unasked."""

from __future__ import annotations

import math
import re
from pathlib import Path

import msgpack
import numpy as np
from test_protocol_figure import soldier
from test_protocol_messages import deliver, open_pair

from protocol import coords
from protocol.connection import SERVER, Connection
from protocol.errors import ErrorCode
from protocol.events import JointUpdates, ProtocolError, Subscribe, UpdateTableMsg
from protocol.figure import figure_to_wire
from protocol.framing import MIN_CLIENT_MAX_FRAME, encode_frame
from protocol.messages import HANDSHAKE_PREFIX, MAGIC, MessageType, pack_body
from protocol.update_table import FigureEntry, JointEntry, example_di_table, table_to_wire
from protocol.updates import UPDATE_HEADER

DOC = (Path(__file__).resolve().parents[1] / "docs" / "PROTOCOL.md").read_text()


def _section(start: str, end: str) -> str:
    return DOC[DOC.index(start) : DOC.index(end)]


def test_resolution_table_is_the_real_tables() -> None:
    table, _, _ = soldier()
    dofs = [(e.name, d) for e in table.entries if isinstance(e, JointEntry) for d in e.dofs]
    rot = {(d.lo, d.hi, d.bits) for _, d in dofs if d.kind == "R"}
    assert rot == {(-math.pi, math.pi, 12)}  # knees too
    (trans,) = [(name, d) for name, d in dofs if d.kind == "T"]
    assert trans[0] == "spine_compression" and (trans[1].lo, trans[1].hi) == (-0.03, 0.01)
    res = _section("### 7.1 Quantisation", "## 8. Joint updates")
    assert "| every rotational DOF (knees too) | `[−π, π)`, 12 |" in res
    step_mm = (trans[1].hi - trans[1].lo) / 4096 * 1000
    assert (
        f"| `spine_compression` (the one translational DOF) | `[−0.03, 0.01)` m, 12 | {step_mm:.4f} mm |"
        in res
    )
    assert "160°" not in res and "0.05" not in res


def test_least_client_max_frame_and_the_sizes_the_doc_states() -> None:
    table, figures, _ = soldier()
    names = [e.name for e in table.entries if isinstance(e, FigureEntry)]
    update_table = len(pack_body(table_to_wire(table))) + 1
    plain = len(pack_body(figure_to_wire(table, figures, names), single_float=True)) + 1
    meshes = len(pack_body(figure_to_wire(table, figures, names, meshes=True), single_float=True)) + 1
    assert max(update_table, plain) <= MIN_CLIENT_MAX_FRAME
    framing = _section("## 2. Framing", "## 3. Handshake")
    assert f"UPDATE_TABLE ({update_table:,} bytes" in framing
    assert f"FIGURE without meshes ({plain:,} bytes" in framing and f"{MIN_CLIENT_MAX_FRAME:,}" in framing
    assert f"{plain:,} bytes without meshes" in DOC and f"{meshes:,} bytes with them" in DOC


def test_hello_below_the_least_max_frame_is_a_clear_bad_value() -> None:
    body = msgpack.packb({"name": "1994", "role": "observer", "max_frame": MIN_CLIENT_MAX_FRAME - 1})
    server = Connection(SERVER)
    (err,) = deliver(server, encode_frame(MessageType.HELLO, HANDSHAKE_PREFIX.pack(MAGIC, 1) + body))
    assert isinstance(err, ProtocolError) and err.code == ErrorCode.BAD_VALUE
    assert f"below {MIN_CLIENT_MAX_FRAME}" in err.message and "UPDATE_TABLE" in err.message
    assert b"below 65536" in server.data_to_send()  # the ERROR frame the client reads


def _pose(angle: float) -> JointUpdates:
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (1, 2, 1))
    return JointUpdates(1, np.array([0]), np.full((1, 50), angle), np.zeros((1, 2, 3)), quat)


def _full_frame() -> tuple[bytes, Connection, Connection]:
    """A full update of soldier 0 (DI-shaped table, every DOF 0) from ``server`` for ``client``."""
    client, server = open_pair()
    deliver(client, server.send(UpdateTableMsg(example_di_table(1))))
    deliver(server, client.send(Subscribe((0,))))
    return server.send(_pose(0.0)), client, server


def test_non_zero_padding_bits_are_malformed_frame() -> None:
    frame, _, _ = _full_frame()
    head_end = 5 + UPDATE_HEADER.size + 2 + 4  # 29 header bits in 4 bytes: the last 3 bits are padding
    for at in (head_end - 1, len(frame) - 1):  # header padding, field padding (772 field bits: 4 padding)
        _, client, _ = _full_frame()
        bad = bytearray(frame)
        bad[at] |= 0x01
        (err,) = deliver(client, bytes(bad))
        assert isinstance(err, ProtocolError) and err.code == ErrorCode.MALFORMED_FRAME
    doc = _section("### 8.1 Header bits", "### 8.3 Applying a frame")
    assert doc.count("padding bits must be 0 (else MALFORMED_FRAME, 1, fatal)") == 1
    assert "its padding bits must\nbe 0 (else MALFORMED_FRAME, 1, fatal)" in doc


def test_count_zero_joint_updates_are_valid_and_change_nothing() -> None:
    frame, client, server = _full_frame()
    deliver(client, frame)
    empty = encode_frame(MessageType.JOINT_UPDATES, UPDATE_HEADER.pack(1, 9, 0))
    (ev,) = deliver(client, empty)
    assert isinstance(ev, JointUpdates) and len(ev.indices) == 0 and ev.tick == 9
    (delta,) = deliver(client, server.send(_pose(0.01)))  # a delta on the state before the empty frame
    assert np.allclose(delta.dofs, 0.01, atol=1e-3)
    assert "**count 0.** A frame with `count` = 0 is valid" in DOC
    longer = encode_frame(MessageType.JOINT_UPDATES, UPDATE_HEADER.pack(1, 9, 0) + b"\x00")
    (err,) = deliver(client, longer)
    assert isinstance(err, ProtocolError) and err.code == ErrorCode.MALFORMED_FRAME


def test_section_11_says_tables_and_ready_come_unasked() -> None:
    text = _section("## 11. Example session", "<!-- example-session:begin")
    assert re.search(r"then, \*\*unasked\*\*, the server sends every UPDATE_TABLE and READY", text)
    assert "A client need not send any JCL" in text


def test_the_root_yaw_the_doc_explains_is_the_shipped_clips() -> None:
    """§7.2: a standing soldier's figure quaternion is −45° about +Z (bladed), a kneeling one's −30°."""
    from server.config import DEFAULT_DATA_DIR
    from server.motion.cache import load_channelset

    for clip, yaw in (("ststow2stfire", -45.0), ("kstow2kfire", -30.0)):
        c = load_channelset(DEFAULT_DATA_DIR / "channelsets" / f"{clip}_low.chset.env")
        w, x, y, z = coords.quats_jack_to_performer(c.fig_quat[-1, 0])
        assert abs(x) < 1e-3 and abs(y) < 1e-3
        assert abs(math.degrees(2 * math.atan2(z, w)) - yaw) < 0.5
    assert "`(0.924, 0, 0, −0.383)`,\n−45° about +Z" in DOC and "Kneeling soldiers\narrive turned −30°" in DOC
