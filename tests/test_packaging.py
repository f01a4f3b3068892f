"""The wheel carries its data (issue 19): setup.py's package data covers every shipped data file, and
``server.data_root`` finds the data in a checkout and in an install. ``.ci/wheel_check.sh`` (``make
wheel-check``) builds and installs the real wheel; these tests catch a forgotten file type or folder early."""

from __future__ import annotations

import fnmatch
import runpy
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import setuptools

import ttes.paths
from client_stub.data_paths import CROWD_DATA, DEFAULT_TERRAIN, STUB_DATA
from server.config import DEFAULT_DATA_DIR
from server.data_root import CHECKOUT_ROOT, SEARCH_SUBDIRS, find_data_root

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def monkeypatch_module() -> Iterator[pytest.MonkeyPatch]:
    with pytest.MonkeyPatch.context() as mp:
        yield mp


@pytest.fixture(scope="module")
def setup_args(monkeypatch_module: pytest.MonkeyPatch) -> dict[str, Any]:
    """The keywords setup.py hands to ``setup()`` (run without building anything)."""
    seen: dict[str, Any] = {}
    monkeypatch_module.setattr(setuptools, "setup", lambda **kw: seen.update(kw))
    monkeypatch_module.chdir(REPO)
    runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    return seen


def _wheel_path(rel: str, package_dir: dict[str, str]) -> str:
    """Where a repository file lands in the wheel, by setup.py's package_dir."""
    for package, folder in package_dir.items():
        if rel.startswith(folder + "/"):
            return package.replace(".", "/") + "/" + rel[len(folder) + 1 :]
    return rel


def _tracked(*folders: str) -> list[str]:
    out = subprocess.run(["git", "ls-files", *folders], cwd=REPO, capture_output=True, text=True, check=True)
    return [line for line in out.stdout.splitlines() if not line.endswith("README.md")]


def test_every_shipped_data_file_is_package_data(setup_args: dict[str, Any]) -> None:
    files = _tracked(*SEARCH_SUBDIRS, "client_stub/data", "client_stub/crowd/data")
    assert len(files) > 250
    packages, data = set(setup_args["packages"]), setup_args["package_data"]
    missing = []
    for rel in files:
        package, name = _wheel_path(rel, setup_args["package_dir"]).rsplit("/", 1)
        dotted = package.replace("/", ".")
        if dotted not in packages or not any(fnmatch.fnmatch(name, g) for g in data.get(dotted, [])):
            missing.append(rel)
    assert not missing, f"not in the wheel: {missing[:10]}"


def test_the_pages_files_are_package_data_of_listed_packages(setup_args: dict[str, Any]) -> None:
    """`ttes web`'s page: its HTML, scripts and (once `make vendor` ran) the vendored three.js and msgpack,
    each in a listed package with a glob that matches it; a folder that is not listed made setuptools warn
    ("Package would be ignored") and would ship nothing in a setuptools that stops guessing."""
    page = REPO / "client_stub" / "web"
    files = [f for top in ("js", "vendor") for f in (page / top).rglob("*") if f.is_file()]
    files += [page / "index.html", page / "package.json"]
    assert (page / "js" / "wire.js") in files
    packages, data = set(setup_args["packages"]), setup_args["package_data"]
    missing = []
    for f in files:
        rel = f.relative_to(REPO)
        dotted = ".".join(rel.parent.parts)
        if dotted not in packages or not any(fnmatch.fnmatch(f.name, g) for g in data.get(dotted, [])):
            missing.append(str(rel))
    assert not missing, f"not in the wheel: {missing[:10]}"


def test_every_code_package_is_in_the_wheel(setup_args: dict[str, Any]) -> None:
    inits = _tracked("peabody", "protocol", "server", "authoring", "client_stub", "ttes")
    wanted = {str(Path(f).parent).replace("/", ".") for f in inits if f.endswith("__init__.py")}
    assert wanted <= set(setup_args["packages"])


def test_a_checkout_reads_its_own_folders() -> None:
    assert CHECKOUT_ROOT == REPO
    assert DEFAULT_DATA_DIR == REPO and ttes.paths.ROOT == REPO
    assert (ttes.paths.POSTURE_GRAPHS / "jack-ttes-soldier_low.jcl").is_file()
    assert DEFAULT_TERRAIN.is_file() and (STUB_DATA / "DI.tips").is_file()
    assert (CROWD_DATA / "soldier.tips").is_file()


def test_an_install_reads_the_wheels_copy_first(tmp_path: Path) -> None:
    wheel_data, checkout = tmp_path / "site" / "server" / "data", tmp_path / "checkout"
    for sub in SEARCH_SUBDIRS:
        (wheel_data / sub).mkdir(parents=True)
        (checkout / sub).mkdir(parents=True)
    assert find_data_root((wheel_data, checkout)) == wheel_data
    (wheel_data / "channelsets").rmdir()  # an incomplete copy is not the data
    assert find_data_root((wheel_data, checkout)) == checkout


def test_without_data_the_answer_is_still_a_path_that_errors_name(tmp_path: Path) -> None:
    assert find_data_root((tmp_path / "a", tmp_path / "b")) == tmp_path / "b"


def test_the_stubs_spawned_server_serves_the_shipped_library() -> None:
    """`ttes stub --spawn-server` (and so `ttes demo`) used a synthetic stand-in because it looked for the
    start-up script at the data root; it lives in posture_graphs/, on the server's search path."""
    import contextlib

    from ttes.commands.stub import _server_data_dir

    with contextlib.ExitStack() as stack:
        assert _server_data_dir(stack) == ttes.paths.ROOT
