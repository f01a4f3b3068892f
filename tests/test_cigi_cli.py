"""`ttes cigi` from the command line: its exit codes, and a short run into a UDP socket with its part map."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from protocol import cigi
from ttes.cli import main


@pytest.mark.parametrize(
    "bad", [["--ig", "no port"], ["--ig", "127.0.0.1:99999"], ["--fps", "0"], ["--soldiers", "0"]]
)
def test_bad_arguments_exit_2(bad: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["cigi", *bad])
    assert exc.value.code == 2


def test_bad_origin_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["cigi", "--origin", "north", "--frames", "1"]) == 2
    assert "--origin" in capsys.readouterr().err


def test_no_server_exits_1(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        free = s.getsockname()[1]  # closed again: nothing listens there
    assert main(["cigi", "--port", str(free), "--frames", "1", "--map", str(tmp_path / "m.json")]) == 1
    assert "cannot connect" in capsys.readouterr().err


def test_a_short_run_sends_frames_and_writes_the_part_map(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as ig:
        ig.bind(("127.0.0.1", 0))
        ig.setblocking(False)
        port = ig.getsockname()[1]
        parts = tmp_path / "parts.json"
        args = [
            "cigi",
            "--with-server",
            "--synthetic-server",
            "--soldiers",
            "3",
            "--frames",
            "4",
            "--fps",
            "50",
        ]
        assert main([*args, "--ig", f"127.0.0.1:{port}", "--map", str(parts), "--json"]) == 0
        summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        got = []
        while True:
            try:
                got.append(ig.recv(65535))
            except BlockingIOError:
                break
    assert summary["frames"] == 4 and summary["datagrams"] == len(got) >= 4
    frames = {cigi.decode_message(m)[0][0].host_frame for m in got}
    assert frames == {0, 1, 2, 3}
    figures = json.loads(parts.read_text())["figures"]
    assert figures and all(f["parts"][0]["part_id"] == 0 for f in figures)
