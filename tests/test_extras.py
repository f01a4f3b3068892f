"""A command whose optional extra is missing exits 2 naming the extra; the server needs none."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

import ttes.cli
from ttes.extras import EXTRA_OF_MODULE, missing_extra_message

ROOT = Path(__file__).resolve().parents[1]


def _parser_raising(exc: BaseException) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ttes")
    parser.add_argument("-v", "--verbose", action="count", default=0)
    sub = parser.add_subparsers(dest="command")

    def run(args: argparse.Namespace) -> int:
        raise exc

    sub.add_parser("stub").set_defaults(func=run)
    return parser


def test_a_missing_extra_module_exits_2_naming_the_extra(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = _parser_raising(ModuleNotFoundError(name="pyrender"))
    monkeypatch.setattr(ttes.cli, "build_parser", lambda: parser)
    assert ttes.cli.main(["stub"]) == 2
    err = capsys.readouterr().err
    assert "pip install 'jack-ttes[stub]'" in err and "pyrender" in err


def test_a_missing_module_of_our_own_is_not_blamed_on_an_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    parser = _parser_raising(ModuleNotFoundError(name="server.x"))
    monkeypatch.setattr(ttes.cli, "build_parser", lambda: parser)
    with pytest.raises(ModuleNotFoundError):
        ttes.cli.main(["stub"])


def test_submodules_map_to_their_package_extra() -> None:
    msg = missing_extra_message("author", ModuleNotFoundError(name="scipy.spatial"))
    assert msg is not None and "jack-ttes[authoring]" in msg


def test_every_extra_module_is_in_an_extra_of_pyproject() -> None:
    text = (ROOT / "pyproject.toml").read_text()
    for extra in set(EXTRA_OF_MODULE.values()):
        assert f"\n{extra} = [" in text


def test_the_server_imports_no_extra() -> None:
    """`ttes server`'s modules load without any module of an extra (the base install is enough); so do the
    fabric's nodes (only its adapters, opened by --shard or ttes front, import Zenoh or Cyclone DDS)."""
    code = (
        "import sys, ttes.cli; ttes.cli.build_parser();"
        "import server.app, server.startup, server.config, server.logging, server.fabric.nodes;"
        "from ttes.extras import EXTRA_OF_MODULE;"
        "print(sorted(m for m in EXTRA_OF_MODULE if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
