"""What the tests share (one place, imported as ``tests.helpers``; test modules never import each
other): the paths of the tree, the four-engine comparison (the core against ``ENGINES``:
``formulas``, LibreOffice, Gnumeric; ``recalc``, ``close``) and the printed-precision check.
Themed helpers live beside this module:

- ``tests.helpers.clouds``: the model parameters, probes and point clouds the core tests share;
- ``tests.helpers.tasks``: task files written for tests (random clouds, large plates, the bore,
  small feature tasks);
- ``tests.helpers.addin``: add-in formulas of a workbook evaluated by calling ``cmmwb.xlfuncs.udf``;
- ``tests.helpers.locator``: the locator's test layouts and the diagnosis workbook's expected rows;
- ``tests.helpers.budget``: Wojtyła/Płowucha 2023, the steering knuckle and Tables 1-9 as printed;
- ``tests.helpers.decision``: building a task and comparing its Decision/Summary cells per engine;
- ``tests.helpers.files``: the one-clear-message check of bad input;
- ``tests.helpers.documented``: the commands the documents and the ``--help`` texts show, and
  their check against the command line's parsers;
- ``tests.helpers.qif``: a small QIF results file with point normals (the ``import`` examples' part);
- ``tests.helpers.openxml``: the Open XML validator and its documented false positives.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from cmmwb.generator.workbook.recalc import recalculate

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "generator" / "examples"
#: test data shipped with the tests (QIF samples and schemas)
DATA = ROOT / "tests" / "data"
#: the corpus of bad and hostile files (``make_bad_files.py``, ``hostile.py``)
BAD_FILES = ROOT / "tests" / "bad_files"
#: the engines every workbook a test builds is recomputed in (the core gives the reference)
ENGINES = ["formulas", pytest.param("libreoffice", marks=pytest.mark.libreoffice),
           pytest.param("gnumeric", marks=pytest.mark.gnumeric)]
REL = 1e-9
#: the numbers the tests read from each engine's recalculated books (this process; the session
#: summary of ``tests/conftest.py`` adds up the workers)
ENGINE_CELLS: Counter = Counter()


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


def recalc(path: Path, engine: str) -> dict[str, dict]:
    """Every cell value of the workbook at ``path`` as ``engine`` recomputes it
    (``cmmwb.generator.workbook.recalc.recalculate``); each number a test reads from it is
    counted in :data:`ENGINE_CELLS`."""
    return {sheet: _Counted(cells, engine) for sheet, cells in recalculate(path, engine).items()}


class _Counted(dict):
    """One sheet's values; reading a number (``[coordinate]`` or ``.get``) counts it for its engine."""

    def __init__(self, cells: dict, engine: str):
        super().__init__(cells)
        self.engine = engine

    def _count(self, v):
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            ENGINE_CELLS[self.engine] += 1
        return v

    def __getitem__(self, key):
        return self._count(super().__getitem__(key))

    def get(self, key, default=None):
        return self._count(super().get(key, default))


def max_rel_diff(a, b) -> float:
    """The largest elementwise |a - b| / |b| (arrays or numbers)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def run_cmmwb(*args, cwd=None, env=None) -> subprocess.CompletedProcess:
    """``python -m generator ARGS`` in a fresh process (the command line as a user runs it);
    ``env``: variables added to this process's environment."""
    return subprocess.run([sys.executable, "-m", "cmmwb.generator", *args], capture_output=True, text=True, cwd=cwd,
                          env=None if env is None else {**os.environ, **env})


#: the contract's Results rows of each task kind as the JSON gives them (docs/cli.md, "Workbooks"),
#: keyed by column name: what a book's cached Results values must equal
FACTORS = ("R", "PQ", "S", "ET", "ER", "P")


def results_table(kind: str, results: dict) -> list[dict]:
    if kind == "pointcloud":
        return [{"from": d["from"], "to": d["to"], "d_mm": d["d_mm"], "u_um": d["u_um"], "U_um": d["U_um"],
                 **{f"u_{f}_um": d["components_um"][f] for f in FACTORS}} for d in results["distances"]]
    if kind == "budget":
        return [{"name": c["name"], "variant": c["variant"], "value_mm": c["value_mm"], "u_um": c["u_um"],
                 "U_um": c["U_um"]} for c in results["characteristics"]]
    if kind == "feature":
        fe = results["feature"]
        state = fe.get("fit", {}).get("state")
        rows = []
        for n in fe["parameter_names"]:
            length = n.endswith("_mm")
            rows.append({"parameter": n, "value": fe["parameters"][n], "u": fe["u"][n],
                         "u_um": fe["u"][n] * 1e3 if length else "—",
                         "u_urad": "—" if length else fe["u"][n] * 1e6,
                         **({"fit_state": state} if state is not None else {})})
        return rows
    return [{"name": c["name"], "type": c["type"], "value": c["value"], "unit": c["unit"], "u": c["u"],
             "u_unit": c["u_unit"]} for c in results["characteristics"]]
