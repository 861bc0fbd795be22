"""Headless recalculation of a generated workbook.

* ``formulas``: the pure-Python engine, in process.
* ``libreoffice``: a real LibreOffice (``soffice --headless``) with a private profile that forces a
  full recalculation on load (``OOXMLRecalcMode`` = 0, see ``docs/engines.md``), converting to a
  fresh ``.xlsx`` whose cached values are then read with openpyxl.
* ``gnumeric``: Gnumeric's ``ssconvert --recalc`` on a copy without cached values
  (``generator.workbook.gnumeric``), read the same way.

Each returns ``{sheet name: {cell coordinate: value}}`` for every cell that holds a value.
:func:`default_engine` is the fastest one installed (``FASTEST_FIRST``, measured in
``docs/engines.md``).
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import openpyxl
from openpyxl.utils import get_column_letter, range_boundaries

from .cached_values import read_values
from .gnumeric import GnumericError, recalculate_into, sheet_as_text, ssconvert

ENGINES = ("formulas", "libreoffice", "gnumeric")
#: the engines by speed on cmmwb's books (docs/engines.md: the knuckle and a step gauge take
#: Gnumeric well under 1 s, LibreOffice 3-8 s, ``formulas`` 24-34 s)
FASTEST_FIRST = ("gnumeric", "libreoffice", "formulas")
Values = dict[str, dict[str, Any]]

_KEY = re.compile(r"^'?\[(?P<book>[^\]]+)\](?P<sheet>.+?)'?!(?P<ref>[A-Z]+[0-9]+(:[A-Z]+[0-9]+)?)$")

_XCU = """<?xml version="1.0" encoding="UTF-8"?>
<oor:items xmlns:oor="http://openoffice.org/2001/registry" xmlns:xs="http://www.w3.org/2001/XMLSchema" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
<item oor:path="/org.openoffice.Office.Calc/Formula/Load"><prop oor:name="OOXMLRecalcMode" oor:op="fuse"><value>0</value></prop></item>
<item oor:path="/org.openoffice.Office.Calc/Formula/Load"><prop oor:name="ODFRecalcMode" oor:op="fuse"><value>0</value></prop></item>
</oor:items>
"""


class RecalcError(RuntimeError):
    """The engine could not recalculate the workbook."""


def soffice() -> str | None:
    """Path of the LibreOffice executable, or None."""
    for name in ("soffice", "libreoffice"):
        found = shutil.which(name)
        if found:
            return found
    for cand in ("/usr/bin/soffice", "/usr/lib/libreoffice/program/soffice"):
        if os.path.exists(cand):
            return cand
    return None


def installed(engine: str) -> bool:
    """Whether ``engine`` can run here (``formulas`` always can: it is a dependency)."""
    if engine == "libreoffice":
        return soffice() is not None
    if engine == "gnumeric":
        return ssconvert() is not None
    return engine == "formulas"


def default_engine() -> str:
    """The fastest engine installed here."""
    return next(e for e in FASTEST_FIRST if installed(e))


def recalculate(path: str | Path, engine: str = "formulas", timeout_s: float = 600) -> Values:
    """Recompute every formula of the workbook at ``path`` and return all cell values."""
    path = Path(path)
    if engine == "formulas":
        return _recalc_formulas(path)
    if engine == "libreoffice":
        return _recalc_libreoffice(path, timeout_s)
    if engine == "gnumeric":
        return _recalc_gnumeric(path, timeout_s)
    raise ValueError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")


def _sheet_map(path: Path) -> dict[str, str]:
    wb = openpyxl.load_workbook(path, read_only=True)
    try:
        return {s.upper(): s for s in wb.sheetnames}
    finally:
        wb.close()


@contextmanager
def _progress_only_on_a_terminal():
    """``formulas`` draws a tqdm bar on stderr while it compiles a workbook; a person at a terminal
    sees it, a pipe or a log file (``cmmwb recalc BOOK 2>&1 | ...``) does not get it."""
    import formulas.excel as engine

    if sys.stderr is not None and sys.stderr.isatty():
        yield
        return
    module = engine.tqdm
    engine.tqdm = SimpleNamespace(tqdm=functools.partial(module.tqdm, disable=True))
    try:
        yield
    finally:
        engine.tqdm = module


def _recalc_formulas(path: Path) -> Values:
    import formulas  # imported lazily: slow import

    names = _sheet_map(path)
    with _progress_only_on_a_terminal():
        model = formulas.ExcelModel().loads(str(path)).finish()
    sol = model.calculate()
    _refuse_cycles(model, sol, names)
    out: Values = {s: {} for s in names.values()}
    for key, rng in sol.items():
        m = _KEY.match(str(key))
        if not m:
            continue
        sheet = names.get(m.group("sheet").upper())
        if sheet is None:
            continue
        values = getattr(rng, "value", rng)
        c0, r0, c1, r1 = range_boundaries(m.group("ref"))
        try:
            import numpy as np

            arr = np.asarray(values, dtype=object).reshape(r1 - r0 + 1, c1 - c0 + 1)
        except Exception:  # pragma: no cover - unexpected shape from the engine
            continue
        for dr in range(r1 - r0 + 1):
            for dc in range(c1 - c0 + 1):
                v = arr[dr, dc]
                if hasattr(v, "item") and not isinstance(v, str):
                    v = v.item()
                if v is None or (isinstance(v, str) and v == ""):
                    continue
                if type(v).__name__ == "XlError":
                    v = str(v)
                out[sheet][f"{get_column_letter(c0 + dc)}{r0 + dr}"] = v
    return out


def _refuse_cycles(model, sol, names: dict[str, str]) -> None:
    """Without ``circular=True`` the ``formulas`` engine leaves the cells of a cycle out of its
    solution: they would print as blanks.  A circular reference is an error instead."""
    unsolved = [str(k) for k in getattr(model, "cells", {}) if k not in sol]
    if unsolved:
        m = _KEY.match(unsolved[0])
        where = f"{names.get(m.group('sheet').upper(), m.group('sheet'))}!{m.group('ref')}" if m else unsolved[0]
        raise RecalcError(f"a circular reference: {len(unsolved)} formula cell(s) depend on themselves, "
                          f"e.g. {where}; cmmwb's workbooks have none (was a formula edited?)")


def check_no_cycles(path: str | Path) -> None:
    """Raise :class:`RecalcError` if the workbook has a circular reference (found with the
    ``formulas`` engine; LibreOffice reports one only as an error value, Err:522 / #VALUE!)."""
    import formulas

    path = Path(path)
    model = formulas.ExcelModel().loads(str(path)).finish()
    _refuse_cycles(model, model.calculate(), _sheet_map(path))


def _recalc_libreoffice(path: Path, timeout_s: float) -> Values:
    exe = soffice()
    if exe is None:
        raise RecalcError("LibreOffice (soffice) is not installed")
    with tempfile.TemporaryDirectory(prefix="cmmwb_lo_") as tmp:
        tmp = Path(tmp)
        profile = tmp / "profile"
        (profile / "user").mkdir(parents=True)
        (profile / "user" / "registrymodifications.xcu").write_text(_XCU)
        src = tmp / "in" / path.name
        src.parent.mkdir()
        shutil.copy(path, src)
        outdir = tmp / "out"
        cmd = [exe, f"-env:UserInstallation={profile.as_uri()}", "--headless", "--norestore",
               "--convert-to", "xlsx:Calc MS Excel 2007 XML", "--outdir", str(outdir), str(src)]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s,
                              env={**os.environ, "HOME": str(tmp)})
        result = outdir / path.name
        if proc.returncode != 0 or not result.exists():
            raise RecalcError(f"LibreOffice failed on {path.name}: {proc.stderr.strip() or proc.stdout.strip()}")
        return read_cached(result)


#: the second starting value of every formula cell in :func:`recalculate_checking_cycles`
CYCLE_SEED = 7.25


def recalculate_checking_cycles(path: str | Path, sheet: str = "Results",
                                timeout_s: float = 600) -> tuple[Values, list[str]]:
    """Gnumeric's values of the workbook at ``path`` (from no cached values), and the cells of
    ``sheet`` (``Results!B2``, in row order) whose value changes when every formula cell starts
    from :data:`CYCLE_SEED` instead: the cells there a circular reference reaches (Gnumeric
    iterates a cycle from its cells' starting values and gives no error value;
    ``generator.workbook.gnumeric``).  Empty for a book without a circular reference.  The two
    runs go side by side; the second one writes only ``sheet``, as text."""
    path = Path(path)
    with ThreadPoolExecutor(2) as pool, tempfile.TemporaryDirectory(prefix="cmmwb_gnumeric_") as tmp:
        first = pool.submit(_recalc_gnumeric, path, timeout_s)
        again = pool.submit(sheet_as_text, path, tmp, sheet, timeout_s, CYCLE_SEED)
        try:
            values, seeded = first.result(), again.result()
        except GnumericError as e:
            raise RecalcError(str(e)) from None
    cells = values.get(sheet, {})
    return values, [f"{sheet}!{ref}" for ref in sorted(set(cells) | set(seeded), key=_row_major)
                    if not _same(cells.get(ref), seeded.get(ref))]


def _row_major(ref: str) -> tuple[int, int]:
    c0, r0, _, _ = range_boundaries(ref)
    return r0, c0


def _same(value, text: str | None) -> bool:
    """Whether a value read from Gnumeric's .xlsx is the text its CSV export wrote for the cell."""
    if value is None or text is None:
        return value is None and text is None
    if isinstance(value, bool):
        return text == ("TRUE" if value else "FALSE")
    if isinstance(value, (int, float)):
        try:
            return float(text) == float(value)
        except ValueError:
            return False
    return text == str(value)


def _recalc_gnumeric(path: Path, timeout_s: float, seed: float | None = None) -> Values:
    with tempfile.TemporaryDirectory(prefix="cmmwb_gnumeric_") as tmp:
        try:
            out = recalculate_into(path, tmp, timeout_s, seed)
        except GnumericError as e:
            raise RecalcError(str(e)) from None
        return read_cached(out)


def read_cached(path: str | Path) -> Values:
    """Cached values of every cell of a saved workbook (as LibreOffice, Gnumeric or Excel left
    them), read from its XML (``generator.workbook.cached_values``)."""
    return read_values(path)


def results_rows(values: Values, sheet: str = "Results") -> list[dict[str, Any]]:
    """The ``Results`` sheet as a list of dicts keyed by the header row."""
    cells = values[sheet]
    header = []
    c = 1
    while f"{get_column_letter(c)}1" in cells:
        header.append(str(cells[f"{get_column_letter(c)}1"]))
        c += 1
    rows = []
    r = 2
    while any(f"{get_column_letter(k + 1)}{r}" in cells for k in range(len(header))):
        rows.append({h: cells.get(f"{get_column_letter(k + 1)}{r}") for k, h in enumerate(header)})
        r += 1
    return rows
