"""Layering: ``client_stub`` may use ``protocol``; it never imports the server (nor the CLI package)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_client_stub_never_imports_server() -> None:
    """Every import statement and import_module/__import__ call of every client_stub module, scanned."""
    offenders = []
    for path in sorted((ROOT / "client_stub").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""] if node.level == 0 else []
            elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__"):  # fmt: skip
                names = [
                    a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)
                ]
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in ("server", "ttes")]
    assert offenders == []


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
