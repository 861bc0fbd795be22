"""Gnumeric as a spreadsheet engine: ``ssconvert --recalc`` on a copy without cached values.

Gnumeric (Debian ``gnumeric``; ``ssconvert`` 1.12.55 measured, docs/engines.md) is an engine of its
own, independent of LibreOffice and of ``formulas``.  :func:`recalculate_into` copies the workbook
with every cached formula value removed (``generator.workbook.uncached``: nothing stale can
survive a cell Gnumeric does not compute), lets ``ssconvert --recalc`` recompute every cell and
write the result as ``.xlsx``, and returns that file, whose cached values are what Gnumeric
computed.  Headless: ``ssconvert`` needs no display.
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
from pathlib import Path

from openpyxl.utils import get_column_letter

from .uncached import strip_cached_values


class GnumericError(RuntimeError):
    """``ssconvert`` is missing or could not recalculate the workbook."""


def ssconvert() -> str | None:
    """Path of Gnumeric's ``ssconvert``, or None."""
    found = shutil.which("ssconvert")
    if found:
        return found
    return "/usr/bin/ssconvert" if os.path.exists("/usr/bin/ssconvert") else None


def sheet_as_text(path: str | Path, folder: str | Path, sheet: str, timeout_s: float = 600,
                  seed: float | None = None) -> dict[str, str]:
    """One sheet of the workbook at ``path`` as Gnumeric recomputes it, each cell's value as the
    text Gnumeric writes (full precision; no types): ``{"B2": "3.25", ...}``.  Cheaper than
    :func:`recalculate_into`, whose ``.xlsx`` export takes most of Gnumeric's time."""
    out = _run(path, folder, timeout_s, seed, "recalculated.csv",
               ["-T", "Gnumeric_stf:stf_assistant", "-O", f"sheet={sheet} format=raw separator=, quoting-mode=always"])
    with open(out, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return {f"{get_column_letter(c + 1)}{r + 1}": v for r, row in enumerate(rows) for c, v in enumerate(row) if v != ""}


def recalculate_into(path: str | Path, folder: str | Path, timeout_s: float = 600,
                     seed: float | None = None) -> Path:
    """Recompute the workbook at ``path`` in Gnumeric inside ``folder`` (a private, empty folder:
    also Gnumeric's home for the run); returns the recalculated ``.xlsx``.  ``seed``: every
    formula cell starts from this cached value instead of none.

    Gnumeric computes a circular reference without an error value, by iterating from the
    cells' starting values (measured: ``B2 = C2+1``, ``C2 = B2*2`` gives 3 and 2 from no cached
    values, 201 and 200 from 100 and 7), so the result of a cycle depends on where it starts,
    while every other cell is recomputed from its inputs alone.  Two runs from different starts
    (``generator.workbook.recalc.recalculate_checking_cycles``, the second one through
    :func:`sheet_as_text`) find the cells a cycle reaches."""
    return _run(path, folder, timeout_s, seed, "recalculated.xlsx", ["--export-type=Gnumeric_Excel:xlsx2"])


def _run(path: str | Path, folder: str | Path, timeout_s: float, seed: float | None, name: str,
         export: list[str]) -> Path:
    exe = ssconvert()
    if exe is None:
        raise GnumericError("Gnumeric (ssconvert) is not installed")
    path, folder = Path(path), Path(folder)
    src = folder / "uncached.xlsx"
    out = folder / name
    strip_cached_values(path, src, seed)
    env = {**os.environ, "HOME": str(folder), "GSETTINGS_BACKEND": "memory"}
    env.pop("DISPLAY", None)
    try:
        proc = subprocess.run([exe, "--recalc", *export, str(src), str(out)],
                              capture_output=True, text=True, timeout=timeout_s, env=env, cwd=folder)
    except subprocess.TimeoutExpired:
        raise GnumericError(f"Gnumeric took longer than {timeout_s:g} s on {path.name}") from None
    if proc.returncode != 0 or not out.exists():
        said = [line for line in (proc.stderr or proc.stdout).splitlines() if line.strip() and "WARNING" not in line]
        raise GnumericError(f"Gnumeric failed on {path.name}: {said[-1].strip() if said else f'exit {proc.returncode}'}")
    return out
