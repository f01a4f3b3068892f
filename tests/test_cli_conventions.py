"""The `ttes` conventions as a user meets them, in real processes (issue 19): exit 1 for a runtime error and 2
for a usage error, values named in the message, ranges validated while parsing, `--version`, a taken port
found before the data loads, valid names listed, no Python reprs in human output, one log format."""

from __future__ import annotations

import io
import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from test_server_support import synthetic_dir

from client_stub.dis.drive import ProgressLine
from ttes.commands.author import print_check_table
from ttes.commands.loadtest import format_result
from ttes.progress import ENV, ProgressBar

REPO = Path(__file__).resolve().parents[1]
GRAPH = REPO / "posture_graphs" / "soldier_low.graph"
LOG_LINE = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z level=\w+ event=\S+")
REPRS = ("{'", "['", "[[", "None", "True", "False")


def ttes(
    *args: str, cwd: Path = REPO, timeout: float = 120.0, progress: bool = False
) -> subprocess.CompletedProcess[str]:
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "PYTHONUNBUFFERED": "1",
        "TTES_PROGRESS": "1" if progress else "0",
    }
    cmd = [sys.executable, "-m", "ttes", *args]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout, check=False)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_version_and_the_exit_statuses_in_help() -> None:
    r = ttes("--version")
    assert r.returncode == 0 and re.match(r"ttes \(jack-ttes\) \S+, protocol \d+$", r.stdout.strip()), r
    r = ttes("--help")
    assert r.returncode == 0
    assert "exit status" in r.stdout and "  1    " in r.stdout and "  2    usage" in r.stdout


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["ping", "--port", "99999"], "--port: 99999 is outside 1..65535"),
        (["ping", "--port", "0"], "--port: 0 is outside 1..65535"),
        (["ping", "--port", "seven"], "--port: 'seven' is not a whole number"),
        (["ping", "--host", "no such host"], "--host: 'no such host' is not an IP address or a host name"),
        (["ping", "--timeout", "-1"], "--timeout: -1 must be > 0"),
        (["server", "--port", "65536"], "--port: 65536 is outside 0..65535"),
        (["stub", "--port", "70000"], "--port: 70000 is outside 1..65535"),
        (["stub", "--size", "big"], "--size: 'big' is not WIDTHxHEIGHT"),
        (["stub", "--headless", "--out", "x.jpg"], "--out: x.jpg: cannot write .jpg; use .mp4"),
        (["stub", "--fps", "0"], "--fps: 0 is outside [1, 120]"),
        (["loadtest", "--port", "-5"], "--port: -5 is outside 1..65535"),
        (["loadtest", "--soldiers", "0"], "--soldiers: 0 must be >= 1"),
        (["gateway", "--dis-port", "70000"], "--dis-port: 70000 is outside 0..65535"),
        (["gateway", "--interface", "eth 0"], "--interface: 'eth 0' is not an IP address or a host name"),
        (["replay", "x.pcap", "--port", "99999"], "--port: 99999 is outside 1..65535"),
        (["replay", "x.pcap", "--out", "x.txt", "--headless"], "--out: x.txt: cannot write .txt"),
        (["crowd", "--size", "8x8"], "--size: 8x8 is outside 16x16..8192x8192"),
        (["dis", "info", "x.pcap", "--port", "99999"], "--port: 99999 is outside 1..65535"),
        (["author", "contact-sheet", "--out", "x.png", "--tile", "8"], "--tile: 8 must be >= 32"),
        (["web", "--port", "99999"], "--port: 99999 is outside 0..65535"),
        (["web", "--server", "nowhere"], "--server"),
        (["server", "--ws-port", "70000"], "--ws-port: 70000 is outside 0..65535"),
    ],
)
def test_a_bad_value_is_a_usage_error_naming_it(args: list[str], named: str) -> None:
    r = ttes(*args)
    assert r.returncode == 2 and named in r.stderr and "usage: ttes" in r.stderr, r.stderr


def test_options_that_do_not_go_together_are_usage_errors() -> None:
    r = ttes("loadtest", "--soldiers", "2", "--clients", "3")
    assert r.returncode == 2 and "more clients than soldiers" in r.stderr
    r = ttes("server", "--throttle", "0.5", "--tick-hz", "100000")
    assert r.returncode == 2 and "tick_hz" in r.stderr
    r = ttes("web", "--with-server", "--server", "127.0.0.1:7001")
    assert r.returncode == 2 and "--with-server or --server" in r.stderr
    r = ttes("front", "--shards", "1", "--front", "0/300", "--port", "0")
    assert r.returncode == 2 and "--front 0/300: at most 255 front-ends" in r.stderr
    r = ttes("front", "--shards", "1", "--fabric-domain", "3", "--port", "0")  # Zenoh has no domains
    assert r.returncode == 2 and "--fabric-domain 3: a DDS domain, and --fabric is zenoh" in r.stderr
    r = ttes("server", "--shard", "0/2", "--fabric", "dds", "--fabric-domain", "233", "--port", "0")
    assert r.returncode == 2 and "233 is outside 0..232" in r.stderr


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["figure", "info", "missing.fig"], "missing.fig"),
        (["channelset", "info", "missing.chset.env"], "missing.chset.env"),
        (["graph", "info", "missing.graph"], "missing.graph"),
        (["dis", "info", "missing.pcap"], "missing.pcap"),
        (["replay", "missing.pcap", "--no-stub"], "missing.pcap"),
    ],
)
def test_a_file_that_cannot_be_read_is_a_runtime_error_naming_it(
    args: list[str], named: str, tmp_path: Path
) -> None:
    r = ttes(*args, cwd=tmp_path)
    assert r.returncode == 1 and named in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_no_server_is_a_runtime_error_naming_the_address() -> None:
    port = _free_port()
    r = ttes("ping", "--port", str(port), "--timeout", "1")
    assert r.returncode == 1 and f"127.0.0.1:{port}" in r.stderr


def test_a_port_in_use_fails_before_the_data_loads_and_names_the_address() -> None:
    data = synthetic_dir().path
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        r = ttes("server", "--port", str(port), "--data-dir", str(data))
    assert r.returncode == 1, r.stderr
    assert f"cannot listen on 127.0.0.1:{port}: Address already in use" in r.stderr
    # the server logs each step of its start-up: none ran (it used to load everything first)
    assert "environment_read" not in r.stderr and "startup_done" not in r.stderr


def test_graph_path_lists_the_valid_postures() -> None:
    r = ttes("graph", "path", str(GRAPH), "stand", "prone")
    assert r.returncode == 2
    assert "unknown posture 'stand' (did you mean STAND_STOWED or STAND_FIRE?)" in r.stderr
    assert "its postures: STAND_STOWED, STAND_FIRE, KNEEL_STOWED" in r.stderr


def test_author_help_has_no_development_note() -> None:
    r = ttes("author", "--help")
    assert r.returncode == 0
    assert "join it as" not in r.stdout and "AUTHOR_STEPS" not in r.stdout
    for step in ("figures", "build", "check", "contact-sheet"):
        assert step in r.stdout


def test_headless_stub_needs_an_out_file(tmp_path: Path) -> None:
    r = ttes("stub", "--headless", "--seconds", "1", cwd=tmp_path)
    assert r.returncode == 2 and "--headless needs --out FILE" in r.stderr and ".png" in r.stderr
    assert not list(tmp_path.iterdir())  # it used to write ./ttes-stub.mp4 unasked


def test_human_output_has_no_python_reprs(tmp_path: Path) -> None:
    pcap = tmp_path / "squad.pcap"
    readme = tmp_path / "notes.txt"
    readme.write_text("# not a DIS log\n" * 40)
    runs = [
        ttes("dis", "synth", "--out", str(pcap), "--seconds", "20"),
        ttes("dis", "info", str(pcap)),
        ttes("figure", "info", str(REPO / "figures" / "DI.fig")),
        ttes("graph", "info", str(GRAPH)),
        ttes("graph", "path", str(GRAPH), "STAND_STOWED", "PRONE_STOWED"),
        ttes("demo", "--figures-only"),
        ttes("replay", str(readme), "--no-stub"),
    ]
    for r in runs:
        text = r.stdout + r.stderr
        assert not [x for x in REPRS if x in text], f"{r.args[3:]}:\n{text}"
    assert "pdu_types: entity_state:" in runs[1].stdout and "victim 1:2:2 at" in runs[0].stdout


def test_every_process_logs_in_the_servers_format(tmp_path: Path) -> None:
    """A client's logger (the stub's) and the server's write the same key=value lines, values plain."""
    script = (
        "import logging, sys\n"
        "from ttes.cli import configure_logging\n"
        "from server.logging import configure, get_logger\n"
        "configure_logging(0)\n"
        "logging.getLogger('ttes.stub').warning('server lost: %s', 'reset')\n"
        "configure()\n"
        "get_logger('world').info('motion_library_bound', figure_sets=[['DI.fig', 'AK_47.fig']], walk=True,\n"
        "                         modes={'idle': 10}, last=None)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    lines = r.stderr.splitlines()
    assert len(lines) == 2 and all(LOG_LINE.match(x) for x in lines), lines
    assert lines[0].endswith('level=warning event="server lost: reset" src=ttes.stub')
    assert lines[1].endswith(
        "event=motion_library_bound figure_sets=DI.fig+AK_47.fig walk=true modes=idle:10 last=none"
    )


# -- progress: totals and ETA on stderr, never in --json stdout ------------------------------------------
def test_headless_stub_progress_goes_to_stderr_with_its_total(tmp_path: Path) -> None:
    out = tmp_path / "last.png"
    r = ttes("stub", "--headless", "--seconds", "1", "--fps", "5", "--size", "64x48", "--out", str(out),
             "--artic-dir", str(tmp_path), "--no-tour", "--json", cwd=tmp_path, progress=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["frames"] == 5  # stdout: the one JSON object
    bars = r.stderr.replace("\r", "\n")
    assert "ttes stub: 100%" in bars and "| 1.0/1.0 s [" in bars


def test_loadtest_progress_names_its_stage_and_total(tmp_path: Path) -> None:
    r = ttes("loadtest", "--spawn-server", "--server-data", "synthetic", "--soldiers", "2", "--clients", "1",
             "--seconds", "0.5", "--warmup", "0.2", "--json", cwd=tmp_path, progress=True)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["soldiers"] == 2
    assert "ttes loadtest N=2: 100%|" in r.stderr.replace("\r", "\n") and "| 0.7/0.7 s [" in r.stderr
    assert "ttes loadtest server loading: 0.0 s" in r.stderr.replace("\r", "\n")  # the spawned server's wait


def test_progress_bar_restarts_per_stage_and_is_off_without_a_terminal(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(ENV, raising=False)
    with ProgressBar("job") as quiet:  # stderr is captured: no terminal, no bar
        quiet(1.0, 2.0)
    assert capsys.readouterr().err == ""
    with ProgressBar("job", enabled=True) as bar:
        bar(1.0, 2.0, "N=10")
        bar(2.0, 2.0, "N=10")
        bar(0.5, 4.0, "N=13")
    err = capsys.readouterr().err.replace("\r", "\n")
    assert "job N=10: 100%" in err and "job N=13:  12%" in err and "| 0.5/4.0 s [" in err


def test_a_wait_of_unknown_length_shows_the_seconds_so_far(capsys: pytest.CaptureFixture[str]) -> None:
    with ProgressBar("ttes server: loading its library", enabled=True) as bar:
        bar.waited(0.0)
        bar.waited(7.5)
        bar(1.0, 2.0, "N=10")  # the job's own stage closes the wait line
        assert bar.wait_bar is None
    err = capsys.readouterr().err.replace("\r", "\n")
    assert "ttes server: loading its library: 0.0 s" in err and "library: 7.5 s" in err
    assert "N=10:  50%" in err


def test_replay_status_lines_give_the_total_and_an_eta() -> None:
    wall = iter([100.0, 104.0, 108.0])  # the wall clock: 4 s for the first 10 s of a 60 s log
    out = io.StringIO()
    line = ProgressLine(out=out, total=60.0, clock=lambda: next(wall))
    line.update(0.0, 0.0, 3, 0)
    line.update(1.0, 10.0, 3, 40)  # 10 s of log in 4 s of wall clock: 50 s more take 20 s
    assert out.getvalue() == "\rreplay    10.0 / 60.0 s |     3 alive |        40 PDU/s | ETA 0:20\n"
    assert ProgressLine(out=None).text(12.0, 1).startswith("replay    12.0 s |")  # looping: no total, no ETA


def test_loadtest_ramp_summary_says_n_a_not_none() -> None:
    stage = dict.fromkeys(("delivered_pct", "updates_per_s", "expected_updates_per_s", "latency_ms_p50",
                           "latency_ms_p99", "delivery_ms_p99", "server_cpu_pct"))  # fmt: skip
    result = {
        "ramp": True,
        "clients": 2,
        "rate_hz": 30.0,
        "criteria": {"min_delivered_pct": 99.0, "max_p99_ms": 33.0, "latency_metric": "request"},
        "largest_sustained_soldiers": None,
        "first_failed_soldiers": 100,
        "stages": [{**stage, "soldiers": 100, "passed": False}],
    }
    text = format_result(result)
    assert not [x for x in REPRS if x in text], text
    assert "criteria: delivered >= 99%, p99 request latency <= 33 ms" in text
    assert "no N sustained: the first stage (N=100) failed" in text
    assert "delivered n/a" in text and "FAIL" in text


def test_author_check_table_shows_ranges_and_unmeasured_values_plainly(
    capsys: pytest.CaptureFixture[str],
) -> None:
    clip = {"name": "walk_cycle", "pass": False, "gait": "walk", "failures": ["gait_speed_m_s"],
            "gait_speed_m_s": 1.9, "foot_skate_cm": None}  # fmt: skip
    summary = {
        "clips": 1,
        "clips_failing": 1,
        "postures_checked": 0,
        "thresholds": {
            "gait_speed_m_s": {
                "limit": (1.2, 1.6),
                "worst": 1.9,
                "where": "walk_cycle",
                "failing": 1,
                "pass": False,
            },
            "foot_skate_cm": {"limit": 2.0, "worst": None, "where": None, "failing": 0, "pass": True},
        },
    }
    print_check_table({"clips": [clip], "continuity": [], "summary": summary})
    text = capsys.readouterr().out
    assert not [x for x in REPRS if x in text] and "(1.2" not in text, text
    assert "gait_speed_m_s = 1.9 (limit 1.2..1.6)" in text and "foot_skate_cm: worst - (limit 2.0)" in text


def test_demo_json_is_one_object_with_the_figures_the_stub_and_the_last_frame(tmp_path: Path) -> None:
    """`--json` is machine output: the demo printed two JSON documents (the figures, then the stub's)."""
    r = ttes("demo", "--seconds", "1", "--out-dir", str(tmp_path), "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)  # one document
    assert {f["file"] for f in out["figures"]} >= {"DI.fig", "soldier.fig"}
    # with a server the frames follow the wall clock (headless.py): a loaded machine renders fewer, never more
    assert 1 <= out["stub"]["frames"] <= 10 and out["stub"]["server"] is True
    assert out["png"] == str(tmp_path / "demo.png") and (tmp_path / "demo.png").stat().st_size > 0
