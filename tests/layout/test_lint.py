"""The linter and the type check run with the suite (so the README's test command, which CI runs,
covers them): `ruff check` over the whole tree and `mypy` over the typed public core, both
configured in pyproject.toml ([tool.ruff], [tool.mypy]).  Both are in the `test` extra; where one
is missing the test is skipped and says so."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import pytest

from tests.helpers import ROOT


def run_tool(module: str, *args: str) -> subprocess.CompletedProcess:
    """``python -m <module> ARGS`` with this interpreter (the venv's tool), from the repository root."""
    if importlib.util.find_spec(module) is None:
        pytest.skip(f"{module} is not installed (pip install -e '.[test]' installs it)")
    return subprocess.run([sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)


def test_ruff_finds_nothing():
    r = run_tool("ruff", "check", "--no-cache", "--output-format", "concise", ".")
    assert r.returncode == 0, f"ruff check . (fix with: ruff check --fix .):\n{r.stdout}{r.stderr}"


def test_mypy_finds_nothing_in_the_typed_core():
    r = run_tool("mypy")
    assert r.returncode == 0, f"mypy (the files of [tool.mypy] in pyproject.toml):\n{r.stdout}{r.stderr}"
