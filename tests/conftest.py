"""Shared test helpers: the three-engine comparison and the example tasks."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from generator.recalc import recalculate, soffice

EXAMPLES = Path(__file__).resolve().parents[1] / "generator" / "examples"
ENGINES = ["formulas", pytest.param("libreoffice", marks=pytest.mark.libreoffice)]
REL = 1e-9


def pytest_collection_modifyitems(config, items):
    """LibreOffice tests are skipped where LibreOffice is missing, except in CI, where a missing
    LibreOffice is an installation error and must fail loudly."""
    if soffice() is not None or os.environ.get("CI"):
        return
    skip = pytest.mark.skip(reason="LibreOffice (soffice) not installed")
    for item in items:
        if "libreoffice" in item.keywords:
            item.add_marker(skip)


def close(a, b, rel: float = REL, floor: float = 1e-12) -> bool:
    """Relative agreement; ``floor`` (µm) absorbs rounding noise of exactly-zero components."""
    if not isinstance(a, (int, float)) or not isinstance(b, (int, float)):
        return False
    if not (math.isfinite(a) and math.isfinite(b)):
        return False
    return abs(a - b) <= rel * max(abs(a), abs(b)) + floor


def printed(value: float, table_value: float, decimals: int = 2) -> bool:
    """True when ``value`` rounds to the printed ``table_value`` (half a unit of the last digit)."""
    return abs(value - table_value) <= 0.5 * 10 ** -decimals + 1e-12


def recalc(path: Path, engine: str):
    return recalculate(path, engine)
