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


PAGE = Path(__file__).resolve().parent / "client_stub" / "web"
PAGE_FILES = ["*.js", "*.mjs"]


def page_packages() -> dict[str, list[str]]:
    """The page's script folders (``js/``, and ``vendor/`` with its subfolders once vendored) as packages
    with their scripts as package data: setuptools ships data only from listed packages, and warns ("Package
    would be ignored") about folders with importable names that are not."""
    folders = [
        d for top in ("js", "vendor") for d in (PAGE / top, *sorted((PAGE / top).rglob("*"))) if d.is_dir()
    ]
    return {
        ".".join(("client_stub.web", *d.relative_to(PAGE).parts)): PAGE_FILES
        for d in folders
        if any(d.glob(g) for g in PAGE_FILES)
    }


class BuildWithThree(build_py):
    """The page of ``ttes web`` imports three.js and msgpack from ``client_stub/web/vendor/``, which is not
    committed: vendor them from npm (package.json's pinned versions) before building, when they are missing,
    and list the vendored folders as packages. Without npm the wheel goes without them, and ``ttes web``
    says so."""

    def run(self) -> None:
        vendor = runpy.run_path(str(PAGE / "vendor.py"))
        if not vendor["vendored"]():
            try:
                vendor["install"]()
            except Exception as exc:  # npm missing or failing: build without the page's libraries
                print(f"setup.py: three.js and msgpack not vendored ({exc}): `make vendor`", file=sys.stderr)
        new = {k: v for k, v in page_packages().items() if k not in self.packages}
        self.packages = [*self.packages, *new]
        self.package_data = {**self.package_data, **new}
        super().run()


setup(
    cmdclass={"build_py": BuildWithThree},
    packages=[
        *find_namespace_packages(
            include=[f"{p}*" for p in CODE], exclude=["*.__pycache__", "*node_modules*", "client_stub.web.*"]
        ),
        *DATA_PACKAGES,
        *page_packages(),
    ],
    package_dir={f"server.data.{folder}": folder for folder in DATA},
    package_data={
        **DATA_PACKAGES,
        "client_stub.data": ["*.glb", "*.json", "*.tips"],
        "client_stub.crowd.data": ["*.tips"],
        "client_stub.web": ["*.html", "package.json"],
        **page_packages(),
    },
)
