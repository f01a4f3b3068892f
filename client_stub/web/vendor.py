"""Vendor the page's JavaScript libraries: copy the files the page imports from npm into ``vendor/``.

The page loads no CDN: ``make vendor`` (or the wheel's build, setup.py) runs ``npm install`` here with
``package.json``'s pinned versions, then this copies three.js (``three.module.js``, ``three.core.js`` and the
glTF loader with its two helpers, in the layout ``index.html``'s import map expects) and the ESM build of
``@msgpack/msgpack`` (``vendor/msgpack/``, which ``js/wire.js`` imports by a relative path, so that node runs
it too). Runs as a plain script (setup.py calls it before the packages exist): ``python
client_stub/web/vendor.py [--node-modules DIR]``; exit 1 when npm is missing or fails.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
VENDOR = HERE / "vendor"
FILES = {  # vendor/<name>: node_modules/<source>
    "three.module.js": "three/build/three.module.js",
    "three.core.js": "three/build/three.core.js",
    "addons/loaders/GLTFLoader.js": "three/examples/jsm/loaders/GLTFLoader.js",
    "addons/utils/BufferGeometryUtils.js": "three/examples/jsm/utils/BufferGeometryUtils.js",
    "addons/utils/SkeletonUtils.js": "three/examples/jsm/utils/SkeletonUtils.js",
}
TREES = {"msgpack": "@msgpack/msgpack/dist.esm"}  # vendor/<name>/**/*.mjs: node_modules/<source>/**/*.mjs
ENTRIES = ("msgpack/index.mjs",)  # what the page imports of the trees


def vendored(folder: Path = VENDOR) -> bool:
    """Whether every file the page imports is in ``folder``."""
    return all((folder / name).is_file() for name in (*FILES, *ENTRIES))


def install(node_modules: Path | None = None, dest: Path = VENDOR) -> Path:
    """Copy the files from ``node_modules`` (default: ``npm install`` next to package.json); the dest."""
    if node_modules is None:
        npm = shutil.which("npm")
        if npm is None:
            raise RuntimeError("npm is not installed: cannot vendor three.js and msgpack")
        subprocess.run(
            [npm, "install", "--no-audit", "--no-fund", "--silent", "--prefix", str(HERE)], check=True
        )
        node_modules = HERE / "node_modules"
    for name, source in FILES.items():
        (dest / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(node_modules / source, dest / name)
    for name, source in TREES.items():
        for module in (node_modules / source).rglob("*.mjs"):
            to = dest / name / module.relative_to(node_modules / source)
            to.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(module, to)
    return dest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--node-modules",
        type=Path,
        help="an installed node_modules with three and @msgpack/msgpack (default: npm install)",
    )
    args = p.parse_args(argv)
    try:
        print(f"three.js and msgpack vendored into {install(args.node_modules)}")
    except (RuntimeError, OSError, subprocess.CalledProcessError) as exc:
        print(f"vendor: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
