"""`ttes cigi` from the command line: its exit codes, and a short run into a UDP socket with its part map."""

from __future__ import annotations

import json
import socket
import threading
from pathlib import Path

import pytest

from protocol import cigi
from ttes.cli import main


@pytest.mark.parametrize(
    "bad",
    [
        ["--ig", "no port"],
        ["--ig", "127.0.0.1:99999"],
        ["--fps", "0"],
        ["--soldiers", "0"],
        ["--listen", "nowhere"],
    ],
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
        ig_args = ["--ig", f"127.0.0.1:{port}", "--listen", "127.0.0.1:0"]
        assert main([*args, *ig_args, "--map", str(parts), "--json"]) == 0
        summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        got = []
        while True:
            try:
                got.append(ig.recv(65535))
            except BlockingIOError:
                break
    assert summary["frames"] == 4 and summary["datagrams"] == len(got) >= 4
    assert summary["listen"].startswith("127.0.0.1:") and summary["sof_received"] == 0
    frames = {cigi.decode_message(m)[0][0].host_frame for m in got}
    assert frames == {0, 1, 2, 3}
    figures = json.loads(parts.read_text())["figures"]
    assert figures and all(f["parts"][0]["part_id"] == 0 for f in figures)


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _fake_ig(ig: socket.socket, host_port: int) -> None:
    """Answer the host's first message: three Start of Frame (its host frame as the last one read), junk."""
    host_frame = cigi.decode_message(ig.recv(65535))[0][0].host_frame
    for n in range(3):
        sof = cigi.StartOfFrame(500 + n, host_frame)
        ig.sendto(cigi.encode_start_of_frame(sof), ("127.0.0.1", host_port))
    ig.sendto(b"not cigi", ("127.0.0.1", host_port))


def test_the_ig_s_start_of_frames_are_counted(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as ig:
        ig.bind(("127.0.0.1", 0))
        ig.settimeout(60)
        listen = _free_udp_port()
        answer = threading.Thread(target=_fake_ig, args=(ig, listen), daemon=True)
        answer.start()
        args = ["cigi", "--with-server", "--synthetic-server", "--soldiers", "1"]
        args += ["--frames", "11", "--fps", "5"]  # 2 s after frame 0 for three datagrams over loopback
        ig_args = ["--ig", f"127.0.0.1:{ig.getsockname()[1]}", "--listen", f"127.0.0.1:{listen}"]
        assert main([*args, *ig_args, "--map", str(tmp_path / "m.json")]) == 0
        answer.join(10)
    out = capsys.readouterr().out  # the answers came after frame 0, ten frames (2 s) before the end
    said = f"cigi IG: 3 Start of Frame on 127.0.0.1:{listen} (1 malformed), IG frame 502, last host frame 0"
    assert said in out


def test_a_listen_port_in_use_exits_1(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        busy = f"127.0.0.1:{taken.getsockname()[1]}"
        args = ["cigi", "--with-server", "--synthetic-server", "--soldiers", "1", "--frames", "1"]
        assert main([*args, "--listen", busy, "--map", str(tmp_path / "m.json")]) == 1
    assert f"cannot listen on {busy}" in capsys.readouterr().err
