"""The Peabody tokenizer/parser: every construct, locations, errors, fast paths, fuzz."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

import peabody.language as lang
from peabody.language import (
    MAX_DEPTH,
    Assign,
    BinOp,
    Block,
    Call,
    Loc,
    Name,
    Number,
    PeabodyError,
    Statement,
    String,
    Vector,
    parse,
    parse_value,
    strip_locations,
)

DATA = Path(__file__).parent / "data" / "peabody"


def value(text: str) -> object:
    return strip_locations(parse_value(text))


def test_blocks_assignments_and_statements() -> None:
    (fig,) = parse(
        """figure soldier {
             segment lower_torso {
               psurf = "soldier/lower_torso.pss";
               site proximal->location = trans(0cm, 0cm, 0cm);
               site distal { location = trans(0cm, 10.5cm, 0cm); }
             }
             joint waist { connect lower_torso.distal to middle_torso.proximal; }
             root = lower_torso.proximal;
           }""",
        "f.fig",
    )
    assert isinstance(fig, Block) and (fig.keyword, fig.name) == ("figure", "soldier")
    seg, joint, root = fig.body
    assert isinstance(seg, Block) and seg.keyword == "segment" and seg.name == "lower_torso"
    psurf, proximal, distal = seg.body
    assert isinstance(psurf, Assign) and psurf.target == "psurf" and psurf.owner is None
    assert psurf.value == String("soldier/lower_torso.pss", Loc("f.fig", 3, 24))
    assert isinstance(proximal, Assign) and proximal.owner == ("site", "proximal")
    assert proximal.target == "location" and proximal.index is None
    assert isinstance(distal, Block) and distal.keyword == "site" and isinstance(distal.body[0], Assign)
    assert isinstance(joint, Block)
    (connect,) = joint.body
    assert isinstance(connect, Statement) and connect.keyword == "connect"
    assert [a.name for a in connect.args] == ["lower_torso.distal", "to", "middle_torso.proximal"]  # type: ignore[union-attr]
    assert isinstance(root, Assign) and root.value == Name("lower_torso.proximal", Loc("f.fig", 8, 21))


def test_generic_extension_blocks_and_indexed_fields() -> None:
    (cs,) = parse(
        """channelset crawl2prstow.chset {
             size = 48; fps = 60;
             sharedchannel right.toes { /* joint angles */
               type = "sharedjoint";
               frame[0] = (0);
               frame[17] = (0.1, -0.2);
             }
           }"""
    )
    assert isinstance(cs, Block) and cs.keyword == "channelset" and cs.name == "crawl2prstow.chset"
    shared = cs.body[2]
    assert isinstance(shared, Block) and shared.keyword == "sharedchannel" and shared.name == "right.toes"
    f0, f17 = shared.body[1], shared.body[2]
    assert isinstance(f0, Assign) and f0.target == "frame" and f0.index == 0
    assert strip_locations(f0.value) == strip_locations(Vector((Number(0.0, None, f0.loc),), f0.loc))
    assert isinstance(f17, Assign) and f17.index == 17
    assert [n.value for n in f17.value.items] == [0.1, -0.2]  # type: ignore[union-attr]


def test_string_block_names_and_keyword_statements() -> None:
    block, stmt, bare = parse('figure "x" { } include "a.env", "b.env"; reset;')
    assert isinstance(block, Block) and block.name == "x" and block.body == ()
    assert isinstance(stmt, Statement) and [a.value for a in stmt.args] == ["a.env", "b.env"]  # type: ignore[union-attr]
    assert isinstance(bare, Statement) and bare.keyword == "reset" and bare.args == ()


def test_numbers_and_units() -> None:
    assert value("31.68cm") == ("Number", 31.68, "cm")
    assert value("-31.05cm") == ("Number", -31.05, "cm")
    assert value(".5") == ("Number", 0.5, None)
    assert value("1e-3m") == ("Number", 0.001, "m")
    assert value("12") == ("Number", 12.0, None)
    assert value("30deg") == ("Number", 30.0, "deg")
    assert value("2in") == ("Number", 2.0, "in")


def test_strings_names_vectors_calls() -> None:
    assert value(r'"a \"q\" \\ b"') == ("String", 'a "q" \\ b')
    assert value("lower_torso.proximal") == ("Name", "lower_torso.proximal")
    assert value("()") == ("Vector", ())
    assert value("(1, (2))") == ("Vector", (("Number", 1.0, None), ("Vector", (("Number", 2.0, None),))))
    assert value("R(1,0,0)") == ("Call", "R", tuple(("Number", float(v), None) for v in (1, 0, 0)))
    assert value("$") == ("Unsupplied",)


def test_products_and_arithmetic_precedence() -> None:
    tree = parse_value("R(z) * R(y) * R(x)")
    assert isinstance(tree, BinOp) and tree.op == "*" and isinstance(tree.left, BinOp)  # left associative
    assert isinstance(tree.right, Call) and tree.right.args[0] == Name("x", tree.right.args[0].loc)
    t = value("1 + 2 * 3")
    assert t[0] == "BinOp" and t[1] == "+" and t[3][1] == "*"
    t = value("2 ^ 3 ^ 2")
    assert t[1] == "^" and t[3][1] == "^"  # right associative
    assert value("-2^2")[0] == "Neg"  # -(2^2), not (-2)^2
    assert value("-x") == ("Neg", ("Name", "x"))
    assert value("--1")[0] == "Neg"
    psurf = value('"arm.pss" * scale(5.6, 7.3, 30.1)')
    assert psurf[0] == "BinOp" and psurf[2] == ("String", "arm.pss")


def test_comments_everywhere() -> None:
    stmts = parse("/* a */ x = /* b */ 1 // c\n; // d\n y = 2; /* multi\nline */")
    assert [s.target for s in stmts] == ["x", "y"]  # type: ignore[union-attr]
    assert stmts[1].loc == Loc("<string>", 3, 2)


def test_locations_are_one_based_line_and_column() -> None:
    (block,) = parse("\n\n  joint j {\n\tdisplacement = (1deg,\n  2deg);\n}", "j.env")
    assert block.loc == Loc("j.env", 3, 3)
    (a,) = block.body  # type: ignore[union-attr]
    assert a.loc == Loc("j.env", 4, 2)
    second = a.value.items[1]  # type: ignore[union-attr]
    assert second.loc == Loc("j.env", 5, 3)
    assert str(second.loc) == "j.env:5:3"


@pytest.mark.parametrize(
    ("text", "line", "col", "words"),
    [
        ("x = 1;\n/* never closed", 2, 1, "unterminated comment"),
        ('x = "abc;\n', 1, 5, "unterminated string"),
        ("x = 1;\n  y = #;", 2, 7, "unexpected character"),
        ("x = 1\ny = 2;", 2, 1, "expected ';'"),
        ("figure f {\n segment s {\n}", 3, 2, "expected a statement or '}'"),
        ("frame[1.5] = (1);", 1, 7, "integer index"),
        ("frame[-1] = (1);", 1, 7, "integer index"),
        ("frame[1234567890123] = (1);", 1, 7, "integer index"),
        ("x = (1, 2;", 1, 10, "expected ',' or ')'"),
        ("x = ;", 1, 5, "expected a value"),
        ("}", 1, 1, "expected a statement"),
        ("site a->= 1;", 1, 9, "field name"),
        ("connect a to b", 1, 15, "expected ';'"),
        ("x = 1.2.3;", 1, 8, "expected ';'"),
    ],
)
def test_located_syntax_errors(text: str, line: int, col: int, words: str) -> None:
    with pytest.raises(PeabodyError) as info:
        parse(text, "bad.env")
    err = info.value
    assert (err.file, err.line, err.column) == ("bad.env", line, col)
    assert words in err.message
    assert str(err) == f"bad.env:{line}:{col}: {err.message}"
    assert isinstance(err, ValueError)


def test_nesting_is_capped() -> None:
    deep_blocks = "a b {" * (MAX_DEPTH + 1) + "}" * (MAX_DEPTH + 1)
    with pytest.raises(PeabodyError, match="nested deeper"):
        parse(deep_blocks)
    ok_blocks = "a b {" * (MAX_DEPTH - 1) + "}" * (MAX_DEPTH - 1)
    assert len(parse(ok_blocks)) == 1
    with pytest.raises(PeabodyError, match="nested deeper"):
        parse("x = " + "(" * 5000 + "1" + ")" * 5000 + ";")
    with pytest.raises(PeabodyError, match="nested deeper"):
        parse("x = " + "-" * 5000 + "1;")
    with pytest.raises(PeabodyError, match="nested deeper"):
        parse("x = " + " + ".join(["1"] * 5000) + ";")


FAST_LINES = [
    'frame[12] = ("lower_torso.proximal", trans(31.68cm,43.53cm,-31.05cm));',
    'frame[3] = ( "a.b" , trans( 1 , 2mm , -3in ) ) ;',
    'frame[4] = ("lower_torso.proximal", xyz(0.1, -0.2, 3deg) * trans(31.68cm,43.53cm,-31.05cm));',
    "frame[5] = (0.1, -0.2);",
    "frame[6] = (0);",
    "frame[7] = ( 1e-3 , .5,-2. );",
    "frame[8] = (1, 2) /* after */;",  # falls back to the general path
    'frame[9] = ("x", trans(1cm, 2cm, 3cm)) ;  // comment',
    "frame[10] = (1cm, 2);",
    'frame[11] = ("x", trans(1cm,\n 2cm, 3cm));',
]


@pytest.mark.parametrize("line", FAST_LINES)
def test_fast_paths_build_the_same_tree(line: str, monkeypatch: pytest.MonkeyPatch) -> None:
    text = "channelset c {\n sharedchannel s {\n   " + line + "\n   " + line + "\n }\n}\n"
    fast = parse(text, "c.env")
    monkeypatch.setattr(lang, "FAST_PATHS", False)
    slow = parse(text, "c.env")
    assert fast == slow  # locations included


def test_parse_value_rejects_trailing_tokens() -> None:
    with pytest.raises(PeabodyError, match="after the value"):
        parse_value("1 2")


def test_non_string_input_is_a_peabody_error() -> None:
    with pytest.raises(PeabodyError):
        parse(b"x = 1;")  # type: ignore[arg-type]


# --- fuzz ---------------------------------------------------------------------------------------------------

_SAMPLES = sorted(p.read_text() for p in DATA.glob("*.fig")) + sorted(
    p.read_text() for p in DATA.glob("*.env")
)
_PIECES = [
    *"{}()[];,=*+-/^$\"'.0123456789 \n\t",
    "->",
    "/*",
    "*/",
    "//",
    "cm",
    "deg",
    "trans(",
    "R(",
    "frame[1]",
]


def _check(text: str) -> None:
    try:
        out = parse(text, "fuzz.env")
    except PeabodyError as err:
        assert err.file == "fuzz.env" and err.line >= 1 and err.column >= 1
        assert err.line <= text.count("\n") + 1
    else:
        assert isinstance(out, list)


@given(st.binary(max_size=300))
def test_random_bytes_never_crash(data: bytes) -> None:
    _check(data.decode("latin-1"))


@given(st.lists(st.sampled_from(_PIECES), max_size=80).map("".join))
def test_random_token_soup_never_crashes(parts: str) -> None:
    _check(parts)


@pytest.mark.fuzz
@given(
    st.sampled_from(_SAMPLES),
    st.lists(
        st.tuples(st.integers(0, 10**6), st.integers(0, 12), st.sampled_from([*_PIECES, ""])),
        min_size=1,
        max_size=6,
    ),
)
def test_mutated_valid_files_raise_located_errors(sample: str, edits: list[tuple[int, int, str]]) -> None:
    text = sample
    for pos, cut, insert in edits:
        i = pos % (len(text) + 1)
        text = text[:i] + insert + text[i + cut :]
    _check(text)
