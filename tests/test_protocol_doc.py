"""docs/PROTOCOL.md cannot rot: the example session is regenerated from the code; tables match enums."""

from __future__ import annotations

import re
from pathlib import Path

from protocol.errors import ErrorCode, is_fatal
from protocol.messages import MessageType
from protocol.session_example import BEGIN, END, render, splice

DOC = Path(__file__).resolve().parents[1] / "docs" / "PROTOCOL.md"


def test_example_session_hex_matches_the_code() -> None:
    text = DOC.read_text()
    block = text[text.index(BEGIN) : text.index(END) + len(END)]
    assert block == render(), "regenerate with: python -m protocol.session_example --write docs/PROTOCOL.md"
    assert splice(text, render()) == text


def test_message_table_lists_every_type() -> None:
    text = DOC.read_text()
    rows = dict(re.findall(r"^\| 0x([0-9a-f]{2}) \| ([A-Z_]+) \|", text, re.M))
    assert {int(k, 16): v for k, v in rows.items()} == {int(t): t.name for t in MessageType}


def test_error_table_lists_every_code() -> None:
    text = DOC.read_text()
    rows = re.findall(r"^\| (\d+) \| ([A-Z_]+) \| (yes|no) \|", text, re.M)
    assert {(int(c), n, f == "yes") for c, n, f in rows} == {(int(c), c.name, is_fatal(c)) for c in ErrorCode}
