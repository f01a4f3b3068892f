"""Lifeform appearance bits, the TTES posture / weapon tokens, and the entity-type tables."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.dis import (
    DisError,
    EntityStatePdu,
    EntityType,
    Health,
    LifeformAppearance,
    LifeformState,
    LocalFrame,
    TtesPosture,
    TtesWeapon,
    WeaponState,
    decode_appearance,
    encode_appearance,
    is_lifeform,
    rifle_code,
    rifle_figure,
    translate,
    ttes_posture,
    ttes_weapon,
)
from protocol.dis.appearance import POSTURE_NAMES, TTES_POSTURE_OF_STATE
from protocol.dis.batch import batch_from_pdus
from protocol.dis.entity_type import RIFLE_AK, RIFLE_M16
from protocol.dis.geo import orientation_from_heading

u32 = st.integers(min_value=0, max_value=0xFFFFFFFF)


@given(u32)
def test_scalar_round_trip_every_word(word: int) -> None:
    assert LifeformAppearance.decode(word).encode() == word


@given(st.lists(u32, min_size=1, max_size=50))
def test_vectorised_round_trip_and_agreement_with_scalar(words: list[int]) -> None:
    fields = decode_appearance(words)
    assert encode_appearance(**fields).tolist() == words
    for k, w in enumerate(words):
        a = LifeformAppearance.decode(w)
        assert (a.health, a.state, a.weapon1, a.weapon2) == (
            fields["health"][k],
            fields["state"][k],
            fields["weapon1"][k],
            fields["weapon2"][k],
        )
        assert (a.frozen, a.deactivated, a.camouflage) == (
            fields["frozen"][k],
            fields["deactivated"][k],
            fields["camouflage"][k],
        )


@given(
    st.sampled_from(list(Health)),
    st.sampled_from(list(LifeformState)),
    st.sampled_from(list(WeaponState)),
    st.sampled_from(list(WeaponState)),
    st.booleans(),
    st.booleans(),
    st.integers(0, 3),
)
def test_fields_round_trip(health, state, w1, w2, frozen, deactivated, camo) -> None:
    a = LifeformAppearance(health, state, w1, w2, frozen, deactivated, camo)
    assert LifeformAppearance.decode(a.encode()) == a


def test_bit_positions() -> None:
    assert encode_appearance(health=3, state=0) == 3 << 3
    assert encode_appearance(state=LifeformState.CRAWLING) == 6 << 16
    assert encode_appearance(state=0, frozen=True) == 1 << 21
    assert encode_appearance(state=0, deactivated=True) == 1 << 23
    assert encode_appearance(state=0, weapon1=WeaponState.FIRING) == 3 << 24
    assert encode_appearance(state=0, weapon2=WeaponState.STOWED) == 1 << 26
    assert encode_appearance(state=0, camouflage=2) == 2 << 28
    a = LifeformAppearance.decode(0x02010000)  # the sample soldier: upright standing, weapon deployed
    assert (a.state, a.weapon1, a.health) == (
        LifeformState.UPRIGHT_STANDING,
        WeaponState.DEPLOYED,
        Health.NO_INJURY,
    )


def test_encode_rejects_out_of_range_fields() -> None:
    with pytest.raises(DisError):
        encode_appearance(state=16)
    with pytest.raises(DisError):
        encode_appearance(weapon1=[1, 4])
    with pytest.raises(DisError):
        LifeformAppearance.decode(-1)


def test_ttes_posture_table() -> None:
    expect = {
        LifeformState.UPRIGHT_STANDING: TtesPosture.STAND,
        LifeformState.UPRIGHT_WALKING: TtesPosture.STAND,
        LifeformState.UPRIGHT_RUNNING: TtesPosture.STAND,
        LifeformState.KNEELING: TtesPosture.KNEEL,
        LifeformState.PRONE: TtesPosture.PRONE,
        LifeformState.CRAWLING: TtesPosture.CRAWL,
        LifeformState.SITTING: TtesPosture.KNEEL,
        LifeformState.SQUATTING: TtesPosture.KNEEL,
        LifeformState.CROUCHING: TtesPosture.KNEEL,
        LifeformState.SWIMMING: TtesPosture.PRONE,
    }
    words = encode_appearance(state=list(expect))
    assert ttes_posture(words).tolist() == [int(v) for v in expect.values()]
    assert set(TTES_POSTURE_OF_STATE) == set(LifeformState)  # every state has a posture
    assert POSTURE_NAMES[LifeformState.SURRENDER] == "surrender"


def test_fatal_or_deactivated_is_dead_whatever_the_state() -> None:
    states = np.arange(16)
    assert (ttes_posture(encode_appearance(state=states, health=Health.FATAL)) == TtesPosture.DEAD).all()
    assert (ttes_posture(encode_appearance(state=states, deactivated=True)) == TtesPosture.DEAD).all()
    assert not (
        ttes_posture(encode_appearance(state=states, health=Health.MODERATE)) == TtesPosture.DEAD
    ).any()
    assert LifeformAppearance(health=Health.FATAL).ttes_posture == TtesPosture.DEAD


def test_ttes_weapon_tokens() -> None:
    words = encode_appearance(weapon1=[0, 1, 2, 3], weapon2=3)
    assert ttes_weapon(words).tolist() == [
        TtesWeapon.STOWED,
        TtesWeapon.STOWED,
        TtesWeapon.DEPLOYED,
        TtesWeapon.FIRING,
    ]


def test_lifeform_filter() -> None:
    assert is_lifeform([3, 3, 1, 3], [1, 2, 1, 1]).tolist() == [True, False, False, True]


@pytest.mark.parametrize(
    ("etype", "figure"),
    [
        ((3, 1, 222, 1, 206, 1, 0), "AK_47.fig"),  # old scheme: AK-74
        ((3, 1, 222, 1, 205, 0, 0), "AK_47.fig"),  # old scheme: AK / AKM
        ((3, 1, 222, 1, 217, 0, 0), "AK_47.fig"),  # RPK-74
        ((3, 1, 225, 1, 32, 0, 0), "M16.fig"),  # old scheme: M16A2
        ((3, 1, 225, 1, 41, 0, 0), "M16.fig"),  # M4
        ((3, 1, 225, 1, 52, 0, 0), "M16.fig"),  # M60: no model, default
        ((3, 1, 222, 11, 5, 112, 0), "AK_47.fig"),  # new scheme: army, assault rifles, AK-47
        ((3, 1, 222, 102, 5, 10, 0), "AK_47.fig"),  # insurgent with an AK-74
        ((3, 1, 225, 12, 5, 42, 0), "M16.fig"),  # naval infantry, M4
        ((3, 1, 225, 12, 5, 35, 0), "M16.fig"),  # G36: default
        ((3, 1, 225, 11, 206, 0, 0), "M16.fig"),  # new scheme, subcategory is no weapon: default
    ],
)
def test_rifle_table(etype: tuple[int, ...], figure: str) -> None:
    assert rifle_figure(etype) == figure


def test_rifle_code_vectorised() -> None:
    codes = rifle_code([1, 1, 11, 12], [206, 32, 5, 5], [1, 0, 113, 40])
    assert codes.tolist() == [RIFLE_AK, RIFLE_M16, RIFLE_AK, RIFLE_M16]


def test_translate_builds_tokens_in_the_local_frame() -> None:
    frame = LocalFrame(38.52, -77.44, 60.0)
    enu = np.array([[0.0, 0.0, 0.0], [10.0, 5.0, 0.0]])
    ecef = frame.to_ecef(enu)
    ori = orientation_from_heading(ecef, [90.0, 180.0])
    vel = frame.vector_to_ecef([[1.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    pdus = [
        EntityStatePdu(
            entity_type=EntityType(3, 1, 225, 12, 5, 41, 0),
            location=tuple(ecef[0]),
            orientation=tuple(ori[0]),
            velocity=tuple(vel[0]),
            appearance=int(encode_appearance(state=2, weapon1=2)),
        ),
        EntityStatePdu(
            entity_type=EntityType(3, 1, 222, 1, 205, 0, 0),
            location=tuple(ecef[1]),
            orientation=tuple(ori[1]),
            appearance=int(encode_appearance(state=5, weapon1=3, health=3)),
        ),
    ]
    tokens, used = translate(batch_from_pdus(pdus), np.array([0.0, 1.0]), frame)
    assert used == frame
    np.testing.assert_allclose(tokens["position"], enu, atol=1e-6)
    np.testing.assert_allclose(tokens["heading"], [90.0, 180.0], atol=1e-4)
    np.testing.assert_allclose(tokens["speed"], [1.5, 0.0], atol=1e-6)
    assert tokens["posture"].tolist() == [TtesPosture.STAND, TtesPosture.DEAD]
    assert tokens["weapon"].tolist() == [TtesWeapon.DEPLOYED, TtesWeapon.FIRING]
    assert tokens["rifle"].tolist() == [RIFLE_M16, RIFLE_AK]
    # default frame: the first entity sits at the origin
    tokens2, frame2 = translate(batch_from_pdus(pdus), np.array([0.0, 1.0]))
    np.testing.assert_allclose(tokens2["position"][0], 0.0, atol=1e-6)
    assert frame2 is not None and frame2.lat == pytest.approx(38.52, abs=1e-9)
