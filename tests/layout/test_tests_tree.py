"""The test tree itself (docs/developing.md, "Tests"): test modules live in the folder of what they
test, never import each other (what they share is in tests/helpers/), and the ``numerics``
selection of conftest.py names modules that exist."""

from __future__ import annotations

import ast

from tests.conftest import NUMERIC_MODULES
from tests.helpers import ROOT

TESTS = ROOT / "tests"


def module_paths():
    return sorted(TESTS.glob("*/test_*.py"))


def test_every_test_module_is_in_a_folder_that_is_a_package():
    assert not list(TESTS.glob("test_*.py")), "move top-level test modules into the folder of what they test"
    for path in module_paths():
        assert (path.parent / "__init__.py").is_file(), path.parent
    assert (TESTS / "__init__.py").is_file() and (TESTS / "helpers" / "__init__.py").is_file()


def test_module_names_are_unique_because_numerics_selects_by_name():
    names = [p.stem for p in module_paths()]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)


def test_every_numeric_module_exists():
    assert NUMERIC_MODULES <= {p.stem for p in module_paths()}, NUMERIC_MODULES - {p.stem for p in module_paths()}


def test_no_test_module_imports_another_or_conftest():
    bad = []
    for path in [*module_paths(), *TESTS.glob("helpers/*.py")]:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                last = name.rsplit(".", 1)[-1]
                if last.startswith("test_") or (last in ("conftest", "pointcloud_tasks") and name != "tests.conftest"):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {name}")
    assert not bad, "import shared code from tests.helpers instead:\n" + "\n".join(bad)
