"""Fuzzed channelset files: ChannelsetError or PeabodyError with a location, never another exception."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from peabody.language import PeabodyError
from server.motion.channelset import channelsets_close
from server.motion.channelset_file import format_channelset, parse_channelsets
from server.motion.errors import ChannelsetError

DATA = Path(__file__).resolve().parent / "data" / "motion"
SEED = (DATA / "ststow2kfire_low.chset.env").read_text()
# shorten it (fuzzing speed) but keep a rotation line: drop frames 4.. of each channel and fix the size
VALID = "\n".join(
    line
    for line in SEED.replace("size = 18;", "size = 3;").splitlines()
    if not line.strip().startswith("frame[") or int(line.split("[")[1].split("]")[0]) < 4
)
TOKENS = [
    "frame[0]",
    "frame[9]",
    "(",
    ")",
    "{",
    "}",
    ";",
    ",",
    "=",
    "*",
    "trans(1,2,3)",
    "xyz(1,2,3)",
    '"',
    "/*",
    "scale(0)",
    "1e40",
    "-",
    "deg",
    "cm",
    "size",
    "count",
    "fps",
    "sharedchannel",
    "channelset",
    "$",
]


def check(data: str | bytes) -> None:
    try:
        found = parse_channelsets(data, "fuzz.chset.env")
    except ChannelsetError as exc:
        assert exc.file == "fuzz.chset.env" and isinstance(exc.line, int) and exc.line >= 1, exc
        return
    except PeabodyError as exc:
        assert exc.file == "fuzz.chset.env" and exc.line >= 1 and exc.column >= 1
        return
    for cs in found:  # whatever reads must write and read back
        (back,) = parse_channelsets(format_channelset(cs), "again")
        assert channelsets_close(cs, back, atol=1e-5)


def test_the_fuzz_seed_is_valid() -> None:
    (cs,) = parse_channelsets(VALID, "v")
    assert cs.nframes == 4 and "xyz(" in VALID


@pytest.mark.fuzz
@given(st.binary(max_size=300))
def test_random_bytes(data: bytes) -> None:
    check(data)


@st.composite
def mutated(draw: st.DrawFn) -> str:
    text = VALID
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(text)))
        op = draw(st.sampled_from(["delete", "insert", "token", "duplicate"]))
        if op == "delete":
            text = text[:i] + text[i + draw(st.integers(1, 30)) :]
        elif op == "insert":
            text = text[:i] + draw(st.text(max_size=4)) + text[i:]
        elif op == "token":
            text = text[:i] + draw(st.sampled_from(TOKENS)) + text[i:]
        else:
            j = draw(st.integers(i, min(len(text), i + 80)))
            text = text[:j] + text[i:j] + text[j:]
    return text


@pytest.mark.fuzz
@given(mutated())
def test_mutated_channelset_text(text: str) -> None:
    check(text)
