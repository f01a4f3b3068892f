"""`ttes replay` and `ttes gateway` on the command line (real clock; private server, synthetic data dir)."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

import pytest
from test_replay_support import exercise
from test_server_support import synthetic_dir

from protocol.dis.synth import write_pcap
from ttes.cli import main


@pytest.fixture(scope="module")
def squad_pcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "squad.pcap"
    write_pcap(path, exercise())
    return path


def run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict, str]:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    return rc, json.loads(lines[-1]) if lines else {}, err


def test_replay_no_stub_unlimited_into_a_private_server(
    capsys: pytest.CaptureFixture[str], squad_pcap: Path
) -> None:
    data = str(synthetic_dir().path)
    rc, summary, _ = run_json(capsys, "replay", str(squad_pcap), "--no-stub", "--speed", "0", "--json",
                              "--data-dir", data)  # fmt: skip
    assert rc == 0
    assert summary["created"] == 4 and summary["finished"] and summary["server_errors"] == 0
    assert summary["pdus"] == len(exercise().packets) and summary["sink_removed"] == 4
    rc, summary, _ = run_json(capsys, "replay", str(squad_pcap), "--no-stub", "--speed", "0", "--json",
                              "--data-dir", data, "--entities", "opposing", "--start", "10")  # fmt: skip
    assert rc == 0 and summary["created"] == 2


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--entities", "force=x"], "entity filter, character 0"),
        (["--origin", "north"], "--origin must be LAT,LON,H"),
        (["--start", "-1"], "--start must be >= 0"),
        (["--offline", "--no-stub"], "would do nothing"),
    ],
)
def test_replay_argument_errors(
    capsys: pytest.CaptureFixture[str], squad_pcap: Path, args: list[str], message: str
) -> None:
    assert main(["replay", str(squad_pcap), *args]) == 2
    assert message in capsys.readouterr().err


def test_replay_of_a_log_without_soldiers(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    empty = tmp_path / "empty.raw"
    empty.write_bytes(b"")
    assert main(["replay", str(empty), "--no-stub"]) == 1
    assert "no lifeform Entity State PDUs" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "missing.pcap"), "--no-stub"]) == 1  # runtime: the file


def test_headless_offline_frame(capsys: pytest.CaptureFixture[str], squad_pcap: Path, tmp_path: Path) -> None:
    """One offline frame rendered offscreen: the soldiers are in the stub (skipped where EGL is missing)."""
    pytest.importorskip("pyrender")
    out = tmp_path / "frame.png"
    try:
        rc, summary, err = run_json(capsys, "replay", str(squad_pcap), "--offline", "--headless",
                                    "--start", "20", "--seconds", "0.2", "--fps", "5", "--size", "160x120",
                                    "--out", str(out), "--json")  # fmt: skip
    except Exception as exc:  # no EGL / OpenGL on this machine
        pytest.skip(f"offscreen rendering unavailable: {exc!r}")
    assert rc == 0, err
    assert out.exists() and summary["frames"] == 1 and summary["alive"] == 4 and not summary["server"]


def test_gateway_command_hears_udp_and_cleans_up(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    packets = [p.payload for p in exercise().packets[:40]]
    stop = threading.Event()

    def send() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            while not stop.is_set():
                for data in packets:
                    s.sendto(data, ("127.0.0.1", port))
                s.sendto(b"\x07garbage", ("127.0.0.1", port))
                time.sleep(0.05)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        rc, summary, _ = run_json(capsys, "gateway", "--with-server", "--data-dir", str(synthetic_dir().path),
                                  "--dis-port", str(port), "--seconds", "2", "--status-every", "0",
                                  "--json")  # fmt: skip
    finally:
        stop.set()
        sender.join(5)
    assert rc == 0
    assert summary["event"] == "summary" and summary["translator_created"] == 4 and summary["alive"] == 0
    assert summary["datagrams"] > 40 and summary["non_dis"] >= 1 and summary["sink_removed"] == 4
    assert summary["server_errors"] == 0
