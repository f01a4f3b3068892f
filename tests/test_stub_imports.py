"""Layering: ``client_stub`` may use ``protocol`` and ``peabody``; it never imports the server (nor the CLI).

The static check is import-linter's (every import statement); the second test tries it: it also catches
``importlib.import_module("server...")``, which no static scan sees."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_the_layer_contracts_hold() -> None:
    """import-linter's contracts (pyproject.toml): client_stub imports protocol and peabody, never the server,
    authoring or the CLI; the server never imports authoring or client_stub; nothing below the clients
    imports a GL, plotting or physics library. (`make test` runs `lint-imports` too.)"""
    pytest.importorskip("importlinter")
    code = (
        "from importlinter.cli import lint_imports as li; raise SystemExit(li(no_cache=True, no_logo=True))"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]


def test_importing_the_stub_loads_no_server_module() -> None:
    """The same, tried: import every client_stub module in a fresh interpreter and list what got loaded."""
    code = (
        "import importlib, pkgutil, sys, client_stub\n"
        "for m in pkgutil.walk_packages(client_stub.__path__, 'client_stub.'):\n"
        "    importlib.import_module(m.name)\n"
        "print(sorted(n for n in sys.modules if n.split('.')[0] in ('server', 'ttes')))\n"
    )
    env = {"PYOPENGL_PLATFORM": "egl", "PATH": ""}
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120, env=env
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "[]"
