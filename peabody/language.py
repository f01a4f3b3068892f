"""The Peabody language: tokenizer and recursive-descent parser (seed 000, 7.5 and 7.11).

The parser builds a small syntax tree and evaluates nothing: the loader (:mod:`peabody.loader`) gives
the tree its meaning, and extension blocks (channelsets, ...) receive their subtree untouched, which is the
role ``DefinePeabodyBlock`` played in Jack.

Syntax tree (all nodes are frozen dataclasses; ``loc`` is a :class:`Loc` ``(file, line, col)``, 1-based):

Statements (``parse`` returns ``list[Stmt]``)
    ``Block(keyword, name, body, loc)``
        ``keyword name { body }`` for ``figure``/``segment``/``site``/``joint`` and *any* other keyword
        (``channelset x {}``, ``sharedchannel right.toes {}``).  ``name`` is an identifier, a dotted name or
        a string's contents.  ``body`` is a tuple of statements.
    ``Assign(target, index, value, loc, owner=None)``
        ``target = value;``, ``target[12] = value;`` (``index`` an ``int`` or ``None``) and the
        ``site proximal->location = value;`` form, which sets ``owner=("site", "proximal")``.
    ``Statement(keyword, args, loc)``
        any other ``keyword arg arg ... ;``; e.g. ``connect a.b to c.d;`` gives
        ``Statement("connect", (Name("a.b"), Name("to"), Name("c.d")))``.  Commas between args are optional.

Values
    ``Number(value, unit, loc)``  ``31.68cm`` -> ``Number(31.68, "cm")``; bare numbers have ``unit=None``.
    ``String(value, loc)``         ``"x.pss"`` (escapes ``\\"`` and ``\\\\``).
    ``Name(name, loc)``            identifiers and dotted names (``lower_torso.proximal``, ``z``).
    ``Vector(items, loc)``         ``( a, b, ... )``; a parenthesised single value is a 1-vector too.
    ``Call(name, args, loc)``      ``trans(1cm,2cm,3cm)``, ``R(z)``, ``R(1,0,0)``: never evaluated here.
    ``BinOp(op, left, right, loc)`` ``+ - * / ^`` with the usual precedence, left associative
                                   (``^`` binds tightest, right associative).
    ``Neg(operand, loc)``          unary minus (``-31.05cm`` is a ``Number`` with a negative value).
    ``Unsupplied(loc)``            ``$`` (Jack's V_UNSUPPLIED).

Lexical rules: comments ``/* ... */`` and ``// ...``; numbers ``12``, ``1.5``, ``.5``, ``1e-3`` with an
optional unit glued on (``10.5cm``, ``30deg``: any letters, checked by the evaluator); identifiers
``[A-Za-z_][A-Za-z0-9_]*`` joined by dots; punctuation ``{ } ( ) [ ] ; , = * + - / ^ $ ->``.

Errors: every malformed input raises :class:`PeabodyError` (a ``ValueError``) carrying ``file``, ``line``,
``column`` and ``message``; nesting of blocks and expressions is capped at :data:`MAX_DEPTH`.

Speed: tokens come from one compiled master regex matched in place (no token list), and the very common
channelset lines (``frame[12] = ("seg.site", trans(..));``, ``frame[3] = (0.1, -0.2);``) are recognised by
whole-statement regexes that build exactly the nodes the general path would.
"""

from __future__ import annotations

import gc
import re
from dataclasses import dataclass
from typing import NamedTuple, NoReturn

MAX_DEPTH = 64


class Loc(NamedTuple):
    file: str
    line: int
    col: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


class PeabodyError(ValueError):
    """A located error in Peabody text (syntax or meaning): ``str()`` is ``"file:line:col: message"``."""

    def __init__(self, file: str, line: int, column: int, message: str) -> None:
        self.file = file
        self.line = line
        self.column = column
        self.message = message
        super().__init__(f"{file}:{line}:{column}: {message}")

    @classmethod
    def at(cls, loc: Loc, message: str) -> PeabodyError:
        return cls(loc.file, loc.line, loc.col, message)


# --- syntax tree -------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Number:
    value: float
    unit: str | None
    loc: Loc


@dataclass(frozen=True, slots=True)
class String:
    value: str
    loc: Loc


@dataclass(frozen=True, slots=True)
class Name:
    name: str
    loc: Loc


@dataclass(frozen=True, slots=True)
class Vector:
    items: tuple[Value, ...]
    loc: Loc


@dataclass(frozen=True, slots=True)
class Call:
    name: str
    args: tuple[Value, ...]
    loc: Loc


@dataclass(frozen=True, slots=True)
class BinOp:
    op: str
    left: Value
    right: Value
    loc: Loc


@dataclass(frozen=True, slots=True)
class Neg:
    operand: Value
    loc: Loc


@dataclass(frozen=True, slots=True)
class Unsupplied:
    loc: Loc


Value = Number | String | Name | Vector | Call | BinOp | Neg | Unsupplied


@dataclass(frozen=True, slots=True)
class Assign:
    target: str
    index: int | None
    value: Value
    loc: Loc
    owner: tuple[str, str] | None = None


@dataclass(frozen=True, slots=True)
class Statement:
    keyword: str
    args: tuple[Value, ...]
    loc: Loc


@dataclass(frozen=True, slots=True)
class Block:
    keyword: str
    name: str
    body: tuple[Stmt, ...]
    loc: Loc


Stmt = Block | Assign | Statement
Node = Stmt | Value

# --- lexer -------------------------------------------------------------------------------------------------

# possessive/atomic pieces: failing matches must never backtrack exponentially (fuzzed input)
_SKIP = r"(?:\s++|//[^\n]*+|/\*.*?\*/)*+"
_NUM = r"(?>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
_IDENT = r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)*"
_STR = r'"(?:[^"\\\n]|\\.)*"'

# kinds: "num" (text, unit), "name", "str", "->", single-character punctuation, "eof"
_TOKEN = re.compile(
    _SKIP
    + r"(?:(?P<num>"
    + _NUM
    + r")(?P<unit>[A-Za-z_]\w*)?"
    + r"|(?P<name>"
    + _IDENT
    + r")"
    + r"|(?P<str>"
    + _STR
    + r")"
    + r"|(?P<opencomment>/\*)"
    + r"|(?P<punct>->|[{}()\[\];,=*+\-/^$])"
    + r"|(?P<eof>\Z))",
    re.S,
)
_SKIP_RE = re.compile(_SKIP, re.S)
_ESCAPE = re.compile(r"\\(.)", re.S)

# Whole-statement fast paths for channelset frames (must build the same nodes as the general parser).
_FN = r"(-?" + _NUM + r")(cm|mm|m|in|deg|rad)?"
_FAST_VEC = re.compile(
    _SKIP
    + r"(?P<t>[A-Za-z_][A-Za-z0-9_]*)\[(?P<i>\d{1,9})\] ?= ?\((?P<v> ?-?"
    + _NUM
    + r"(?: ?, ?-?"
    + _NUM
    + r")*) ?\) ?;",
)
_FAST_NUM = re.compile(r"-?" + _NUM)
_FAST_FRAME = re.compile(
    _SKIP + r"(?P<t>[A-Za-z_][A-Za-z0-9_]*)\[(?P<i>\d{1,9})\] ?= ?\( ?(?P<s>\"[^\"\\\n]*\") ?, ?"
    r"(?:(?P<x>xyz)\( ?" + _FN + r" ?, ?" + _FN + r" ?, ?" + _FN + r" ?\) ?(?P<star>\*) ?)?"
    r"(?P<tr>trans)\( ?" + _FN + r" ?, ?" + _FN + r" ?, ?" + _FN + r" ?\) ?\) ?;",
)

_FAST_FRAME_X = _FAST_FRAME.groupindex["x"]
_FAST_FRAME_TR = _FAST_FRAME.groupindex["tr"]
_tuple_new = tuple.__new__
FAST_PATHS = True  # tests switch this off to check the fast paths build the same trees


def _unescape(body: str) -> str:
    return _ESCAPE.sub(lambda m: m.group(1), body) if "\\" in body else body


class _Parser:
    __slots__ = ("_line", "_line_off", "_line_start", "file", "pos", "text", "tok", "tok_end", "tok_start")

    def __init__(self, text: str, filename: str) -> None:
        self.text = text
        self.file = filename
        self.pos = 0
        self._line = 1
        self._line_start = 0
        self._line_off = 0  # offset up to which newlines have been counted
        self.tok: tuple[str, str, str | None] = ("eof", "", None)
        self.tok_start = 0
        self.tok_end = 0
        self._advance()

    # location bookkeeping: newlines are counted incrementally as the parse moves forward
    def loc(self, offset: int) -> Loc:
        if offset < self._line_off:
            line = self.text.count("\n", 0, offset) + 1
            start = self.text.rfind("\n", 0, offset) + 1
            return Loc(self.file, line, offset - start + 1)
        n = self.text.count("\n", self._line_off, offset)
        if n:
            self._line += n
            self._line_start = self.text.rfind("\n", self._line_off, offset) + 1
        self._line_off = offset
        return Loc(self.file, self._line, offset - self._line_start + 1)

    def error(self, offset: int, message: str) -> PeabodyError:
        return PeabodyError.at(self.loc(offset), message)

    def _advance(self) -> None:
        m = _TOKEN.match(self.text, self.pos)
        if m is None:
            self._lex_error()
        kind = m.lastgroup
        if kind == "opencomment":
            raise self.error(m.start(kind), "unterminated comment")
        if kind == "unit":
            self.tok = ("num", m.group("num"), m.group("unit"))
            self.tok_start = m.start("num")
        else:
            assert kind is not None
            self.tok = (kind, m.group(kind), None) if kind != "punct" else (m.group(kind), "", None)
            self.tok_start = m.start(kind)
        self.tok_end = self.pos = m.end()

    def _lex_error(self) -> NoReturn:
        text = self.text
        p = _SKIP_RE.match(text, self.pos).end()  # type: ignore[union-attr]
        if text.startswith("/*", p):
            raise self.error(p, "unterminated comment")
        if text.startswith('"', p):
            raise self.error(p, "unterminated string")
        raise self.error(p, f"unexpected character {text[p]!r}")

    def expect(self, kind: str, what: str) -> tuple[str, str, str | None]:
        tok = self.tok
        if tok[0] != kind:
            raise self.error(self.tok_start, f"expected {what}, found {self.describe()}")
        self._advance()
        return tok

    def describe(self) -> str:
        kind, text, unit = self.tok
        if kind == "eof":
            return "end of input"
        if kind == "num":
            return f"number {text}{unit or ''}"
        if kind == "name":
            return f"name {text!r}"
        if kind == "str":
            return f"string {text}"
        return repr(kind)

    # statements --------------------------------------------------------------------------------------------

    def statements(self, depth: int, closing: str) -> tuple[Stmt, ...]:
        out: list[Stmt] = []
        append = out.append
        text = self.text
        while True:
            kind = self.tok[0]
            if kind == closing:
                return tuple(out)
            if kind == ";":
                self._advance()
                continue
            if kind != "name":
                what = "'}'" if closing == "}" else "a statement"
                raise self.error(self.tok_start, f"expected a statement or {what}, found {self.describe()}")
            # fast paths: the token just read is the statement's first name; re-match from its start
            if FAST_PATHS and text[self.tok_end : self.tok_end + 1] == "[":
                fast = self._fast_assign(self.tok_start)
                if fast is not None:
                    append(fast)
                    continue
            append(self.statement(depth))

    def _fast_assign(self, start: int) -> Assign | None:
        text = self.text
        m = _FAST_VEC.match(text, start)
        if m is not None:
            loc = self.loc(start)
            line, base, file = loc.line, self._line_start - 1, self.file
            v0, v1 = m.span("v")
            items = tuple(
                Number(float(n.group()), None, _tuple_new(Loc, (file, line, n.start() - base)))
                for n in _FAST_NUM.finditer(text, v0, v1)
            )
            vloc = _tuple_new(Loc, (file, line, text.rfind("(", start, v0 + 1) - base))
            node = Assign(m.group("t"), int(m.group("i")), Vector(items, vloc), loc)
        else:
            m = _FAST_FRAME.match(text, start)
            if m is None:
                return None
            loc = self.loc(start)
            line, base, file = loc.line, self._line_start - 1, self.file
            g = m.group
            st = m.start
            tr = _FAST_FRAME_TR
            trans = Call(
                "trans",
                (
                    Number(float(g(tr + 1)), g(tr + 2), _tuple_new(Loc, (file, line, st(tr + 1) - base))),
                    Number(float(g(tr + 3)), g(tr + 4), _tuple_new(Loc, (file, line, st(tr + 3) - base))),
                    Number(float(g(tr + 5)), g(tr + 6), _tuple_new(Loc, (file, line, st(tr + 5) - base))),
                ),
                _tuple_new(Loc, (file, line, st(tr) - base)),
            )
            value: Value = trans
            x = _FAST_FRAME_X
            if g(x) is not None:
                xyz = Call(
                    "xyz",
                    (
                        Number(float(g(x + 1)), g(x + 2), _tuple_new(Loc, (file, line, st(x + 1) - base))),
                        Number(float(g(x + 3)), g(x + 4), _tuple_new(Loc, (file, line, st(x + 3) - base))),
                        Number(float(g(x + 5)), g(x + 6), _tuple_new(Loc, (file, line, st(x + 5) - base))),
                    ),
                    _tuple_new(Loc, (file, line, st(x) - base)),
                )
                value = BinOp("*", xyz, trans, _tuple_new(Loc, (file, line, st("star") - base)))
            s0 = st("s")
            s = String(g("s")[1:-1], _tuple_new(Loc, (file, line, s0 - base)))
            vloc = _tuple_new(Loc, (file, line, text.rfind("(", start, s0) - base))
            node = Assign(g("t"), int(g("i")), Vector((s, value), vloc), loc)
        # the statement ends the line's work: lex the next token
        self.pos = m.end()
        self._advance()
        return node

    def statement(self, depth: int) -> Stmt:
        start = self.tok_start
        keyword = self.tok[1]
        self._advance()
        kind = self.tok[0]
        if kind == "=":
            self._advance()
            return self._finish_assign(keyword, None, start, None, depth)
        if kind == "[":
            index = self._index()
            self.expect("=", "'='")
            return self._finish_assign(keyword, index, start, None, depth)
        if kind in ("name", "str"):
            name_tok = self.tok
            name_start = self.tok_start
            name = name_tok[1] if kind == "name" else _unescape(name_tok[1][1:-1])
            self._advance()
            nxt = self.tok[0]
            if nxt == "{":
                if depth >= MAX_DEPTH:
                    raise self.error(start, f"blocks nested deeper than {MAX_DEPTH}")
                loc = self.loc(start)
                self._advance()
                body = self.statements(depth + 1, "}")
                self._advance()
                return Block(keyword, name, body, loc)
            if nxt == "->" and kind == "name":
                self._advance()
                field = self.expect("name", "a field name after '->'")[1]
                field_index = self._index() if self.tok[0] == "[" else None
                self.expect("=", "'='")
                return self._finish_assign(field, field_index, start, (keyword, name), depth)
            # a keyword statement whose first argument we already consumed: rewind to it
            self.pos = name_start
            self._advance()
        loc = self.loc(start)
        args: list[Value] = []
        while self.tok[0] != ";":
            if self.tok[0] == "eof":
                raise self.error(self.tok_start, f"expected ';' to end the {keyword!r} statement")
            if self.tok[0] == "," and args:
                self._advance()
                continue
            args.append(self.expr(depth))
        self._advance()
        return Statement(keyword, tuple(args), loc)

    def _index(self) -> int:
        self._advance()  # '['
        tok = self.tok
        if tok[0] != "num" or tok[2] is not None or not tok[1].isdigit() or len(tok[1]) > 9:
            raise self.error(self.tok_start, f"expected an integer index, found {self.describe()}")
        self._advance()
        self.expect("]", "']'")
        return int(tok[1])

    def _finish_assign(
        self, target: str, index: int | None, start: int, owner: tuple[str, str] | None, depth: int
    ) -> Assign:
        loc = self.loc(start)
        value = self.expr(depth)
        self.expect(";", "';' after the value")
        return Assign(target, index, value, loc, owner)

    # expressions -------------------------------------------------------------------------------------------

    def expr(self, depth: int) -> Value:
        if depth >= MAX_DEPTH:
            raise self.error(self.tok_start, f"expression nested deeper than {MAX_DEPTH}")
        left = self.term(depth + 1)
        while self.tok[0] in ("+", "-"):
            depth = self._deeper(depth)  # each operator deepens the (left-leaning) tree
            op, loc = self.tok[0], self.loc(self.tok_start)
            self._advance()
            left = BinOp(op, left, self.term(depth + 1), loc)
        return left

    def _deeper(self, depth: int) -> int:
        if depth + 1 >= MAX_DEPTH:
            raise self.error(self.tok_start, f"expression nested deeper than {MAX_DEPTH}")
        return depth + 1

    def term(self, depth: int) -> Value:
        left = self.unary(depth)
        while self.tok[0] in ("*", "/"):
            depth = self._deeper(depth)
            op, loc = self.tok[0], self.loc(self.tok_start)
            self._advance()
            left = BinOp(op, left, self.unary(depth), loc)
        return left

    def unary(self, depth: int) -> Value:
        if depth >= MAX_DEPTH:
            raise self.error(self.tok_start, f"expression nested deeper than {MAX_DEPTH}")
        kind = self.tok[0]
        if kind == "-":
            loc = self.loc(self.tok_start)
            self._advance()
            if self.tok[0] == "num":  # fold literal negatives (as the fast paths do), unless a power follows
                node = self._power(self.primary(depth), depth)
                if isinstance(node, Number):
                    return Number(-node.value, node.unit, loc)
                return Neg(node, loc)
            return Neg(self.unary(depth + 1), loc)
        if kind == "+":
            self._advance()
            return self.unary(depth + 1)
        return self._power(self.primary(depth), depth)

    def _power(self, base: Value, depth: int) -> Value:
        if self.tok[0] == "^":
            loc = self.loc(self.tok_start)
            self._advance()
            return BinOp("^", base, self.unary(depth + 1), loc)
        return base

    def primary(self, depth: int) -> Value:
        kind, text, unit = self.tok
        start = self.tok_start
        if kind == "num":
            self._advance()
            return Number(float(text), unit, self.loc(start))
        if kind == "str":
            self._advance()
            return String(_unescape(text[1:-1]), self.loc(start))
        if kind == "name":
            self._advance()
            if self.tok[0] == "(":
                loc = self.loc(start)
                return Call(text, self._args(depth), loc)
            return Name(text, self.loc(start))
        if kind == "(":
            loc = self.loc(start)
            return Vector(self._args(depth), loc)
        if kind == "$":
            self._advance()
            return Unsupplied(self.loc(start))
        raise self.error(start, f"expected a value, found {self.describe()}")

    def _args(self, depth: int) -> tuple[Value, ...]:
        self._advance()  # '('
        items: list[Value] = []
        if self.tok[0] == ")":
            self._advance()
            return ()
        while True:
            items.append(self.expr(depth + 1))
            kind = self.tok[0]
            if kind == ",":
                self._advance()
                continue
            if kind == ")":
                self._advance()
                return tuple(items)
            raise self.error(self.tok_start, f"expected ',' or ')', found {self.describe()}")


def parse(text: str, filename: str = "<string>") -> list[Stmt]:
    """Parse Peabody text into a list of top-level statements (see the module docstring)."""
    if not isinstance(text, str):
        raise PeabodyError(filename, 1, 1, "Peabody text must be str")
    # the tree is acyclic: pausing the cyclic collector saves its repeated scans of the growing tree
    paused = gc.isenabled()
    gc.disable()
    try:
        return list(_Parser(text, filename).statements(0, "eof"))
    finally:
        if paused:
            gc.enable()


def parse_value(text: str, filename: str = "<string>") -> Value:
    """Parse one value expression (e.g. ``"trans(1cm, 2cm, 3cm)"``)."""
    p = _Parser(text, filename)
    value = p.expr(0)
    if p.tok[0] != "eof":
        raise p.error(p.tok_start, f"unexpected {p.describe()} after the value")
    return value


def strip_locations(node: object) -> object:
    """The tree with every ``loc`` dropped (nested tuples), for comparing trees from different sources."""
    if isinstance(node, tuple | list):
        return tuple(strip_locations(n) for n in node)
    slots = getattr(type(node), "__slots__", None)
    if slots is None or isinstance(node, Loc):
        return node
    return (type(node).__name__, *(strip_locations(getattr(node, s)) for s in slots if s != "loc"))
