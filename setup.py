"""What the wheel carries besides pyproject.toml's metadata: the code packages and the data read at run time.

The shipped data folders stay at the repository root, where ``ttes author`` writes them; in the wheel they go
under ``server/data/`` (site-packages has no repository root), where :mod:`server.data_root` finds them. The
clients' terrain and TIPS files live inside ``client_stub`` already. ``.ci/wheel_check.sh`` installs the wheel
outside the checkout and fails if any of this is missing.
"""

import runpy
import sys
from pathlib import Path

from setuptools import find_namespace_packages, setup
from setuptools.command.build_py import build_py

CODE = ("peabody", "protocol", "server", "authoring", "client_stub", "ttes")  # docs/ARCHITECTURE.md

# the shipped data folders (and their subfolders, e.g. figures/DI/) with the files of each
DATA = {
    "figures": ["*.fig", "*.pss"],
    "channelsets": ["*.chset.env"],
    "posture_graphs": ["*.graph", "*.jcl", "*.env"],
}
DATA_PACKAGES = {
    ".".join(("server.data", folder, sub)).rstrip("."): files
    for folder, files in DATA.items()
    for sub in ("", *find_namespace_packages(where=folder))
}


class BuildWithThree(build_py):
    """The page of ``ttes web`` imports three.js from ``client_stub/web/vendor/``, which is not committed:
    vendor it from npm (package.json's pinned version) before building, when it is missing. Without npm the
    wheel goes without it, and ``ttes web`` says so."""

    def run(self) -> None:
        vendor = runpy.run_path(str(Path(__file__).parent / "client_stub" / "web" / "vendor.py"))
        if not vendor["vendored"]():
            try:
                vendor["install"]()
            except Exception as exc:  # npm missing or failing: build without the page's three.js
                print(f"setup.py: three.js not vendored ({exc}): `make vendor`", file=sys.stderr)
        super().run()


setup(
    cmdclass={"build_py": BuildWithThree},
    packages=[
        *find_namespace_packages(
            include=[f"{p}*" for p in CODE], exclude=["*.__pycache__", "*node_modules*", "client_stub.web.*"]
        ),
        *DATA_PACKAGES,
    ],
    package_dir={f"server.data.{folder}": folder for folder in DATA},
    package_data={
        **DATA_PACKAGES,
        "client_stub.data": ["*.glb", "*.json", "*.tips"],
        "client_stub.crowd.data": ["*.tips"],
        "client_stub.web": ["*.html", "package.json", "js/*.js", "vendor/*.js", "vendor/addons/*/*.js"],
    },
)
