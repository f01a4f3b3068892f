"""TickUpdate (Jack cm, +Y up) → the protocol's JointUpdates (Performer m, +Z up) and the update table."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from protocol import coords
from protocol.entity import Appearance, make_entity_requests
from protocol.updates import UpdateDecoder, UpdateEncoder
from server.soldier.manager import SoldierManager, TickUpdate
from server.soldier.synthetic import synthetic_motion_library
from server.soldier.wire import WireConverter, to_joint_updates, update_table_for

FIGURES = Path(__file__).resolve().parents[1] / "figures"


@pytest.fixture(scope="module")
def real_lib():
    from peabody.loader import read_figure

    if not (FIGURES / "DI.fig").is_file():
        pytest.skip("figures/DI.fig not present")
    figs = [
        read_figure(FIGURES / "DI.fig", load_psurfs=False),
        read_figure(FIGURES / "AK_47.fig", load_psurfs=False),
    ]
    return synthetic_motion_library([figs])


def test_update_table_has_di_fig_shape(real_lib) -> None:
    table = update_table_for(real_lib, 3)
    assert (table.table_id, table.figure, table.weapon) == (3, "DI.fig", "AK_47.fig")
    assert table.ndofs == 50 and table.nfigures == 2 and len(table.entries) == 25
    assert [e.name for e in table.entries[-2:]] == ["soldier", "rifle"]
    spine = next(e for e in table.entries if e.name == "spine_compression")
    assert spine.dofs[0].kind == "T" and (spine.dofs[0].lo, spine.dofs[0].hi) == (-0.03, 0.01)
    waist = next(e for e in table.entries if e.name == "waist")
    assert waist.dofs[0].lo == -math.pi and waist.dofs[0].bits == 12


def test_conversion_units_axes_and_round_trip(real_lib) -> None:
    m = SoldierManager(real_lib)
    idx = [m.create_soldier() for _ in range(3)]
    rows = make_entity_requests(
        idx, [Appearance.UPRIGHT, Appearance.KNEEL, Appearance.PRONE], velocity=(0, 0, 0)
    )
    rows["velocity"][0] = (0.0, 1.4, 0.0)
    m.apply_requests(rows, 0.0)
    upd = m.tick(0.7)
    table = update_table_for(real_lib, 1)
    conv = WireConverter(real_lib, table)
    ju = conv.convert(upd)
    assert ju.table == 1 and ju.tick == upd.tick and ju.indices.tolist() == idx
    kinds = np.array([d.kind for e in table.entries if hasattr(e, "dofs") for d in e.dofs])
    np.testing.assert_allclose(ju.dofs[:, kinds == "T"], upd.joints[:, kinds == "T"] / 100.0, rtol=1e-6)
    np.testing.assert_allclose(ju.dofs[:, kinds == "R"], upd.joints[:, kinds == "R"], atol=1e-6)
    np.testing.assert_allclose(ju.positions, coords.points_jack_to_performer(upd.figures[..., :3]), atol=1e-9)
    np.testing.assert_allclose(
        ju.orientations, coords.quats_jack_to_performer(upd.figures[..., 3:]), atol=1e-9
    )
    assert (ju.positions[:, 0, 2] > 0.05).all()  # the pelvis is above the feet: Performer +Z up
    payloads = UpdateEncoder(table).encode(ju, 1 << 16)
    dec = UpdateDecoder(table)
    back = [dec.decode(p) for p in payloads]
    np.testing.assert_allclose(back[0].dofs, ju.dofs, atol=0.002)
    np.testing.assert_allclose(back[0].positions, ju.positions, atol=0.0006)
    same = to_joint_updates(upd, real_lib, table)
    np.testing.assert_array_equal(same.dofs, ju.dofs)


def test_angles_are_wrapped_and_shapes_checked() -> None:
    lib = synthetic_motion_library()
    table = update_table_for(lib, 1)
    conv = WireConverter(lib, table)
    joints = np.zeros((1, lib.ndof), np.float32)
    joints[0, :3] = [3.5, -3.5, 7.0]
    figs = np.zeros((1, lib.nfig, 7), np.float32)
    figs[..., 3] = 1.0
    ju = conv.convert(TickUpdate(np.array([0]), joints, figs, np.array([False])))
    np.testing.assert_allclose(
        ju.dofs[0, :3], [3.5 - 2 * math.pi, 2 * math.pi - 3.5, 7.0 - 2 * math.pi], atol=1e-6
    )
    with pytest.raises(ValueError, match="DOFs"):
        WireConverter(lib, update_table_for(synthetic_motion_library(ndof=40), 2))
