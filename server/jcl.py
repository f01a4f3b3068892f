"""JCL: Jack's command language, as a whitelist interpreter (never ``eval``).

A JCL script is a sequence of calls ``name(arg, arg, ...);`` whose arguments are strings (double or
single quotes) or numbers, with ``//`` and ``/* */`` comments — exactly what the seed's start-up script
``jack-ttes-soldier_low.jcl`` uses (section 3.6). Clients send JCL text over the wire too, so the parser has
hard limits on size and count, and every failure is a :class:`JclError` with a line and column.

Commands are looked up in a table of registered Python callables with declared argument types; anything else
is an error. Paths given to commands are resolved with :meth:`JclInterpreter.resolve_path`, which refuses to
leave the data directory.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

JclArg = str | float

MAX_SCRIPT_BYTES = 1 << 20
MAX_CALLS = 10_000
MAX_ARGS = 32
MAX_READ_DEPTH = 8

_TOKEN = re.compile(
    r"""
    (?P<ws>[ \t\r\n]+)
  | (?P<line_comment>//[^\n]*)
  | (?P<block_comment>/\*.*?\*/)
  | (?P<ident>[A-Za-z_][A-Za-z0-9_.]*)
  | (?P<number>[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?)
  | (?P<dstring>"(?:[^"\\\n]|\\.)*")
  | (?P<sstring>'(?:[^'\\\n]|\\.)*')
  | (?P<punct>[(),;])
    """,
    re.VERBOSE | re.DOTALL,
)
_ESCAPE = re.compile(r"\\(.)")


class JclError(ValueError):
    """A JCL script could not be parsed or run; carries where."""

    def __init__(self, message: str, *, file: str = "<jcl>", line: int = 0, column: int = 0) -> None:
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        super().__init__(f"{file}:{line}:{column}: {message}")


@dataclass(frozen=True)
class JclCall:
    name: str
    args: tuple[JclArg, ...]
    file: str
    line: int
    column: int


def _tokens(text: str, filename: str) -> list[tuple[str, str, int, int]]:
    out: list[tuple[str, str, int, int]] = []
    pos, line, line_start = 0, 1, 0
    n = len(text)
    while pos < n:
        m = _TOKEN.match(text, pos)
        if m is None:
            col = pos - line_start + 1
            if text.startswith("/*", pos):
                raise JclError("unterminated comment", file=filename, line=line, column=col)
            if text[pos] in "\"'":
                raise JclError("unterminated string", file=filename, line=line, column=col)
            raise JclError(f"unexpected character {text[pos]!r}", file=filename, line=line, column=col)
        kind = m.lastgroup or ""
        value = m.group()
        if kind not in ("ws", "line_comment", "block_comment"):
            out.append((kind, value, line, pos - line_start + 1))
        newlines = value.count("\n")
        if newlines:
            line += newlines
            line_start = pos + value.rindex("\n") + 1
        pos = m.end()
    return out


def parse_jcl(text: str, filename: str = "<jcl>") -> list[JclCall]:
    """Parse a script into calls; raises :class:`JclError` with a location on any malformed input."""
    if len(text) > MAX_SCRIPT_BYTES:
        raise JclError(f"script longer than {MAX_SCRIPT_BYTES} bytes", file=filename, line=1, column=1)
    toks = _tokens(text, filename)
    calls: list[JclCall] = []
    i = 0

    def expect(kind: str, value: str | None = None) -> tuple[str, str, int, int]:
        nonlocal i
        if i >= len(toks):
            last = toks[-1] if toks else ("", "", 1, 1)
            want = value or kind
            raise JclError(f"expected {want!r} at end of script", file=filename, line=last[2], column=last[3])
        tok = toks[i]
        if tok[0] != kind or (value is not None and tok[1] != value):
            want = value or kind
            raise JclError(f"expected {want!r}, found {tok[1]!r}", file=filename, line=tok[2], column=tok[3])
        i += 1
        return tok

    while i < len(toks):
        if toks[i][0] == "punct" and toks[i][1] == ";":  # empty statement
            i += 1
            continue
        name_tok = expect("ident")
        expect("punct", "(")
        args: list[JclArg] = []
        if i < len(toks) and toks[i][1] == ")":
            i += 1
        else:
            while True:
                if i >= len(toks):
                    raise JclError(
                        "unterminated argument list", file=filename, line=name_tok[2], column=name_tok[3]
                    )
                kind, value, line, col = toks[i]
                if kind == "number":
                    args.append(float(value))
                elif kind in ("dstring", "sstring"):
                    args.append(_ESCAPE.sub(r"\1", value[1:-1]))
                elif kind == "ident":  # Jack accepted bare words where strings were expected
                    args.append(value)
                else:
                    raise JclError(
                        f"expected an argument, found {value!r}", file=filename, line=line, column=col
                    )
                i += 1
                if len(args) > MAX_ARGS:
                    raise JclError(f"more than {MAX_ARGS} arguments", file=filename, line=line, column=col)
                sep = expect("punct")
                if sep[1] == ")":
                    break
                if sep[1] != ",":
                    raise JclError(
                        f"expected ',' or ')', found {sep[1]!r}", file=filename, line=sep[2], column=sep[3]
                    )
        if i < len(toks) and toks[i][1] == ";":
            i += 1
        elif i < len(toks):
            tok = toks[i]
            raise JclError(f"expected ';', found {tok[1]!r}", file=filename, line=tok[2], column=tok[3])
        calls.append(JclCall(name_tok[1], tuple(args), filename, name_tok[2], name_tok[3]))
        if len(calls) > MAX_CALLS:
            raise JclError(
                f"more than {MAX_CALLS} calls", file=filename, line=name_tok[2], column=name_tok[3]
            )
    return calls


@dataclass(frozen=True)
class JclCommand:
    """A whitelisted command: ``types`` are the accepted argument types, ``optional`` trailing ones may be
    omitted."""

    name: str
    func: Callable[..., object]
    types: tuple[type, ...]
    optional: int = 0
    variadic: type | None = None  # extra trailing arguments of this type (``object``: any)


class JclInterpreter:
    """Runs parsed JCL against a table of registered commands, inside one data directory."""

    def __init__(self, data_dir: str | Path, search_subdirs: tuple[str, ...] = ()) -> None:
        self.data_dir = Path(data_dir).resolve()
        # relative names not found in the data dir are looked up in these sub-folders (like Jack's data path)
        self.search_dirs = [self.data_dir / s for s in search_subdirs]
        self._commands: dict[str, JclCommand] = {}
        self._depth = 0
        self.register("read_file", self._read_file, (str,))
        self._file_handlers: dict[str, Callable[[Path], object]] = {".jcl": self.run_file}

    @property
    def commands(self) -> list[str]:
        return sorted(self._commands)

    def register(
        self,
        name: str,
        func: Callable[..., object],
        types: tuple[type, ...] = (),
        *,
        optional: int = 0,
        variadic: type | None = None,
    ) -> None:
        self._commands[name] = JclCommand(name, func, types, optional, variadic)

    def command(self, name: str) -> Callable[..., object]:
        """The function registered as ``name`` (to wrap it)."""
        return self._commands[name].func

    def register_file_handler(self, suffix: str, handler: Callable[[Path], object]) -> None:
        """``read_file`` dispatches on the file suffix (``.env``, ``.graph``, ...); ``.jcl`` runs nested."""
        self._file_handlers[suffix] = handler

    def resolve_path(self, name: str) -> Path:
        """A path named by a script, inside the data directory or an error (no ``..`` escapes, no absolute
        paths outside it, symlinks resolved); then the search sub-folders, each candidate confined too."""
        if not name or "\x00" in name:
            raise JclError(f"bad path {name!r}")
        path = (self.data_dir / name).resolve()
        if not self._inside(path):
            raise JclError(f"path {name!r} is outside the data directory")
        if path.exists() or Path(name).is_absolute():
            return path
        for folder in self.search_dirs:
            candidate = (folder / name).resolve()
            if candidate.exists() and self._inside(candidate):
                return candidate
        return path

    def _inside(self, path: Path) -> bool:
        return path == self.data_dir or self.data_dir in path.parents

    def run_text(self, text: str, filename: str = "<jcl>") -> list[object]:
        return [self.call(c) for c in parse_jcl(text, filename)]

    def run_file(self, path: Path) -> list[object]:
        if self._depth >= MAX_READ_DEPTH:
            raise JclError(f"read_file nested deeper than {MAX_READ_DEPTH}", file=str(path))
        self._depth += 1
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
            return self.run_text(text, path.name)
        finally:
            self._depth -= 1

    def call(self, c: JclCall) -> object:
        cmd = self._commands.get(c.name)
        where: dict[str, Any] = {"file": c.file, "line": c.line, "column": c.column}
        if cmd is None:
            raise JclError(f"unknown command {c.name!r}", **where)
        lo = len(cmd.types) - cmd.optional
        hi = None if cmd.variadic is not None else len(cmd.types)
        if len(c.args) < lo or (hi is not None and len(c.args) > hi):
            want = f"{lo}" if hi == lo else f"{lo}..{hi if hi is not None else ''}"
            raise JclError(f"{c.name} takes {want} arguments, got {len(c.args)}", **where)
        for k, arg in enumerate(c.args):
            want_t = cmd.types[k] if k < len(cmd.types) else cmd.variadic
            if want_t is object:  # any argument (a refused command answers whatever it is given)
                continue
            if want_t is float and isinstance(arg, float):
                continue
            if want_t is str and isinstance(arg, str):
                continue
            tname = "number" if want_t is float else "string"
            raise JclError(f"{c.name}: argument {k + 1} must be a {tname}", **where)
        try:
            return cmd.func(*c.args)
        except JclError as exc:
            if exc.line == 0:
                raise JclError(exc.message, **where) from None
            raise
        except (ValueError, KeyError, OSError, ArithmeticError) as exc:  # bad values, files, numbers
            raise JclError(f"{c.name}: {exc}", **where) from None

    def _read_file(self, name: str) -> object:
        path = self.resolve_path(name)
        if not path.is_file():
            raise JclError(f"read_file: no such file {name!r} in the data directory")
        handler = self._file_handlers.get(path.suffix)
        if handler is None:
            raise JclError(f"read_file: no reader for {path.suffix!r} files")
        return handler(path)
