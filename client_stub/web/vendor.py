"""Vendor three.js into the page: copy the files ``index.html`` imports from npm's ``three`` into ``vendor/``.

The page loads no CDN: ``make vendor`` (or the wheel's build, setup.py) runs ``npm install`` here with
``package.json``'s pinned version, then this copies ``three.module.js``, ``three.core.js`` and the glTF loader
with its two helpers, keeping the layout ``index.html``'s import map expects. Runs as a plain script (setup.py
calls it before the packages exist): ``python client_stub/web/vendor.py [--node-modules DIR]``; exit 1 when
npm is missing or fails.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
VENDOR = HERE / "vendor"
FILES = {  # vendor/<name>: node_modules/three/<source>
    "three.module.js": "build/three.module.js",
    "three.core.js": "build/three.core.js",
    "addons/loaders/GLTFLoader.js": "examples/jsm/loaders/GLTFLoader.js",
    "addons/utils/BufferGeometryUtils.js": "examples/jsm/utils/BufferGeometryUtils.js",
    "addons/utils/SkeletonUtils.js": "examples/jsm/utils/SkeletonUtils.js",
}


def vendored(folder: Path = VENDOR) -> bool:
    """Whether every file the page imports is in ``folder``."""
    return all((folder / name).is_file() for name in FILES)


def install(node_modules: Path | None = None, dest: Path = VENDOR) -> Path:
    """Copy the files from ``node_modules`` (default: ``npm install`` next to package.json); the dest."""
    if node_modules is None:
        npm = shutil.which("npm")
        if npm is None:
            raise RuntimeError("npm is not installed: cannot vendor three.js")
        subprocess.run(
            [npm, "install", "--no-audit", "--no-fund", "--silent", "--prefix", str(HERE)], check=True
        )
        node_modules = HERE / "node_modules"
    for name, source in FILES.items():
        (dest / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(node_modules / "three" / source, dest / name)
    return dest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--node-modules", type=Path, help="an installed node_modules with three (default: npm install)"
    )
    args = p.parse_args(argv)
    try:
        print(f"three.js vendored into {install(args.node_modules)}")
    except (RuntimeError, OSError, subprocess.CalledProcessError) as exc:
        print(f"vendor: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
