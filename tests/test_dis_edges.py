"""DIS as exercises send it (issue 19): non-DIS input, long silences, --start past the end, the synthetic
epoch, the exercise filter, and what the gateway says about loopback."""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import dpkt
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_replay_support import pcap_of

from client_stub.dis import LogCursor, Replayer
from client_stub.dis.cursor import GapSqueeze
from protocol.dis import (
    EntityId,
    EntityStatePdu,
    EntityType,
    encode_appearance,
    encode_entity_state,
    read_bytes,
)
from protocol.dis.synth import EPOCH, synthesize, udp_frame
from ttes.cli import main
from ttes.commands.gateway import listening_line

REPO = Path(__file__).resolve().parent.parent
SOLDIER = EntityType(3, 1, 225, 1, 27, 0, 0)


def espdu(entity: int, exercise: int = 1) -> bytes:
    return encode_entity_state(
        EntityStatePdu(
            entity_id=EntityId(1, 1, entity),
            entity_type=SOLDIER,
            appearance=int(encode_appearance(state=1, weapon1=2)),
            location=(1.1e6, -4.8e6, 4.0e6),
            exercise=exercise,
        )
    )


FIVE_OVER_813 = [0.0, 1.0, 400.0, 800.0, 813.0]  # five PDUs spanning 813 s: mostly silence


# -- non-DIS input --------------------------------------------------------------------------------
def test_text_and_binary_files_are_not_dis_logs(tmp_path: Path) -> None:
    readme = (REPO / "README.md").read_bytes()
    assert "not a DIS log" in (read_bytes(readme, name="README.md").not_dis() or "")
    junk = np.random.default_rng(1).integers(0, 256, 200_000, dtype=np.uint8).tobytes()
    assert read_bytes(junk).not_dis() is not None  # a few "PDUs" in noise do not make it DIS
    # DIS: a log of soldiers, an empty log, a log of PDUs TTES does not decode (comment PDUs), no problems
    assert read_bytes(pcap_of([(0.0, espdu(1))])).not_dis() is None
    assert read_bytes(b"").not_dis() is None
    comment = bytes([7, 1, 22, 5]) + (0).to_bytes(4, "big") + (20).to_bytes(2, "big") + bytes(10)
    assert read_bytes(comment * 30, fmt="raw").not_dis() is None


def test_cli_rejects_non_dis_input_with_a_message_and_exit_1() -> None:
    """`ttes dis info README.md` and `ttes replay README.md` as a user runs them."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    for argv in (["dis", "info", "README.md"], ["replay", "README.md", "--no-stub"]):
        done = subprocess.run([sys.executable, "-m", "ttes", *argv], cwd=REPO, env=env, capture_output=True,
                              text=True, timeout=120)  # fmt: skip
        assert done.returncode == 1, (argv, done.stderr)
        assert "README.md: not a DIS log" in done.stderr and "{" not in done.stderr
        assert done.stdout == ""


def test_replay_of_a_capture_without_soldiers_says_why_in_words(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "other-port.pcap"
    f = io.BytesIO()
    w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
    w.writepkt(udp_frame(espdu(1), 0, port=3001), ts=1.0)
    path.write_bytes(f.getvalue())
    assert main(["replay", str(path), "--no-stub"]) == 1
    err = capsys.readouterr().err
    assert "no lifeform Entity State PDUs" in err and "--any-port" in err and "{" not in err


# -- silences: --max-gap --------------------------------------------------------------------------
def test_gap_squeeze_cuts_only_the_long_silences() -> None:
    sq = GapSqueeze.of(np.array(FIVE_OVER_813), 5.0)
    np.testing.assert_allclose(sq(np.array(FIVE_OVER_813)), [0.0, 1.0, 6.0, 11.0, 16.0])
    assert sq.skipped == pytest.approx(813.0 - 16.0)
    assert sq(np.array([200.0]))[0] == pytest.approx(6.0)  # inside a cut silence: its end


@given(
    st.lists(st.floats(0, 1e5, allow_nan=False), min_size=1, max_size=40),
    st.floats(0.01, 100.0),
)
def test_gap_squeeze_is_monotone_and_keeps_short_gaps(times: list[float], max_gap: float) -> None:
    t = np.sort(np.array(times))
    sq = GapSqueeze.of(t, max_gap)
    out = sq(t)
    gaps, new = np.diff(t), np.diff(out)
    assert (new >= -1e-9).all() and (new <= max_gap + 1e-6).all()
    np.testing.assert_allclose(new[gaps <= max_gap], gaps[gaps <= max_gap], atol=1e-6)
    assert out[-1] - out[0] == pytest.approx(t[-1] - t[0] - sq.skipped, abs=1e-6)


def test_five_pdus_over_813_s_replay_in_16_s_and_the_summary_says_so() -> None:
    log = read_bytes(pcap_of([(1000.0 + t, espdu(1)) for t in FIVE_OVER_813]))
    r = Replayer(LogCursor(log, max_gap=5.0))
    dues = []
    r.advance(0.0)
    while np.isfinite(r.next_due()):
        dues.append(r.next_due())
        r.advance(dues[-1])
    assert dues == pytest.approx([1.0, 6.0, 11.0, 16.0])
    assert r.status()["silence_skipped_s"] == pytest.approx(797.0)
    assert r.translator.stats["removed_timeout"] == 0  # a 5 s silence is shorter than the DIS timeout
    assert Replayer(log).cursor.duration == pytest.approx(813.0)  # without max_gap: as recorded
    late = Replayer(LogCursor(log, max_gap=5.0), start=800.0)  # --start counts log seconds
    assert late.t_begin - late.cursor.t0 == pytest.approx(11.0)


def test_cli_max_gap_and_start_past_the_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "sparse.pcap"
    path.write_bytes(pcap_of([(1000.0 + t, espdu(1)) for t in FIVE_OVER_813]))
    assert main(["replay", str(path), "--no-stub", "--speed", "0", "--synthetic-server"]) == 0
    out = capsys.readouterr().out
    assert "797.0 s of silence skipped" in out
    assert main(["replay", str(path), "--no-stub", "--start", "999"]) == 2
    err = capsys.readouterr().err
    assert "--start 999 is past the end" in err and "813.0 s long" in err
    with pytest.raises(SystemExit) as bad:
        main(["replay", str(path), "--no-stub", "--max-gap", "-3"])
    assert bad.value.code == 2 and "--max-gap must be" in capsys.readouterr().err


# -- the synthetic exercise's epoch ----------------------------------------------------------------
def test_synthetic_exercises_start_on_the_seed_reports_date() -> None:
    assert datetime.fromtimestamp(EPOCH, UTC) == datetime(1994, 8, 5, 12, 0, tzinfo=UTC)
    ex = synthesize(soldiers=2, seconds=1.0, vehicles=0)
    first = datetime.fromtimestamp(ex.packets[0].t, UTC)
    assert (first.date().isoformat(), first.hour, first.minute) == ("1994-08-05", 12, 0)


# -- the exercise filter ---------------------------------------------------------------------------
def test_exercise_filter_decodes_one_exercise_and_counts_the_others(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = pcap_of([(1.0, espdu(1, exercise=1)), (1.5, espdu(2, exercise=2)), (2.0, espdu(3, exercise=2))])
    every = read_bytes(data)
    assert len(every.batch) == 3 and every.exercises == {1: 1, 2: 2}
    two = read_bytes(data, exercise=2)
    assert two.batch.records["entity_id"]["entity"].tolist() == [2, 3]
    assert two.counters["other_exercise"] == 1 and two.counters["entity_states"] == 2
    path = tmp_path / "two.pcap"
    path.write_bytes(data)
    assert main(["dis", "info", str(path), "--exercise", "1", "--json"]) == 0
    assert '"other_exercise": 2' in capsys.readouterr().out
    assert main(["replay", str(path), "--no-stub", "--exercise", "3"]) == 1
    assert "exercises in the log: 1, 2" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["dis", "info", str(path), "--exercise", "0"])


# -- the gateway on loopback ------------------------------------------------------------------------
def test_gateway_on_loopback_says_how_to_hear_a_lan_exercise(capsys: pytest.CaptureFixture[str]) -> None:
    args = argparse.Namespace(dis_group=None, exercise=None)
    line = listening_line(args, "127.0.0.1", 3000, "127.0.0.1:7000")
    assert "loopback only" in line and "--listen 0.0.0.0" in line
    assert "loopback" not in listening_line(args, "0.0.0.0", 3000, "127.0.0.1:7000")
    with pytest.raises(SystemExit):
        main(["gateway", "--help"])
    help_text = capsys.readouterr().out
    assert "--listen" in help_text and "LAN exercise" in help_text


def test_gateway_exercise_filter() -> None:
    from client_stub.dis.gateway import DisGateway, GatewayConfig

    gw = DisGateway(GatewayConfig(port=0, exercise=2))
    out = gw.handle([espdu(1, exercise=1), espdu(2, exercise=2)], 5.0)
    assert out.created["entity"][:, 2].tolist() == [2]
    assert gw.status["other_exercise"] == 1
