"""The JCL whitelist interpreter.

The seed's start-up script parses, paths stay in the data dir, junk gets a located error.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from server.jcl import JclError, JclInterpreter, parse_jcl

SEED_SCRIPT = """\
read_file("jack-ttes-soldier_low.env");
create_soldier_state("s0","Di2_0","AK_47_0");
create_soldier_state("s1","Di2_1","AK_47_1");
set_channelset_parameters("no");
set_ttes_report_interval(10.00);
set_ttes_heading_offset(256.00,0.00,256.00);
set_ttes_soldier_throttle(0.04);
/* a comment */ set_ttes_report_interval(30.00); // trailing
start_ttes_socket_simulation();
disable_graphics();
"""


def test_seed_startup_script_parses() -> None:
    calls = parse_jcl(SEED_SCRIPT, "jack-ttes-soldier_low.jcl")
    assert [c.name for c in calls] == [
        "read_file",
        "create_soldier_state",
        "create_soldier_state",
        "set_channelset_parameters",
        "set_ttes_report_interval",
        "set_ttes_heading_offset",
        "set_ttes_soldier_throttle",
        "set_ttes_report_interval",
        "start_ttes_socket_simulation",
        "disable_graphics",
    ]
    assert calls[1].args == ("s0", "Di2_0", "AK_47_0")
    assert calls[5].args == (256.0, 0.0, 256.0)
    assert calls[8].args == ()
    assert (calls[7].line, calls[7].column) == (8, 17)


def test_single_quotes_and_escapes() -> None:
    (call,) = parse_jcl("read_file('jack-ttes-terrain.jcl');")
    assert call.args == ("jack-ttes-terrain.jcl",)
    (call,) = parse_jcl(r'echo("a \"b\"");')
    assert call.args == ('a "b"',)


@pytest.mark.parametrize(
    ("text", "line", "col"),
    [
        ("foo(1,;", 1, 7),
        ("foo(1) bar(2);", 1, 8),
        ('foo("abc);', 1, 5),
        ("foo(1);\n/* never closed", 2, 1),
        ("foo(1);\n  $x", 2, 3),
        ("foo(", 1, 1),
    ],
)
def test_errors_are_located(text: str, line: int, col: int) -> None:
    with pytest.raises(JclError) as exc:
        parse_jcl(text, "x.jcl")
    assert (exc.value.line, exc.value.column) == (line, col)
    assert str(exc.value).startswith(f"x.jcl:{line}:{col}:")


def test_whitelist_and_argument_types(tmp_path: Path) -> None:
    seen: list[tuple] = []
    jcl = JclInterpreter(tmp_path)
    jcl.register("set_ttes_soldier_throttle", lambda t: seen.append(("throttle", t)), (float,))
    jcl.register("create_soldier_state", lambda *a: seen.append(a), (str, str, str))
    jcl.run_text('set_ttes_soldier_throttle(0.04); create_soldier_state("s0", "Di2_0", "AK_47_0");')
    assert seen == [("throttle", 0.04), ("s0", "Di2_0", "AK_47_0")]
    with pytest.raises(JclError, match="unknown command 'system'"):
        jcl.run_text('system("rm -rf /");')
    with pytest.raises(JclError, match="must be a number"):
        jcl.run_text('set_ttes_soldier_throttle("fast");')
    with pytest.raises(JclError, match="takes 3 arguments"):
        jcl.run_text('create_soldier_state("s0");')


def test_read_file_stays_inside_data_dir(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    (tmp_path / "secret.jcl").write_text("boom();")
    (data / "inner.jcl").write_text("mark(1);")
    (data / "loop.jcl").write_text('read_file("loop.jcl");')
    marks: list[float] = []
    jcl = JclInterpreter(data)
    jcl.register("mark", marks.append, (float,))
    jcl.run_text('read_file("inner.jcl");')
    assert marks == [1.0]
    for bad in ("../secret.jcl", str(tmp_path / "secret.jcl"), "missing.jcl", "inner.exe"):
        with pytest.raises(JclError):
            jcl.run_text(f'read_file("{bad}");')
    with pytest.raises(JclError, match="nested deeper"):
        jcl.run_text('read_file("loop.jcl");')


@given(st.binary(max_size=300))
def test_fuzz_random_bytes_only_raise_jcl_error(data: bytes) -> None:
    try:
        parse_jcl(data.decode("utf-8", errors="replace"))
    except JclError as exc:
        assert exc.line >= 1
        assert exc.column >= 1


@pytest.mark.fuzz
@given(st.data())
def test_fuzz_mutated_script(data: st.DataObject) -> None:
    text = SEED_SCRIPT
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(text)))
        op = data.draw(st.sampled_from(["del", "ins", "dup"]))
        if op == "del":
            text = text[:pos] + text[pos + 1 :]
        elif op == "ins":
            text = text[:pos] + data.draw(st.sampled_from(list("();,\"'/*x0.- \n"))) + text[pos:]
        else:
            text = text[:pos] + text[pos : pos + 8] + text[pos:]
    try:
        calls = parse_jcl(text)
    except JclError as exc:
        assert exc.line >= 1
    else:
        assert all(isinstance(a, str | float) for c in calls for a in c.args)


def test_search_subfolders_are_searched_and_confined(tmp_path: Path) -> None:
    data = tmp_path / "data"
    (data / "posture_graphs").mkdir(parents=True)
    (data / "posture_graphs" / "start.jcl").write_text("mark(2);")
    (data / "start.jcl").write_text("mark(1);")
    (tmp_path / "outside.jcl").write_text("mark(9);")
    marks: list[float] = []
    jcl = JclInterpreter(data, ("posture_graphs",))
    jcl.register("mark", marks.append, (float,))
    jcl.run_text('read_file("start.jcl");')  # the data dir wins over the search folders
    (data / "start.jcl").unlink()
    jcl.run_text('read_file("start.jcl");')  # then found in posture_graphs/
    assert marks == [1.0, 2.0]
    with pytest.raises(JclError, match="outside the data directory"):
        jcl.run_text('read_file("../outside.jcl");')
