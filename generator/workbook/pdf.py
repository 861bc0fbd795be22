"""Workbooks printed to PDF by a headless LibreOffice, for the audit file (``cmmwb build --pdf``,
``cmmwb demo --pdf``).

The PDF holds what the workbook's print setup says (:meth:`generator.workbook.book.Book.print_setup`):
every visible sheet on A4, scaled to the page width, headers repeated; large matrix sheets
print their top-left corner only; the hidden ``_task`` sheet never prints.  LibreOffice computes
the formula cells on loading (openpyxl writes none of their values), so the PDF shows the
workbook's own numbers.

All books of one call are converted by ONE LibreOffice process (starting it costs seconds).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Sequence

from ..errors import InputError
from .recalc import soffice

NO_LIBREOFFICE = ("--pdf needs LibreOffice (the `soffice` program), which was not found on PATH; install "
                  "it (e.g. `apt-get install libreoffice-calc-nogui`) or leave out --pdf")


def require_libreoffice() -> str:
    """The soffice executable, or an :class:`InputError` saying LibreOffice is needed."""
    exe = soffice()
    if exe is None:
        raise InputError(NO_LIBREOFFICE)
    return exe


def print_books(books: Sequence[Path], *, timeout_s: float = 900) -> list[Path]:
    """Print each ``BOOK.xlsx`` to ``BOOK.pdf`` beside it (replacing it atomically); return the
    PDFs.  One LibreOffice run with a private profile converts them all."""
    exe = require_libreoffice()
    books = [Path(b) for b in books]
    if not books:
        return []
    with tempfile.TemporaryDirectory(prefix="cmmwb-pdf-") as tmp:
        tmp = Path(tmp)
        src = tmp / "in"
        out = tmp / "out"
        src.mkdir()
        out.mkdir()
        names = []
        for k, b in enumerate(books):
            name = f"{k:04d}_{b.stem}"   # unique: demo writes two books named diagnosis.xlsx
            os.symlink(b.resolve(), src / f"{name}.xlsx")
            names.append(name)
        cmd = [exe, f"-env:UserInstallation={(tmp / 'profile').as_uri()}", "--headless", "--norestore",
               "--convert-to", "pdf", "--outdir", str(out), *(str(src / f"{n}.xlsx") for n in names)]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise InputError(f"LibreOffice did not finish printing within {timeout_s:.0f} s",
                             file=books[0]) from None
        made = []
        for b, n in zip(books, names):
            pdf = out / f"{n}.pdf"
            if not pdf.exists():
                raise InputError("LibreOffice could not print this workbook to PDF"
                                 + (f" ({proc.stderr.strip()[:300]})" if proc.stderr.strip() else ""), file=b)
            target = b.with_suffix(".pdf")
            part = target.with_name(target.name + ".tmp")
            shutil.move(str(pdf), part)
            os.replace(part, target)
            made.append(target)
    return made
