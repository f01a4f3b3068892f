"""The npm packages the tests drive with node (tests/tools/package.json: the Khronos glTF validator,
puppeteer-core), installed outside the checkout (``TTES_NPM_DIR``, default ~/.cache/jack-ttes/npm; .ci/run
installs them there first, a test installs them on first use)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

TOOLS = Path(__file__).resolve().parent / "tools"


def npm_dir(package: str) -> Path | None:
    """The folder whose node_modules holds ``package`` (installed now if missing); None without node/npm or
    the registry."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        return None
    where = Path(os.environ.get("TTES_NPM_DIR", Path.home() / ".cache" / "jack-ttes" / "npm"))
    if not (where / "node_modules" / package).is_dir():
        where.mkdir(parents=True, exist_ok=True)
        shutil.copy(TOOLS / "package.json", where / "package.json")
        cmd = ["npm", "install", "--silent", "--no-audit", "--no-fund", "--prefix", str(where)]
        try:
            subprocess.run(cmd, check=True, timeout=300, capture_output=True)
        except (subprocess.SubprocessError, OSError):
            return None
    return where if (where / "node_modules" / package).is_dir() else None
