"""The scene's fast packer writes, byte for byte, what the codec writes packet by packet."""

from __future__ import annotations

import numpy as np
import pytest

from peabody import quaternion, rotations
from protocol import cigi, cigi_scene
from protocol.dis.geo import LocalFrame

ORIGIN = LocalFrame(52.0, 4.0, 10.0)


def _group(n: int, kinds: str, nfig: int, seed: int) -> cigi_scene.SoldierGroup:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, nfig, 4))
    return cigi_scene.SoldierGroup(
        np.arange(100, 100 + n), 1001, rng.uniform(-500, 500, (n, 3)), rng.uniform(-720, 720, n),
        rng.uniform(-2, 2, (n, nfig, 3)), q / np.linalg.norm(q, axis=-1, keepdims=True),
        tuple([0] + [len(kinds) + 1 + k for k in range(nfig - 1)]), rng.uniform(-3, 3, (n, len(kinds))),
        tuple(kinds),
    )  # fmt: skip


@pytest.mark.parametrize("n, kinds, nfig", [(1, "R", 1), (3, "RRT" * 5, 2), (10, "R" * 50, 2), (2, "", 1)])
def test_group_bytes_are_the_codecs(n: int, kinds: str, nfig: int) -> None:
    g = _group(n, kinds, nfig, seed=n + len(kinds))
    packets = list(cigi_scene.soldier_packets(g, ORIGIN))
    assert cigi_scene.group_bytes(g, ORIGIN).tobytes() == b"".join(cigi.encode(p) for p in packets)
    shorts = [p for p in packets if isinstance(p, cigi.ShortArticulatedPart)]
    assert len(shorts) == n * ((len(kinds) + 1) // 2)
    assert all(p.yaw is not None for p in packets if isinstance(p, cigi.ArticulatedPart))


def test_messages_hold_whole_soldiers_under_the_size() -> None:
    g = _group(10, "R" * 50, 2, seed=1)
    messages = cigi_scene.frame_messages(7, [g], ORIGIN, max_bytes=1472)
    assert len(messages) == 5 and all(len(m) <= 1472 for m in messages)  # 512-byte soldiers, 2 a message
    ids = [
        p.entity_id for m in messages for p in cigi.decode_message(m)[0] if isinstance(p, cigi.EntityControl)
    ]
    assert ids == list(range(100, 110))


def about(axis: list[float], degrees: float) -> np.ndarray:
    return quaternion.from_matrix(rotations.axis_angle(np.array(axis, float), np.radians(degrees)))


def test_body_euler_of_a_yaw_a_pitch_and_a_roll() -> None:
    """The soldier frame (x right, y forward, z up) read as CIGI's body axes (x forward, y right, z down):
    -45 degrees about +z is 45 degrees of yaw to the right; lying face down is pitch -90."""
    assert cigi_scene.body_euler(about([0, 0, 1], -45)) == pytest.approx([0, 0, 45], abs=1e-9)
    assert cigi_scene.body_euler(about([1, 0, 0], -90)) == pytest.approx([0, -90, 0], abs=1e-6)
    assert cigi_scene.body_euler(about([0, 1, 0], 30)) == pytest.approx([30, 0, 0], abs=1e-9)
