"""`ttes cigi`'s host against an in-process server (autojump clock): a 10-soldier scene's CIGI messages, read
back by our decoder and by Wireshark's CIGI dissector (tshark; skipped where it is not installed)."""

from __future__ import annotations

import functools
import shutil
import subprocess
from pathlib import Path

import dpkt
import pytest
import trio
import trio.testing
from test_server_support import running_server

from client_stub.cigi.host import CigiHost, HostConfig
from client_stub.link.client import Client
from protocol import cigi, cigi_scene
from protocol.dis.geo import LocalFrame
from protocol.dis.synth import udp_frame

SOLDIERS = 10
FRAMES = 45
PORT = 8004


@functools.cache
def scene() -> tuple[list[bytes], dict, dict[int, int]]:
    """The messages of FRAMES frames at 30 fps, the part map, and entity id -> entity type."""
    sent: list[bytes] = []

    async def main() -> tuple[dict, dict[int, int]]:
        async with running_server(throttle=0.0) as server, trio.open_nursery() as nursery:
            link = Client("cigi-test")
            await link.open(nursery, "127.0.0.1", server.addresses[0][1])
            host = CigiHost(link, HostConfig(SOLDIERS, 30.0, LocalFrame(52.0, 4.0, 10.0)), sent.append)
            await host.populate()
            await host.run(FRAMES)
            types = cigi_scene.entity_types(link.tables)
            by_entity = {i: types[t] for i, t in host.table_of.items()}
            parts = cigi_scene.part_map(link.tables)
            await link.aclose()
            nursery.cancel_scope.cancel()
            return parts, by_entity

    parts, by_entity = trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    return sent, parts, by_entity


def test_every_frame_opens_with_ig_control_and_carries_every_soldier() -> None:
    messages, parts, by_entity = scene()
    frames: dict[int, list[cigi.Packet]] = {}
    for m in messages:
        assert len(m) <= cigi_scene.MAX_MESSAGE
        packets, skipped = cigi.decode_message(m)
        assert skipped == 0 and isinstance(packets[0], cigi.IgControl)
        frames.setdefault(packets[0].host_frame, []).extend(packets[1:])
    assert sorted(frames) == list(range(FRAMES))
    last = frames[FRAMES - 1]
    entities = [p for p in last if isinstance(p, cigi.EntityControl)]
    assert {e.entity_id: e.entity_type for e in entities} == by_entity
    figure = next(f for f in parts["figures"] if f["entity_type"] == entities[0].entity_type)
    dof_parts = {p["part_id"] for p in figure["parts"] if "joint" in p}
    one = entities[0].entity_id
    shorts = [p for p in last if isinstance(p, cigi.ShortArticulatedPart) and p.entity_id == one]
    sent_parts = {p.part1 for p in shorts} | {p.part2 for p in shorts if p.enable2}
    assert sent_parts == dof_parts == set(range(1, len(dof_parts) + 1))
    root = next(
        p for p in last if isinstance(p, cigi.ArticulatedPart) and p.entity_id == one and p.part_id == 0
    )
    assert root.z is not None and root.z < -0.3  # the pelvis above the feet (z down)


def test_soldiers_are_placed_about_the_origin() -> None:
    messages, _, _ = scene()
    entities = [p for p in cigi.decode_message(messages[-1])[0] if isinstance(p, cigi.EntityControl)]
    for e in entities:
        assert abs(e.x - 52.0) < 1e-3 and abs(e.y - 4.0) < 1e-3 and abs(e.z - 10.0) < 0.01  # 3 m grid


def _pcap(messages: list[bytes], path: Path) -> None:
    with path.open("wb") as f:
        w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
        for k, m in enumerate(messages):
            w.writepkt(udp_frame(m, 0, PORT), ts=k / 30.0)


FIELDS = {  # tshark field -> (our packet type, attribute)
    "cigi.ig_control.host_frame_number": (cigi.IgControl, "host_frame"),
    "cigi.ig_control.minor_version": (cigi.IgControl, None),
    "cigi.entity_control.entity_id": (cigi.EntityControl, "entity_id"),
    "cigi.entity_control.entity_type": (cigi.EntityControl, "entity_type"),
    "cigi.entity_control.lat_xoff": (cigi.EntityControl, "x"),
    "cigi.entity_control.yaw": (cigi.EntityControl, "yaw"),
    "cigi.art_part_control.part_id": (cigi.ArticulatedPart, "part_id"),
    "cigi.art_part_control.zoff": (cigi.ArticulatedPart, "z"),
    "cigi.short_art_part_control.part_id_1": (cigi.ShortArticulatedPart, "part1"),
    "cigi.short_art_part_control.dof_select_1": (cigi.ShortArticulatedPart, "select1"),
    "cigi.short_art_part_control.dof_1": (cigi.ShortArticulatedPart, "value1"),
}


def _ours(packets: list[cigi.Packet], kind: type, attr: str | None) -> list[float]:
    return [
        cigi.MINOR_VERSION if attr is None else float(getattr(p, attr)) for p in packets if type(p) is kind
    ]


@pytest.mark.skipif(shutil.which("tshark") is None, reason="tshark (Wireshark) is not installed")
def test_wireshark_dissects_the_scene_without_a_malformed_packet(tmp_path: Path) -> None:
    messages, _, _ = scene()
    pcap = tmp_path / "cigi.pcap"
    _pcap(messages, pcap)
    base = ["tshark", "-n", "-r", str(pcap), "-d", f"udp.port=={PORT},cigi"]
    verbose = subprocess.run([*base, "-V"], capture_output=True, text=True, timeout=60, check=True).stdout
    assert verbose.count("Common Image Generator Interface (3)") == len(messages)
    assert "Malformed" not in verbose and "Expert Info (Error" not in verbose
    assert verbose.count("Minor Version: 3") == len(messages)
    cmd = [*base, "-T", "fields", "-E", "aggregator=;", "-E", "separator=\t"]
    for name in FIELDS:
        cmd += ["-e", name]
    lines = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=True).stdout.splitlines()
    assert len(lines) == len(messages)
    compared = dict.fromkeys(FIELDS, 0)
    for line, message in zip(lines, messages, strict=True):
        packets, _ = cigi.decode_message(message)
        for text, (name, (kind, attr)) in zip(line.split("\t"), FIELDS.items(), strict=True):
            theirs = [float(v) for v in text.split(";") if v]
            assert theirs == pytest.approx(_ours(packets, kind, attr), rel=1e-5, abs=1e-5), name
            compared[name] += len(theirs)
    assert min(compared.values()) >= SOLDIERS  # every field was dissected and compared, many times
