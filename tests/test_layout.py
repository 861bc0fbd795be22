"""The source tree as an installation sees it.

`pip install .` (not only the editable install the tests use) must carry every package of the
tree: a subpackage left out of `pyproject.toml` imports in the checkout and fails for a user.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from setuptools import find_packages

ROOT = Path(__file__).resolve().parents[1]


def _packages_in_tree() -> set[str]:
    out = set()
    for top in ("generator", "xlfuncs"):
        for init in (ROOT / top).rglob("__init__.py"):
            out.add(".".join(init.parent.relative_to(ROOT).parts))
    return out


def test_every_package_in_the_tree_is_installed():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    find = config["tool"]["setuptools"]["packages"]["find"]
    installed = set(find_packages(str(ROOT), include=find["include"]))
    assert _packages_in_tree() <= installed, sorted(_packages_in_tree() - installed)
    assert {"xlfuncs.locator", "generator.importers"} <= installed
