"""Gnumeric as a spreadsheet engine: ``ssconvert --recalc`` on a copy without cached values.

Gnumeric (Debian ``gnumeric``; ``ssconvert`` 1.12.55 measured, docs/engines.md) is an engine of its
own, independent of LibreOffice and of ``formulas``.  :func:`recalculate_into` copies the workbook
with every cached formula value removed (``generator.workbook.uncached``: nothing stale can
survive a cell Gnumeric does not compute), lets ``ssconvert --recalc`` recompute every cell and
write the result as ``.xlsx``, and returns that file, whose cached values are what Gnumeric
computed.  Headless: ``ssconvert`` needs no display.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

from .uncached import strip_cached_values


class GnumericError(RuntimeError):
    """``ssconvert`` is missing or could not recalculate the workbook."""


def ssconvert() -> str | None:
    """Path of Gnumeric's ``ssconvert``, or None."""
    found = shutil.which("ssconvert")
    if found:
        return found
    return "/usr/bin/ssconvert" if os.path.exists("/usr/bin/ssconvert") else None


def recalculate_into(path: str | Path, folder: str | Path, timeout_s: float = 600,
                     seed: float | None = None) -> Path:
    """Recompute the workbook at ``path`` in Gnumeric inside ``folder`` (a private, empty folder:
    also Gnumeric's home for the run); returns the recalculated ``.xlsx``.  ``seed``: every
    formula cell starts from this cached value instead of none.

    Gnumeric computes a circular reference without an error value, by iterating from the
    cells' starting values (measured: ``B2 = C2+1``, ``C2 = B2*2`` gives 3 and 2 from no cached
    values, 201 and 200 from 100 and 7), so the result of a cycle depends on where it starts,
    while every other cell is recomputed from its inputs alone.  Two runs from different starts
    (``generator.workbook.recalc.recalculate_checking_cycles``) find the cells a cycle reaches."""
    exe = ssconvert()
    if exe is None:
        raise GnumericError("Gnumeric (ssconvert) is not installed")
    path, folder = Path(path), Path(folder)
    src = folder / "uncached.xlsx"
    out = folder / "recalculated.xlsx"
    strip_cached_values(path, src, seed)
    env = {**os.environ, "HOME": str(folder), "GSETTINGS_BACKEND": "memory"}
    env.pop("DISPLAY", None)
    try:
        proc = subprocess.run([exe, "--recalc", "--export-type=Gnumeric_Excel:xlsx2", str(src), str(out)],
                              capture_output=True, text=True, timeout=timeout_s, env=env, cwd=folder)
    except subprocess.TimeoutExpired:
        raise GnumericError(f"Gnumeric took longer than {timeout_s:g} s on {path.name}") from None
    if proc.returncode != 0 or not out.exists():
        said = [line for line in (proc.stderr or proc.stdout).splitlines() if line.strip() and "WARNING" not in line]
        raise GnumericError(f"Gnumeric failed on {path.name}: {said[-1].strip() if said else f'exit {proc.returncode}'}")
    return out
