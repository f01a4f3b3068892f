"""What the wheel carries besides pyproject.toml's metadata: the code packages and the data read at run time.

The shipped data folders stay at the repository root, where ``ttes author`` writes them; in the wheel they go
under ``server/data/`` (site-packages has no repository root), where :mod:`server.data_root` finds them. The
clients' terrain and TIPS files live inside ``client_stub`` already. ``.ci/wheel_check.sh`` installs the wheel
outside the checkout and fails if any of this is missing.
"""

from setuptools import find_namespace_packages, setup

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

setup(
    packages=[
        *find_namespace_packages(include=[f"{p}*" for p in CODE], exclude=["*.__pycache__"]),
        *DATA_PACKAGES,
    ],
    package_dir={f"server.data.{folder}": folder for folder in DATA},
    package_data={
        **DATA_PACKAGES,
        "client_stub.data": ["*.glb", "*.json", "*.tips"],
        "client_stub.crowd.data": ["*.tips"],
    },
)
