"""Authoring modules share helpers by public names: none reaches into another's ``_private`` ones.

A helper two modules need lives in a small public module (``signal_shaping``: curves along the frames,
``slave_body``: a slaved clip's body, ``ground_frames``: frames turned on the ground) or gets a public name
in the module it belongs to; renaming a private helper then never breaks a module that borrowed it. Tests
may still reach into the module they test."""

from __future__ import annotations

import ast
from pathlib import Path

AUTHORING = Path(__file__).resolve().parent.parent / "authoring"
# dead_settle's body model, which the death modules share as ``ds._Body`` and so on: left for after the
# death work of session 19 lands (renaming it there would collide with it). Strict: one made public leaves.
KNOWN = {
    "authoring.dead_settle._Body",
    "authoring.dead_settle._Leg",
    "authoring.dead_settle._dofs",
    "authoring.dead_settle._face_down",
    "authoring.dead_settle._leg_dofs",
    "authoring.dead_settle._rest_frame",
}


def _borrowed(path: Path) -> set[str]:
    """The other authoring modules' private names that ``path`` uses: imported by name, or as an attribute
    of an authoring module it imported."""
    tree = ast.parse(path.read_text())
    own = f"authoring.{path.stem}"
    modules: dict[str, str] = {}  # local name -> authoring module
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "authoring":
            modules.update({a.asname or a.name: f"authoring.{a.name}" for a in node.names})
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("authoring."):
            out |= {f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_")}
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.asname and a.name.startswith("authoring."):
                    modules[a.asname] = a.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules:
            out |= {f"{modules[node.value.id]}.{node.attr}"} if node.attr.startswith("_") else set()
    return {name for name in out if not name.startswith(own + ".")}


def test_no_authoring_module_uses_another_ones_private_names() -> None:
    """Every authoring module (tests aside) imports and uses only public names of the others."""
    found = set().union(*(_borrowed(p) for p in sorted(AUTHORING.glob("*.py"))))
    assert found - KNOWN == set(), "give these a public name (or a shared module) instead"
    assert KNOWN - found == set(), "made public: take them out of KNOWN"


def test_the_scan_sees_both_ways_of_borrowing(tmp_path: Path) -> None:
    """A name imported from another module and an attribute of an imported module both count; the module's
    own private names do not."""
    mod = tmp_path / "stage.py"
    mod.write_text(
        "from authoring import dead_settle as ds\n"
        "from authoring.crawl import _hidden, shown\n"
        "from authoring.stage import _mine\n"
        "x = ds._Body(ds.SIDES, shown, _hidden, _mine)\n"
    )
    assert _borrowed(mod) == {"authoring.crawl._hidden", "authoring.dead_settle._Body"}
